//! A plain f32 image: width × height pixels of `channels` interleaved values, rows top to bottom.

/// An f32 image with interleaved channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: u32,
    height: u32,
    channels: u32,
    data: Vec<f32>,
}

impl Image {
    /// An image filled with `value`.
    pub fn filled(width: u32, height: u32, channels: u32, value: f32) -> Self {
        let len = width as usize * height as usize * channels as usize;
        Self { width, height, channels, data: vec![value; len] }
    }

    /// An image from its data, `None` when the length does not match the size.
    pub fn from_data(width: u32, height: u32, channels: u32, data: Vec<f32>) -> Option<Self> {
        (data.len() == width as usize * height as usize * channels as usize).then_some(Self {
            width,
            height,
            channels,
            data,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Channels per pixel.
    pub fn channels(&self) -> u32 {
        self.channels
    }

    /// All values, row-major, channels interleaved.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// All values, the image consumed (handed to another owner without a copy).
    pub fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// All values, mutable.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// The values of pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> &[f32] {
        let i = self.index(x, y);
        &self.data[i..i + self.channels as usize]
    }

    /// The values of pixel (x, y), mutable.
    pub fn pixel_mut(&mut self, x: u32, y: u32) -> &mut [f32] {
        let i = self.index(x, y);
        &mut self.data[i..i + self.channels as usize]
    }

    fn index(&self, x: u32, y: u32) -> usize {
        assert!(x < self.width && y < self.height, "pixel ({x}, {y}) outside {}×{}", self.width, self.height);
        (y as usize * self.width as usize + x as usize) * self.channels as usize
    }
}

/// 8-bit value of a display-referred float: round(clamp(v, 0, 1) × 255), NaN → 0 (what the PNG
/// writer stores and the GPU display pass shows).
pub fn to_u8(v: f32) -> u8 {
    if v.is_nan() { 0 } else { (v.clamp(0.0, 1.0) * 255.0).round() as u8 }
}
