//! The CPU view's accumulation: per pixel a running Welford mean and M2 of the frames'
//! colour, the mean stored in the chosen [`AccumulationFormat`] after every frame, as
//! vk_gaussian_splatting's temporal accumulation stores it (mean ← mix(mean, frame, 1/(n+1));
//! its documentation warns that FP16 drifts after about 150–200 frames: the viewer shows it).
//! Depth and normal are frame 0's, as in every render of the project.

use splat_core::frame::RenderOutput;
use splat_core::image::Image;
use splat_gpu::{AccumulationFormat, DisplayTransform, PixelState};

/// The accumulated frames of a `width` × `height` view.
pub struct CpuAccumulation {
    width: u32,
    height: u32,
    frames: u32,
    mean: Vec<f32>,
    m2: Vec<f32>,
    depth: Vec<f32>,
    normal: Vec<f32>,
}

impl CpuAccumulation {
    /// No frames yet.
    pub fn new(width: u32, height: u32) -> Self {
        let pixels = width as usize * height as usize;
        Self {
            width,
            height,
            frames: 0,
            mean: vec![0.0; 3 * pixels],
            m2: vec![0.0; 3 * pixels],
            depth: vec![f32::NAN; pixels],
            normal: vec![0.0; 3 * pixels],
        }
    }

    /// Frames folded in.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Width and height.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Fold in the mean colour of `frame` (one frame), storing the running mean in `format`.
    pub fn fold(&mut self, frame: &RenderOutput, format: AccumulationFormat) {
        let n = self.frames as f32 + 1.0;
        for ((mean, m2), &x) in self.mean.iter_mut().zip(&mut self.m2).zip(frame.mean.data()) {
            let delta = x - *mean;
            *mean += delta / n;
            *m2 += delta * (x - *mean);
            *mean = store(*mean, format);
        }
        if self.frames == 0 {
            self.depth.copy_from_slice(frame.depth.data());
            self.normal.copy_from_slice(frame.normal.data());
        }
        self.frames += 1;
    }

    /// The running mean as an image.
    pub fn mean_image(&self) -> Image {
        Image::from_data(self.width, self.height, 3, self.mean.clone()).expect("three channels per pixel")
    }

    /// What `display` shows, as RGBA8 rows.
    pub fn rgba8(&self, display: &DisplayTransform) -> Vec<u8> {
        let variance = |i: usize| if self.frames > 1 { self.m2[i] / (self.frames - 1) as f32 } else { 0.0 };
        let rgb = |v: &[f32], p: usize| [v[3 * p], v[3 * p + 1], v[3 * p + 2]];
        (0..self.depth.len())
            .flat_map(|p| {
                display.rgba8(&PixelState {
                    mean: rgb(&self.mean, p),
                    variance: [variance(3 * p), variance(3 * p + 1), variance(3 * p + 2)],
                    depth: self.depth[p],
                    normal: rgb(&self.normal, p),
                })
            })
            .collect()
    }
}

/// `v` as `format` stores it ([`AccumulationFormat::store`]; f32 keeps f32 here, as on the GPU).
fn store(v: f32, format: AccumulationFormat) -> f32 {
    format.store(f64::from(v)) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(value: f32) -> RenderOutput {
        let image = |c| Image::filled(2, 1, c, value);
        RenderOutput::colour_only(image(3), image(3), image(1))
    }

    #[test]
    fn the_running_mean_and_variance_are_the_frames() {
        let mut acc = CpuAccumulation::new(2, 1);
        for v in [0.2, 0.4, 0.9] {
            acc.fold(&frame(v), AccumulationFormat::F32);
        }
        assert_eq!(acc.frames(), 3);
        assert!((acc.mean_image().data()[0] - 0.5).abs() < 1e-6);
        // Sample variance of 0.2, 0.4, 0.9 is 0.13: standard deviation 0.3606.
        let d = DisplayTransform {
            mode: splat_gpu::DisplayMode::Variance,
            variance_scale: 1.0,
            ..DisplayTransform::default()
        };
        assert_eq!(acc.rgba8(&d)[0], (0.13f32.sqrt() * 255.0).round() as u8);
    }

    #[test]
    fn an_eight_bit_mean_stops_converging_where_f32_does_not() {
        // 1000 frames alternating 0 and 1/255·0.6: the true mean 0.3/255 is below half a step,
        // so the 8-bit store rounds every update back to 0.
        let (mut wide, mut narrow) = (CpuAccumulation::new(2, 1), CpuAccumulation::new(2, 1));
        for i in 0..1000 {
            let v = if i % 2 == 0 { 0.0 } else { 0.6 / 255.0 };
            wide.fold(&frame(v), AccumulationFormat::F32);
            narrow.fold(&frame(v), AccumulationFormat::Unorm8);
        }
        assert!((wide.mean_image().data()[0] - 0.3 / 255.0).abs() < 1e-5);
        assert_eq!(narrow.mean_image().data()[0], 0.0);
        assert_eq!(store(0.1, AccumulationFormat::F16), half::f16::from_f32(0.1).to_f32());
    }
}
