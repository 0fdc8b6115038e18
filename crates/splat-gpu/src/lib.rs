//! `splat-gpu`: wgpu compute ray tracing of transparent 3D Gaussians with every method of
//! [`splat_core::trace`], tested against the core.
//!
//! The kernel (`shaders/trace.wgsl`) traverses the BVH that `splat-core` builds, in software
//! (as Sun et al. do on Metal and low-end GPUs), with the same counter-based decisions, hit
//! conventions and defaults, so a GPU frame makes the CPU frame's accept/reject choices.
//!
//! ```no_run
//! use splat_core::{render::RenderSettings, scenes, trace::{Frames, Method, TraceScene}};
//! let ctx = splat_gpu::GpuContext::new()?;
//! let (scene, camera) = scenes::cloud();
//! let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
//! let gpu_scene = splat_gpu::GpuScene::new(&ctx, &trace)?;
//! let out = splat_gpu::render(&ctx, &gpu_scene, &trace, &camera, &Method::Stochastic, &Frames::default())?;
//! # Ok::<(), splat_gpu::GpuError>(())
//! ```

mod accumulate;
mod layout;
pub mod raster;
pub mod sort;

pub use wgpu;

pub use accumulate::{AccumulationFormat, Accumulator};
pub use layout::{GpuParticle, Params, PassState};
pub use raster::{DepthPick, GpuRasterizer, GpuSplat, RasterPipelines, RasterScene, RasterTimings};
pub use sort::RadixSort;

use splat_core::Camera;
use splat_core::image::Image;
use splat_core::trace::{Frames, Method, TraceScene};
use std::time::{Duration, Instant};
use thiserror::Error;
use wgpu::util::DeviceExt;

/// WGSL of the ray-tracing kernel.
pub const TRACE_WGSL: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/sh.wgsl"),
    include_str!("../../../shaders/trace.wgsl")
);
/// Dispatches encoded into one submission.
pub const DISPATCHES_PER_SUBMIT: u32 = 64;
/// Frames rendered per dispatch on a real GPU; longer runs are split so that no dispatch runs
/// for long. CPU adapters (lavapipe) render one frame per dispatch (see [`LOOP_BUDGET`]).
pub const FRAMES_PER_DISPATCH: u32 = 32;
/// lavapipe ends a loop after 65535 iterations of its SIMD loop per invocation (gallivm's loop
/// limiter), silently. A loop statement runs at most lanes × the busiest lane's total loop
/// iterations, which the kernel counts: on a CPU adapter [`render`] renders one frame per
/// dispatch and refuses a result where that bound reaches the budget.
pub const LOOP_BUDGET: u32 = 65_535;

/// Why the GPU path cannot run.
#[derive(Debug, Error)]
pub enum GpuError {
    /// No adapter matched.
    #[error(
        "no GPU adapter found{detail}. Install a Vulkan driver (on Debian/Ubuntu: `apt-get install mesa-vulkan-drivers`, which provides the lavapipe CPU driver) or choose a backend with WGPU_BACKEND=vulkan|gl|metal|dx12 and an adapter with WGPU_ADAPTER_NAME"
    )]
    NoAdapter {
        /// What was asked for.
        detail: String,
    },
    /// The adapter refused the device.
    #[error("the GPU adapter '{adapter}' refused a device: {message}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// Its reason.
        message: String,
    },
    /// The kernel failed validation or pipeline creation on this device.
    #[error("the GPU kernel was rejected by the device: {0}")]
    Shader(String),
    /// A buffer exceeds the adapter's storage binding limit.
    #[error(
        "the scene's {buffer} buffer needs {bytes} bytes but the adapter binds at most {limit} bytes per storage buffer ({count} particles); render it with --backend cpu or on an adapter with larger limits"
    )]
    SceneTooLarge {
        /// Which buffer.
        buffer: &'static str,
        /// Its size.
        bytes: u64,
        /// The adapter's limit.
        limit: u64,
        /// Particles in the scene.
        count: usize,
    },
    /// The method or its parameters cannot run on the GPU.
    #[error("{0}")]
    Unsupported(String),
    /// The scene or settings are invalid.
    #[error(transparent)]
    Render(#[from] splat_core::render::RenderError),
    /// Reading results back failed.
    #[error("GPU readback failed: {0}")]
    Readback(String),
    /// A ray may need more loop iterations than lavapipe allows one invocation.
    #[error(
        "pixel ({x}, {y}) ran {iterations} loop iterations in one frame; with {lanes} lanes in lockstep a loop of it may have reached lavapipe's limit of {LOOP_BUDGET} iterations, which silently cuts rays short. Use --backend cpu, a larger k (fewer passes), a smaller n, or a hardware GPU"
    )]
    LoopBudget {
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
        /// Loop iterations of the busiest lane.
        iterations: u32,
        /// Lanes in lockstep.
        lanes: u32,
    },
}

