//! A progressive ray-traced view, for interactive viewers: the per-pixel Welford state stays
//! on the device between steps, each [`ProgressiveTrace::step`] folds more frames into it, and
//! [`ProgressiveTrace::present`] draws what the chosen [`DisplayTransform`] shows into the caller's
//! texture view, with no readback. A camera move keeps the buffers (only a new size
//! reallocates) and restarts the accumulation; so does a new method.
//!
//! Frames `0..n` of a progressive view are the frames of [`GpuTracer::render`] with
//! `Frames { count: n, .. }`: the same keys, the same running mean.
//!
//! ```no_run
//! use splat_core::{RenderSettings, frame::Frames, scenes, trace::{Method, TraceScene}};
//! use splat_gpu::{DisplayTransform, GpuContext, GpuTracer, ProgressiveTrace, TracePipeline};
//! let ctx = GpuContext::new()?;
//! let pipeline = TracePipeline::new(&ctx)?;
//! let (scene, camera) = scenes::cloud();
//! let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
//! let tracer = GpuTracer::new(&ctx, &pipeline, &trace)?;
//! let mut view = ProgressiveTrace::new(&tracer, &camera, &Method::Stochastic, &Frames::default())?;
//! view.step(&tracer, 4)?;
//! let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
//!     label: None,
//!     size: wgpu::Extent3d { width: camera.width, height: camera.height, depth_or_array_layers: 1 },
//!     mip_level_count: 1,
//!     sample_count: 1,
//!     dimension: wgpu::TextureDimension::D2,
//!     format: wgpu::TextureFormat::Rgba8UnormSrgb,
//!     usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
//!     view_formats: &[],
//! });
//! let target = texture.create_view(&Default::default());
//! let mut encoder = ctx.device.create_command_encoder(&Default::default());
//! view.present(&ctx, &mut encoder, &target, texture.format(), &DisplayTransform::default())?;
//! ctx.queue.submit([encoder.finish()]);
//! # use splat_gpu::wgpu;
//! # Ok::<(), splat_gpu::GpuError>(())
//! ```

use crate::display::{DISPLAY_WGSL, DisplayParams, DisplayTransform};
use crate::layout::{self, GpuPick, Params};
use crate::trace::{
    DISPATCHES_PER_SUBMIT, LOOP_BUDGET, TraceTargets, busiest_pixel, dispatch_batch, frame_params, params_buffer,
};
use crate::{GpuContext, GpuError, GpuTracer, MethodParams};
use splat_core::Camera;
use splat_core::frame::{Frames, RenderOutput};
use splat_core::trace::Method;

/// A progressive ray-traced view of one [`GpuTracer`]'s scene (see the module documentation).
pub struct ProgressiveTrace {
    targets: TraceTargets,
    uniform: wgpu::Buffer,
    bind_group: crate::split::BindGroups,
    camera: Camera,
    method: Method,
    params: MethodParams,
    frames: Frames,
    done: u32,
    display: DisplayPass,
}

impl ProgressiveTrace {
    /// A view of `camera` rendering `method` with the seed and generator of `frames` (its
    /// count is ignored: [`ProgressiveTrace::step`] says how many frames to add).
    pub fn new(tracer: &GpuTracer, camera: &Camera, method: &Method, frames: &Frames) -> Result<Self, GpuError> {
        camera.validate().map_err(splat_core::RenderError::from)?;
        frames.keys(true)?;
        let ctx = tracer.context();
        let targets = TraceTargets::new(ctx, camera.width, camera.height);
        let uniform = params_buffer(ctx);
        let bind_group = tracer.bind_group(&uniform, &targets, None, None);
        Ok(Self {
            targets,
            uniform,
            bind_group,
            camera: *camera,
            method: *method,
            params: MethodParams::try_from(method)?,
            frames: *frames,
            done: 0,
            display: DisplayPass::new(ctx),
        })
    }

