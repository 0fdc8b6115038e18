//! What a viewer shows of a render, as the CPU twin of `shaders/display.wgsl`: the mean colour,
//! frame 0's depth or normal, or the per-frame standard deviation. Values are display-referred
//! (3DGS colours are stored as they are shown), so a pixel's byte is `round(255 × v)`: the PNG
//! writer's [`splat_core::image::to_u8`].

use bytemuck::{Pod, Zeroable};

/// Which image a view shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DisplayMode {
    /// The running mean of the radiance (Eq. 3 in expectation).
    #[default]
    Colour,
    /// Frame 0's picked depth, near bright and far dark between
    /// [`DisplayTransform::depth_near`] and [`DisplayTransform::depth_far`]; black where
    /// nothing was picked.
    Depth,
    /// Frame 0's unit normal n as (n + 1) / 2; black where nothing was hit.
    Normal,
    /// The per-frame standard deviation √(mean of the RGB variances) ×
    /// [`DisplayTransform::variance_scale`], grey: where the estimator is noisy (zero after one
    /// frame).
    Variance,
}

impl DisplayMode {
    /// Every mode, in menu order.
    pub const ALL: [DisplayMode; 4] =
        [DisplayMode::Colour, DisplayMode::Depth, DisplayMode::Normal, DisplayMode::Variance];

    /// Its name in a menu.
    pub fn name(self) -> &'static str {
        match self {
            DisplayMode::Colour => "colour",
            DisplayMode::Depth => "depth",
            DisplayMode::Normal => "normals",
            DisplayMode::Variance => "variance",
        }
    }
}

/// A display transform: the mode and its ranges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplayTransform {
    /// What to show.
    pub mode: DisplayMode,
    /// Depth shown white.
    pub depth_near: f32,
    /// Depth shown black.
    pub depth_far: f32,
    /// Standard deviation shown white is 1 / `variance_scale`.
    pub variance_scale: f32,
}

impl Default for DisplayTransform {
    fn default() -> Self {
        Self { mode: DisplayMode::Colour, depth_near: 0.0, depth_far: 10.0, variance_scale: 2.0 }
    }
}

/// One pixel of a render as the display transform reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelState {
    /// Mean RGB.
    pub mean: [f32; 3],
    /// Per-frame variance RGB (zero after one frame).
    pub variance: [f32; 3],
    /// Frame 0's depth (NaN where none).
    pub depth: f32,
    /// Frame 0's unit normal (zero where none).
    pub normal: [f32; 3],
}

impl DisplayTransform {
    /// The displayed RGB of `p`, in [0, 1] (display.wgsl `shade`).
    pub fn shade(&self, p: &PixelState) -> [f32; 3] {
        let unit = |v: f32| v.clamp(0.0, 1.0);
        match self.mode {
            DisplayMode::Colour => p.mean.map(unit),
            DisplayMode::Depth if p.depth.is_nan() || p.depth < 0.0 => [0.0; 3],
            DisplayMode::Depth => {
                let span = (self.depth_far - self.depth_near).max(f32::MIN_POSITIVE);
                [1.0 - unit((p.depth - self.depth_near) / span); 3]
            }
            DisplayMode::Normal if p.normal == [0.0; 3] => [0.0; 3],
            DisplayMode::Normal => p.normal.map(|n| unit(0.5 * n + 0.5)),
            DisplayMode::Variance => {
                let v = (p.variance.iter().sum::<f32>() / 3.0).max(0.0);
                [unit(v.sqrt() * self.variance_scale); 3]
            }
        }
    }

    /// The RGBA8 bytes of `p` (alpha 255).
    pub fn rgba8(&self, p: &PixelState) -> [u8; 4] {
        let [r, g, b] = self.shade(p).map(splat_core::image::to_u8);
        [r, g, b, 255]
    }

    /// The uniform block of display.wgsl for `frames` frames of a `width` × `height` view,
    /// drawn into a target of `format`.
    pub(crate) fn uniform(&self, width: u32, height: u32, frames: u32, format: wgpu::TextureFormat) -> DisplayParams {
        DisplayParams {
            mode: self.mode as u32,
            frames,
            width,
            height,
            depth_near: self.depth_near,
            depth_far: self.depth_far,
            variance_scale: self.variance_scale,
            srgb_target: u32::from(format.is_srgb()),
        }
    }
}

/// The texels of an 8-bit RGBA `texture` (one with `COPY_SRC` usage), row after row without
/// padding: what a view shows, for screenshots and tests. Waits for the queue. A caller that
/// reads a texture every step keeps an [`Rgba8Readback`] instead.
pub fn read_rgba8(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
) -> Result<Vec<u8>, crate::GpuError> {
    Rgba8Readback::default().read(device, queue, texture)
}