/// A headless wgpu device.
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What the adapter is.
    pub info: wgpu::AdapterInfo,
    /// Largest storage buffer binding accepted for a scene (the adapter's limit, or less).
    pub max_binding: u64,
    /// Whether timestamp queries are available.
    pub timestamps: bool,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    uniform_alignment: u64,
    /// Most frames one dispatch renders ([`FRAMES_PER_DISPATCH`] by default).
    pub frames_per_dispatch: u32,
}

impl GpuContext {
    /// The adapter chosen as wgpu's `from_env` helpers do: backends from `WGPU_BACKEND`, the
    /// first adapter whose name contains `WGPU_ADAPTER_NAME` (case-insensitive) when it is
    /// set, else the default adapter. A typed error, never a panic, when none matches.
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(name) => {
                let wanted = name.to_lowercase();
                let adapters = instance.enumerate_adapters(backends).await;
                adapters.into_iter().find(|a| a.get_info().name.to_lowercase().contains(&wanted)).ok_or_else(|| {
                    GpuError::NoAdapter { detail: format!(" whose name contains '{name}' (WGPU_ADAPTER_NAME)") }
                })?
            }
            Err(_) => instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::NoAdapter { detail: format!(" for backends {backends:?} ({e})") })?,
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        // Timestamps for the benchmarks and blendable RGBA32F targets for sorted splatting, where
        // the adapter has them.
        let required_features =
            adapter.features() & (wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::FLOAT32_BLENDABLE);
        // The kernels bind five storage buffers per stage (downlevel defaults allow four):
        // ask for what the adapter offers.
        let required_limits = limits.clone();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("splat"),
                required_features,
                required_limits,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device { adapter: info.name.clone(), message: e.to_string() })?;
        // Shader and pipeline errors come back as a typed error, not wgpu's panicking handler.
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(TRACE_WGSL.into()),
        });
        let storage = |binding, read_only| storage_entry(binding, wgpu::ShaderStages::COMPUTE, read_only);
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("trace"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::COMPUTE, true, std::mem::size_of::<Params>()),
                storage(1, true),
                storage(2, true),
                storage(3, true),
                storage(4, false),
                storage(5, false),
                storage(6, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("trace"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = compute_pipeline(&device, &module, Some(&pipeline_layout), "main");
        if let Some(e) = scope.pop().await {
            return Err(GpuError::Shader(e.to_string()));
        }
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let uniform_alignment = u64::from(limits.min_uniform_buffer_offset_alignment);
        Ok(Self {
            device,
            queue,
            info,
            max_binding,
            timestamps,
            pipeline,
            layout,
            uniform_alignment,
            frames_per_dispatch: FRAMES_PER_DISPATCH,
        })
    }

    /// Lower the storage binding limit scenes are checked against (to test the refusal).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.max_binding = self.max_binding.min(bytes);
        self
    }

    /// Invocations a CPU adapter runs in lockstep (its largest subgroup size, at most 128).
    pub fn lanes(&self) -> u32 {
        self.info.subgroup_max_size.clamp(1, 128)
    }

    /// One line naming the adapter.
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {})", self.info.name, self.info.backend, self.info.driver)
    }

    fn read_buffer(&self, buffer: &wgpu::Buffer) -> Result<Vec<f32>, GpuError> {
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = {
            let view = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
            bytemuck::cast_slice::<u8, f32>(&view).to_vec()
        };
        buffer.unmap();
        Ok(data)
    }

    /// Refuse a storage buffer of `bytes` above the binding limit, naming the buffer and the
    /// `count` of items (particles, keys) that needed it.
    pub(crate) fn check_binding(&self, buffer: &'static str, bytes: u64, count: usize) -> Result<(), GpuError> {
        if bytes > self.max_binding {
            return Err(GpuError::SceneTooLarge { buffer, bytes, limit: self.max_binding, count });
        }
        Ok(())
    }

    /// A read-only storage buffer holding `contents`.
    pub(crate) fn upload(&self, label: &str, contents: &[u8]) -> wgpu::Buffer {
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE,
        })
    }

    /// Copy `words` u32 of `source` from word `first` into a staging buffer and read them.
    pub(crate) fn read_u32_at(&self, source: &wgpu::Buffer, first: usize, words: usize) -> Result<Vec<u32>, GpuError> {
        let bytes = (4 * words.max(1)) as u64;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut data: Vec<u32> =
            self.read_through(source, 4 * first as u64, &staging, bytes)?.iter().map(|f| f.to_bits()).collect();
        data.truncate(words);
        Ok(data)
    }

    /// Copy `bytes` of `source` from byte `offset` into the mappable `staging` and read them.
    fn read_through(
        &self,
        source: &wgpu::Buffer,
        offset: u64,
        staging: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<f32>, GpuError> {
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_buffer_to_buffer(source, offset, staging, 0, bytes);
        self.queue.submit([encoder.finish()]);
        self.read_buffer(staging)
    }

    /// The first `words` u32 of `source`.
    pub(crate) fn read_u32(&self, source: &wgpu::Buffer, words: usize) -> Result<Vec<u32>, GpuError> {
        self.read_u32_at(source, 0, words)
    }

    /// The first `words` f32 of `source`.
    pub(crate) fn read_f32(&self, source: &wgpu::Buffer, words: usize) -> Result<Vec<f32>, GpuError> {
        Ok(self.read_u32(source, words)?.into_iter().map(f32::from_bits).collect())
    }
}