    /// Look through `camera` from now on and restart the accumulation. The buffers stay; a
    /// camera of another size replaces them.
    pub fn set_camera(&mut self, tracer: &GpuTracer, camera: &Camera) -> Result<(), GpuError> {
        camera.validate().map_err(splat_core::RenderError::from)?;
        if (camera.width, camera.height) != (self.targets.width, self.targets.height) {
            self.targets = TraceTargets::new(tracer.context(), camera.width, camera.height);
            self.bind_group = tracer.bind_group(&self.uniform, &self.targets, None, None);
        }
        self.camera = *camera;
        self.reset();
        Ok(())
    }

    /// Render `method` from now on and restart the accumulation.
    pub fn set_method(&mut self, method: &Method) -> Result<(), GpuError> {
        self.params = MethodParams::try_from(method)?;
        self.method = *method;
        self.reset();
        Ok(())
    }

    /// Draw the decisions from `frames`' seed and generator from now on and restart.
    pub fn set_frames(&mut self, frames: &Frames) -> Result<(), GpuError> {
        frames.keys(true)?;
        self.frames = *frames;
        self.reset();
        Ok(())
    }

    /// Forget the frames so far: the next step starts again at frame 0.
    pub fn reset(&mut self) {
        self.done = 0;
    }

    /// Frames folded in since the last reset.
    pub fn frames(&self) -> u32 {
        self.done
    }

    /// The camera the view looks through.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Whether more frames change nothing: a deterministic method (exact, k-buffer) on a
    /// scene without random parts is done after one frame.
    pub fn is_converged(&self, tracer: &GpuTracer) -> bool {
        self.done >= 1 && !(self.method.is_stochastic() || tracer.trace().is_random())
    }

    /// Fold up to `frames` more frames into the running state (one, then none, for a converged
    /// view) and return how many were submitted; the work is queued, not waited for. On a CPU
    /// adapter (lavapipe) each frame is its own dispatch and the step waits, to check the loop
    /// budget: [`GpuError::LoopBudget`] when a ray may have been cut short (the view then needs
    /// the CPU tracer).
    pub fn step(&mut self, tracer: &GpuTracer, frames: u32) -> Result<u32, GpuError> {
        let ctx = tracer.context();
        let count = if self.is_converged(tracer) {
            0
        } else if self.method.is_stochastic() || tracer.trace().is_random() {
            frames
        } else {
            frames.min(1)
        };
        let cpu_adapter = ctx.info.device_type == wgpu::DeviceType::Cpu;
        let per_dispatch = if cpu_adapter { 1 } else { ctx.frames_per_dispatch };
        let range = self.done..self.done + count;
        let params = frame_params(
            tracer.trace(),
            &self.camera,
            &self.params,
            &self.frames,
            layout::MODE_FRAMES,
            range,
            per_dispatch,
        );
        for batch in params.chunks(DISPATCHES_PER_SUBMIT as usize) {
            self.submit(tracer, batch);
        }
        self.done += count;
        if cpu_adapter && count > 0 {
            self.check_loop_budget(ctx)?;
        }
        Ok(count)
    }