/// [`read_rgba8`] with its staging buffer kept between reads of textures of one size (a view's
/// host copy, read back at every step), made again when the size changes.
#[derive(Debug, Default)]
pub struct Rgba8Readback {
    buffer: Option<wgpu::Buffer>,
}

impl Rgba8Readback {
    /// The texels of `texture`, as [`read_rgba8`] returns them.
    pub fn read(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        texture: &wgpu::Texture,
    ) -> Result<Vec<u8>, crate::GpuError> {
        let (w, h) = (texture.width(), texture.height());
        if texture.format().block_copy_size(None) != Some(4) {
            return Err(crate::GpuError::Unsupported(format!("{:?} is not 4 bytes a texel", texture.format())));
        }
        let row = (4 * w).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let size = u64::from(row) * u64::from(h);
        let buffer = match self.buffer.take() {
            Some(buffer) if buffer.size() == size => buffer,
            _ => device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("texels"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        };
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("texels") });
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(h) },
            },
            texture.size(),
        );
        queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        let failed = |e: String| crate::GpuError::Readback(e);
        device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| failed(e.to_string()))?;
        rx.recv().map_err(|e| failed(e.to_string()))?.map_err(|e| failed(e.to_string()))?;
        let mut texels = Vec::with_capacity(4 * w as usize * h as usize);
        {
            let data = buffer.slice(..).get_mapped_range().map_err(|e| failed(e.to_string()))?;
            for r in data.chunks(row as usize) {
                texels.extend_from_slice(&r[..4 * w as usize]);
            }
        }
        // Kept (unmapped) for the next read; on an error above it is dropped instead.
        buffer.unmap();
        self.buffer = Some(buffer);
        Ok(texels)
    }
}

/// display.wgsl's `DisplayParams` (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct DisplayParams {
    mode: u32,
    frames: u32,
    width: u32,
    height: u32,
    depth_near: f32,
    depth_far: f32,
    variance_scale: f32,
    srgb_target: u32,
}

/// The WGSL of the display pass (entry points `vs_main`, `fs_main`), with the `Pick` it shares
/// with the ray-tracing kernel.
pub const DISPLAY_WGSL: &str = concat!(include_str!("../shaders/pick.wgsl"), include_str!("../shaders/display.wgsl"));

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::wgsl_check::{assert_constants, assert_mirrors, validate};

    #[test]
    fn the_display_pass_validates_and_mirrors_its_rust_twin() {
        validate("display.wgsl", DISPLAY_WGSL);
        assert_mirrors!(
            DISPLAY_WGSL,
            DisplayParams,
            "DisplayParams",
            [mode, frames, width, height, depth_near, depth_far, variance_scale, srgb_target]
        );
        assert_mirrors!(DISPLAY_WGSL, crate::layout::GpuPick, "Pick", [normal, depth, picked, pad0, pad1, pad2]);
        assert_constants!(
            DISPLAY_WGSL,
            [
                "MODE_COLOUR" = DisplayMode::Colour as u32,
                "MODE_DEPTH" = DisplayMode::Depth as u32,
                "MODE_NORMAL" = DisplayMode::Normal as u32,
                "MODE_VARIANCE" = DisplayMode::Variance as u32,
            ]
        );
    }

    #[test]
    fn the_display_layout_matches_the_shader() {
        let entries = crate::progressive::DisplayPass::layout_entries();
        crate::layout::wgsl_check::check_layout("display", DISPLAY_WGSL, naga::valid::Capabilities::empty(), &entries);
    }

    fn pixel() -> PixelState {
        PixelState { mean: [0.25, 1.5, -0.1], variance: [0.04, 0.04, 0.04], depth: 2.5, normal: [0.0, 0.0, -1.0] }
    }

    #[test]
    fn each_mode_shows_its_quantity() {
        let d =
            DisplayTransform { depth_near: 1.0, depth_far: 4.0, variance_scale: 2.0, ..DisplayTransform::default() };
        let show = |mode| DisplayTransform { mode, ..d }.shade(&pixel());
        assert_eq!(show(DisplayMode::Colour), [0.25, 1.0, 0.0]);
        assert_eq!(show(DisplayMode::Depth), [0.5; 3]);
        assert_eq!(show(DisplayMode::Normal), [0.5, 0.5, 0.0]);
        let sd = show(DisplayMode::Variance)[0];
        assert!((sd - 0.4).abs() < 1e-6, "{sd}");
        let none = PixelState { depth: f32::NAN, normal: [0.0; 3], ..pixel() };
        assert_eq!(DisplayTransform { mode: DisplayMode::Depth, ..d }.shade(&none), [0.0; 3]);
        assert_eq!(DisplayTransform { mode: DisplayMode::Normal, ..d }.shade(&none), [0.0; 3]);
        assert_eq!(d.rgba8(&pixel()), [64, 255, 0, 255]);
    }
}