/// Images from per-pixel Welford state (mean RGBA, M2 RGB) of `count` frames.
pub(crate) fn output(
    camera: &Camera,
    mean: &[f32],
    m2: &[f32],
    count: u32,
    gpu_time: Duration,
    timestamps: bool,
) -> GpuOutput {
    let n = f64::from(count);
    let image = |channels, value: &dyn Fn(usize) -> f32| rgba_image(camera, channels, value);
    GpuOutput {
        mean: image(3, &|i| mean[i]),
        variance: image(3, &|i| if count > 1 { (f64::from(m2[i]) / (n - 1.0)) as f32 } else { 0.0 }),
        alpha: image(1, &|i| mean[i - i % 4 + 3]),
        loop_iterations: 0,
        frames_per_dispatch: 1,
        pass_per_dispatch: false,
        gpu_time,
        timestamps,
    }
}

/// An image of `channels` channels whose pixel p, channel c is `value(4p + c)`: the first
/// channels of a per-pixel RGBA buffer read back from the GPU.
pub(crate) fn rgba_image(camera: &Camera, channels: u32, value: &dyn Fn(usize) -> f32) -> Image {
    let pixels = camera.width as usize * camera.height as usize;
    let data = (0..pixels).flat_map(|p| (0..channels as usize).map(move |c| value(4 * p + c))).collect();
    Image::from_data(camera.width, camera.height, channels, data).expect("the buffer holds every pixel")
}

/// A storage-buffer entry of a bind group layout.
pub(crate) fn storage_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    read_only: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A uniform-buffer entry of at least `size` bytes, with a dynamic offset when `dynamic`.
pub(crate) fn uniform_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    dynamic: bool,
    size: usize,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: wgpu::BufferSize::new(size as u64),
        },
        count: None,
    }
}