    fn submit(&self, tracer: &GpuTracer, batch: &[Params]) {
        let ctx = tracer.context();
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("progressive") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("progressive"),
                timestamp_writes: None,
            });
            pass.set_pipeline(tracer.kernel());
            dispatch_batch(ctx, &mut pass, &self.uniform, &self.bind_group, batch, &self.camera);
        }
        ctx.submit(encoder.finish());
    }

    /// Refuse the state when its busiest pixel may have reached lavapipe's loop budget.
    fn check_loop_budget(&self, ctx: &GpuContext) -> Result<(), GpuError> {
        let m2 = ctx.read_f32(&self.targets.m2, self.pixels() * 4)?;
        let (iterations, pixel) = busiest_pixel(&m2);
        let lanes = ctx.lanes();
        if u64::from(iterations) * u64::from(lanes) >= u64::from(LOOP_BUDGET) {
            let width = self.camera.width;
            return Err(GpuError::LoopBudget { x: pixel % width, y: pixel / width, iterations, lanes });
        }
        Ok(())
    }

    fn pixels(&self) -> usize {
        self.camera.width as usize * self.camera.height as usize
    }

    /// Encode the display pass: `display` of the state so far drawn into `target` (a view of a
    /// texture of `format` with `RENDER_ATTACHMENT` usage and the view's size, one texel per
    /// pixel). Any colour format renders; into an sRGB format the stored value is the display
    /// value, as into a unorm one. Choose the format for whoever samples the texture: a UI
    /// that treats sampled texels as gamma-encoded (egui-wgpu does) needs a unorm texture, as
    /// the sampler decodes an sRGB one. The display parameters are written to the queue now,
    /// so the last of several presents before a submission sets them for all.
    pub fn present(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        display: &DisplayTransform,
    ) -> Result<(), GpuError> {
        let params = display.uniform(self.camera.width, self.camera.height, self.done, format);
        ctx.queue.write_buffer(&self.display.uniform, 0, bytemuck::bytes_of(&params));
        let pipeline = self.display.pipeline(ctx, format)?.clone();
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("display"),
            layout: &self.display.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.display.uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: self.targets.mean.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: self.targets.m2.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: self.targets.pick.as_entire_binding() },
            ],
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("display"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::BLACK), store: wgpu::StoreOp::Store },
            })],
            ..Default::default()
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.draw(0..3, 0..1);
        Ok(())
    }

    /// Wait for the queued frames and read the state back as the images of a render.
    pub fn read(&self, ctx: &GpuContext) -> Result<RenderOutput, GpuError> {
        let words = self.pixels() * 4;
        let mean = ctx.read_f32(&self.targets.mean, words)?;
        let m2 = ctx.read_f32(&self.targets.m2, words)?;
        let picks = ctx.read_u32(&self.targets.pick, self.pixels() * std::mem::size_of::<GpuPick>() / 4)?;
        let (mut output, _) = crate::output(&self.camera, &mean, &m2, self.done.max(1), Default::default(), false);
        crate::trace::set_picks(&mut output, bytemuck::cast_slice(&picks));
        Ok(output)
    }
}

/// The display pipeline, compiled once per target format.
pub(crate) struct DisplayPass {
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    uniform: wgpu::Buffer,
    pipelines: Vec<(wgpu::TextureFormat, wgpu::RenderPipeline)>,
}

impl DisplayPass {
    fn new(ctx: &GpuContext) -> Self {
        let device = &ctx.device;
        let module = crate::context::shader_module(device, "display.wgsl", DISPLAY_WGSL);
        let (layout, pipeline_layout) = crate::context::layouts(device, "display", &Self::layout_entries());
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let uniform = ctx.buffer("display", std::mem::size_of::<DisplayParams>() as u64, usage);
        Self { module, layout, pipeline_layout, uniform, pipelines: Vec::new() }
    }

    /// The display pass's bindings (checked against `display.wgsl`'s by a test).
    pub(crate) fn layout_entries() -> [wgpu::BindGroupLayoutEntry; 4] {
        let fragment = wgpu::ShaderStages::FRAGMENT;
        [
            crate::context::params_entry(0, fragment, false, std::mem::size_of::<DisplayParams>()),
            crate::context::storage_entry(1, fragment, true),
            crate::context::storage_entry(2, fragment, true),
            crate::context::storage_entry(3, fragment, true),
        ]
    }

    fn pipeline(&mut self, ctx: &GpuContext, format: wgpu::TextureFormat) -> Result<&wgpu::RenderPipeline, GpuError> {
        if let Some(at) = self.pipelines.iter().position(|(f, _)| *f == format) {
            return Ok(&self.pipelines[at].1);
        }
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = ctx.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("display"),
            layout: Some(&self.pipeline_layout),
            vertex: wgpu::VertexState {
                module: &self.module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            fragment: Some(wgpu::FragmentState {
                module: &self.module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Unsupported(format!("the display pass cannot draw into {format:?}: {e}")));
        }
        self.pipelines.push((format, pipeline));
        Ok(&self.pipelines.last().expect("just pushed").1)
    }
}
