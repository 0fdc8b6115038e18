//! Temporal accumulation on the GPU: a running mean over frames, mean ← mix(mean, frame,
//! 1/(n + 1)), as the vk_gaussian_splatting post pass does, in a selectable storage format.
//! vk_gaussian_splatting warns that its default FP16 output drifts past ~150–200 accumulated
//! frames; a test measures that drift against an f64 mean.

use crate::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// WGSL of the accumulation kernel.
pub const ACCUMULATE_WGSL: &str = include_str!("../shaders/accumulate.wgsl");

pub use splat_core::frame::AccumulationFormat;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct AccParams {
    count: u32,
    frame: u32,
    format: u32,
    pad: u32,
}

/// A running mean of RGBA frames held on the GPU.
pub struct Accumulator {
    format: AccumulationFormat,
    pixels: usize,
    frames: u32,
    pipeline: wgpu::ComputePipeline,
    frame_in: wgpu::Buffer,
    acc32: wgpu::Buffer,
    acc16: wgpu::Buffer,
    acc8: wgpu::Buffer,
}

impl Accumulator {
    /// An empty accumulator of `pixels` RGBA pixels.
    pub fn new(ctx: &GpuContext, pixels: usize, format: AccumulationFormat) -> Self {
        let module = crate::context::shader_module(&ctx.device, "accumulate.wgsl", ACCUMULATE_WGSL);
        let pipeline = crate::context::compute_pipeline(&ctx.device, &module, None, "accumulate");
        let buffer = |label, bytes: usize, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16) as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let (b32, b16, b8) = match format {
            AccumulationFormat::F32 => (16 * pixels, 16, 16),
            AccumulationFormat::F16 => (16, 8 * pixels, 16),
            AccumulationFormat::Unorm8 => (16, 16, 4 * pixels),
        };
        Self {
            format,
            pixels,
            frames: 0,
            frame_in: buffer("frame", 16 * pixels, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST),
            acc32: buffer("acc32", b32, rw),
            acc16: buffer("acc16", b16, rw),
            acc8: buffer("acc8", b8, rw),
            pipeline,
        }
    }

    /// Frames accumulated so far.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Add one frame of RGBA values (`pixels` of them).
    pub fn add(&mut self, ctx: &GpuContext, frame: &[[f32; 4]]) -> Result<(), GpuError> {
        if frame.len() != self.pixels {
            return Err(GpuError::Unsupported(format!("frame has {} pixels, expected {}", frame.len(), self.pixels)));
        }
        ctx.queue.write_buffer(&self.frame_in, 0, bytemuck::cast_slice(frame));
        let params = AccParams { count: self.pixels as u32, frame: self.frames, format: self.format.code(), pad: 0 };
        let uniform = ctx.upload("acc params", bytemuck::bytes_of(&params));
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("accumulate"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: self.frame_in.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: self.acc32.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: self.acc16.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: self.acc8.as_entire_binding() },
            ],
        });
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("accumulate") });
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("accumulate"), timestamp_writes: None });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            ctx.dispatch(&mut pass, (self.pixels as u32).div_ceil(64), 1, 1);
        }
        ctx.submit(encoder.finish());
        self.frames += 1;
        Ok(())
    }

    /// The running mean, decoded to f32 RGBA.
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<[f32; 4]>, GpuError> {
        let (source, bytes) = match self.format {
            AccumulationFormat::F32 => (&self.acc32, 16 * self.pixels),
            AccumulationFormat::F16 => (&self.acc16, 8 * self.pixels),
            AccumulationFormat::Unorm8 => (&self.acc8, 4 * self.pixels),
        };
        let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("acc readback"),
            size: bytes.max(16) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("acc read") });
        encoder.copy_buffer_to_buffer(source, 0, &staging, 0, bytes.max(16) as u64);
        ctx.submit(encoder.finish());
        let words: Vec<u32> = ctx.read_buffer(&staging)?.iter().map(|f| f.to_bits()).collect();
        Ok((0..self.pixels)
            .map(|i| match self.format {
                AccumulationFormat::F32 => [0, 1, 2, 3].map(|c| f32::from_bits(words[4 * i + c])),
                AccumulationFormat::F16 => {
                    let h =
                        |w: u32, hi: bool| half::f16::from_bits(if hi { (w >> 16) as u16 } else { w as u16 }).to_f32();
                    let (a, b) = (words[2 * i], words[2 * i + 1]);
                    [h(a, false), h(a, true), h(b, false), h(b, true)]
                }
                AccumulationFormat::Unorm8 => {
                    let w = words[i];
                    [0, 1, 2, 3].map(|c| ((w >> (8 * c)) & 0xff) as f32 / 255.0)
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    /// The accumulation shader is valid WGSL for naga (a shader error fails `cargo test`),
    /// with the one capability its f16 format needs: naga files `pack2x16float` /
    /// `unpack2x16float` under `SHADER_FLOAT16_IN_FLOAT32`, which wgpu grants with the
    /// downlevel flag `SHADER_F16_IN_F32` (every Vulkan, Metal and DX12 adapter; not every GL).
    #[test]
    fn accumulate_wgsl_validates() {
        let f16 = naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32;
        crate::layout::wgsl_check::validate_with("accumulate", super::ACCUMULATE_WGSL, f16);
    }
}