/// A compute pipeline of `entry` (also its label); `layout: None` derives it from the shader.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: Option<&wgpu::PipelineLayout>,
    entry: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout,
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A scene uploaded to the GPU: particles in BVH leaf order, BVH nodes, SH coefficients.
pub struct GpuScene {
    particles: wgpu::Buffer,
    nodes: wgpu::Buffer,
    sh: wgpu::Buffer,
}

impl GpuScene {
    /// Upload the particles and BVH of a [`TraceScene`]; refuse buffers above the binding limit.
    pub fn new(ctx: &GpuContext, trace: &TraceScene) -> Result<Self, GpuError> {
        let particles = layout::particles(trace);
        let nodes = layout::nodes(trace);
        let sh = layout::sh(trace.scene());
        let count = trace.scene().particles.len();
        let bytes = |data: &[u8]| data.len() as u64;
        ctx.check_binding("particle", bytes(bytemuck::cast_slice(&particles)), count)?;
        ctx.check_binding("BVH node", bytes(bytemuck::cast_slice(&nodes)), count)?;
        ctx.check_binding("SH", bytes(bytemuck::cast_slice(&sh)), count)?;
        Ok(Self {
            particles: ctx.upload("particles", bytemuck::cast_slice(&particles)),
            nodes: ctx.upload("nodes", bytemuck::cast_slice(&nodes)),
            sh: ctx.upload("sh", bytemuck::cast_slice(&sh)),
        })
    }
}

/// Images of a GPU render, as [`splat_core::trace::TraceOutput`] without depth and normal.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuOutput {
    /// Mean radiance (RGB).
    pub mean: Image,
    /// Per-frame variance of the radiance (RGB).
    pub variance: Image,
    /// Mean coverage.
    pub alpha: Image,
    /// Most loop iterations one invocation ran in one dispatch (lavapipe's budget is 65535).
    pub loop_iterations: u32,
    /// Frames per dispatch the render settled on.
    pub frames_per_dispatch: u32,
    /// Whether rays ran one pass per dispatch (multi-pass methods over lavapipe's loop budget).
    pub pass_per_dispatch: bool,
    /// GPU time of the dispatches (timestamp queries when available, else wall time around
    /// submit and poll).
    pub gpu_time: Duration,
    /// Whether `gpu_time` comes from timestamp queries.
    pub timestamps: bool,
}

/// The kernel's method code and parameters for a method; `exact` is the k-buffer with no
/// early-out and no pass limit.
fn method_code(method: &Method) -> Result<(u32, u32, u32, f32, u32, u32), GpuError> {
    method.validate()?;
    Ok(match *method {
        // Any k gives Eq. 3 without the early-out; 18 keeps each pass short.
        Method::Exact => (1, splat_core::trace::DEFAULT_K as u32, u32::MAX, 0.0, 1, 1),
        Method::KBuffer { k, max_passes, min_transmittance } => (1, k as u32, max_passes, min_transmittance, 1, 1),
        Method::Stochastic => (2, 1, 1, 0.0, 1, 1),
        Method::StochasticN { m, n } => (3, 1, 1, 0.0, n, m),
        Method::StochasticPass { k, max_passes } => (4, k as u32, max_passes, 0.0, 1, 1),
        Method::DepthSampling { k } => (5, k as u32, 1, 0.0, 1, 1),
        Method::Opaque => return Err(GpuError::Unsupported("the opaque baseline runs on the CPU only".into())),
    })
}

/// Render `frames.count` frames of `method` (one for a deterministic method) through pixel
/// centres, as [`splat_core::trace::render_frames`] does, on the GPU: per pixel a running
/// Welford mean and M2 in f32, frames in dispatches of up to [`FRAMES_PER_DISPATCH`].
///
/// On a CPU adapter (lavapipe) every dispatch renders one frame, since its loop limiter counts
/// per invocation, and the render fails with [`GpuError::LoopBudget`] rather than return an
/// image whose rays may have been cut short (see [`LOOP_BUDGET`]).
pub fn render(
    ctx: &GpuContext,
    scene: &GpuScene,
    trace: &TraceScene,
    camera: &Camera,
    method: &Method,
    frames: &Frames,
) -> Result<GpuOutput, GpuError> {
    camera.validate().map_err(splat_core::render::RenderError::from)?;
    if frames.count == 0 {
        return Err(GpuError::Unsupported("at least one frame is needed".into()));
    }
    let code = method_code(method)?;
    let count = if method.is_stochastic() { frames.count } else { 1 };
    let cpu_adapter = ctx.info.device_type == wgpu::DeviceType::Cpu;
    let per_dispatch = if cpu_adapter { 1 } else { ctx.frames_per_dispatch };
    let run = Run { ctx, scene, trace, camera, code, frames, count };
    let lanes = u64::from(ctx.lanes());
    let over = |f: &Finished| cpu_adapter && u64::from(f.loop_iterations.0) * lanes >= u64::from(LOOP_BUDGET);
    let mut out = run.execute(per_dispatch, false)?;
    // Multi-pass methods (and stochastic-n, slot by slot) that do not fit run again with one
    // pass per dispatch.
    let multi_pass = matches!(code.0, 1 | 3 | 4);
    if over(&out) && multi_pass {
        out = run.execute(1, true)?;
    }
    if over(&out) {
        let (iterations, pixel) = out.loop_iterations;
        let lanes = lanes as u32;
        return Err(GpuError::LoopBudget { x: pixel % camera.width, y: pixel / camera.width, iterations, lanes });
    }
    Ok(out.output)
}

/// A finished render with the busiest pixel's loop count (count, pixel index).
struct Finished {
    output: GpuOutput,
    loop_iterations: (u32, u32),
}

/// One attempt at a render.
struct Run<'a> {
    ctx: &'a GpuContext,
    scene: &'a GpuScene,
    trace: &'a TraceScene<'a>,
    camera: &'a Camera,
    code: (u32, u32, u32, f32, u32, u32),
    frames: &'a Frames,
    count: u32,
}

impl Run<'_> {
    fn storage(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage,
            mapped_at_creation: false,
        })
    }

    /// Render with `per_dispatch` frames a dispatch, or, with `by_pass`, one pass of one frame
    /// per dispatch (k-buffer and stochastic pass), the rays' state kept between dispatches.
    fn execute(&self, per_dispatch: u32, by_pass: bool) -> Result<Finished, GpuError> {
        let (ctx, camera) = (self.ctx, self.camera);
        let pixels = camera.width as usize * camera.height as usize;
        let out_bytes = (pixels * 16) as u64;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let (out_mean, out_var) = (self.storage("mean", out_bytes, rw), self.storage("m2", out_bytes, rw));
        let (read_mean, read_var) =
            (self.storage("read mean", out_bytes, read), self.storage("read m2", out_bytes, read));
        let state_bytes = (pixels * std::mem::size_of::<PassState>()) as u64;
        let pass_state = self.storage("pass state", state_bytes, rw);
        let read_state = self.storage("read pass state", state_bytes, read);
        let stride = (std::mem::size_of::<Params>() as u64).next_multiple_of(ctx.uniform_alignment);
        let uniform = self.storage(
            "params",
            stride * u64::from(DISPATCHES_PER_SUBMIT),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("trace"),
            layout: &ctx.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &uniform,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<Params>() as u64),
                    }),
                },
                wgpu::BindGroupEntry { binding: 1, resource: self.scene.particles.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: self.scene.nodes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: self.scene.sh.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: out_mean.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: out_var.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 6, resource: pass_state.as_entire_binding() },
            ],
        });
        let mut gpu_time = Duration::ZERO;
        let timer = ctx.timestamps.then(|| Timer::new(ctx));
        // Submit the dispatches of `params`, one batch per submission.
        let mut submit = |params: &[Params]| -> Result<(), GpuError> {
            for batch in params.chunks(DISPATCHES_PER_SUBMIT as usize) {
                let mut params_bytes = vec![0u8; stride as usize * batch.len()];
                for (slot, p) in batch.iter().enumerate() {
                    let at = slot * stride as usize;
                    params_bytes[at..at + std::mem::size_of::<Params>()].copy_from_slice(bytemuck::bytes_of(p));
                }
                ctx.queue.write_buffer(&uniform, 0, &params_bytes);
                let mut encoder =
                    ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("trace") });
                {
                    let timestamp_writes = timer.as_ref().map(|t| wgpu::ComputePassTimestampWrites {
                        query_set: &t.queries,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    });
                    let mut pass = encoder
                        .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("trace"), timestamp_writes });
                    pass.set_pipeline(&ctx.pipeline);
                    for slot in 0..batch.len() {
                        pass.set_bind_group(0, &bind_group, &[(slot as u64 * stride) as u32]);
                        pass.dispatch_workgroups(camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
                    }
                }
                if let Some(t) = &timer {
                    t.resolve(&mut encoder);
                }
                let start = Instant::now();
                ctx.queue.submit([encoder.finish()]);
                ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
                gpu_time += match &timer {
                    Some(t) => t.elapsed(ctx)?,
                    None => start.elapsed(),
                };
            }
            Ok(())
        };
        if by_pass {
            // stochastic-n runs one slot per dispatch: m × n "passes" of n = 1 slot.
            let (method, _, passes, _, n, m) = self.code;
            let (max_passes, slots, chunk) = if method == 3 { (n * m, n * m, 1) } else { (passes, m, n) };
            for frame in 0..self.count {
                let mut pass_index = 0u32;
                while pass_index < max_passes {
                    let batch: Vec<Params> = (pass_index..max_passes.min(pass_index.saturating_add(8)))
                        .map(|p| Params {
                            mode: 1,
                            pass_index: p,
                            max_passes,
                            m: slots,
                            n: chunk,
                            ..layout::params(self.trace, camera, self.code, self.frames, frame, 1)
                        })
                        .collect();
                    pass_index += batch.len() as u32;
                    submit(&batch)?;
                    let states = self.ctx.read_through(&pass_state, 0, &read_state, state_bytes)?;
                    if states.chunks(8).all(|s| s[6].to_bits() & 1 == 1) {
                        break;
                    }
                }
            }
        } else {
            let mut params = Vec::new();
            let mut first = 0u32;
            while first < self.count {
                let chunk = per_dispatch.min(self.count - first);
                params.push(layout::params(self.trace, camera, self.code, self.frames, first, chunk));
                first += chunk;
            }
            submit(&params)?;
        }
        let mean = self.ctx.read_through(&out_mean, 0, &read_mean, out_bytes)?;
        let m2 = self.ctx.read_through(&out_var, 0, &read_var, out_bytes)?;
        let busiest = m2.chunks(4).enumerate().map(|(p, v)| (v[3] as u32, p as u32)).max().unwrap_or((0, 0));
        let output = GpuOutput {
            loop_iterations: busiest.0,
            frames_per_dispatch: per_dispatch,
            pass_per_dispatch: by_pass,
            ..output(camera, &mean, &m2, self.count, gpu_time, timer.is_some())
        };
        Ok(Finished { output, loop_iterations: busiest })
    }
}

/// Timestamp queries at the start and end of each compute pass.
struct Timer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl Timer {
    fn new(ctx: &GpuContext) -> Self {
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass time"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let buffer = |label, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Self {
            queries,
            resolved: buffer("timestamps", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
            staging: buffer("read timestamps", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
        }
    }

    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.staging, 0, 16);
    }

    /// Time between the two timestamps of the last submitted pass.
    fn elapsed(&self, ctx: &GpuContext) -> Result<Duration, GpuError> {
        let words = ctx.read_buffer(&self.staging)?;
        let ticks = |i: usize| u64::from(words[2 * i].to_bits()) | (u64::from(words[2 * i + 1].to_bits()) << 32);
        let nanos = ticks(1).saturating_sub(ticks(0)) as f64 * f64::from(ctx.queue.get_timestamp_period());
        Ok(Duration::from_nanos(nanos as u64))
    }
}
