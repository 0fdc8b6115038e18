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

pub use accumulate::{AccumulationFormat, Accumulator};
pub use layout::{GpuParticle, Params};

use splat_core::Camera;
use splat_core::image::Image;
use splat_core::trace::{Frames, MAX_SLOTS, Method, TraceScene};
use std::time::{Duration, Instant};
use thiserror::Error;
use wgpu::util::DeviceExt;

/// WGSL of the ray-tracing kernel.
pub const TRACE_WGSL: &str = include_str!("../../../shaders/trace.wgsl");
/// Frames rendered per dispatch; longer runs are split so that no dispatch runs for long.
pub const FRAMES_PER_DISPATCH: u32 = 32;

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
        let required_features = if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() };
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
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(TRACE_WGSL.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("trace"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let max_binding = u64::from(limits.max_storage_buffer_binding_size).min(limits.max_buffer_size);
        Ok(Self { device, queue, info, max_binding, timestamps, pipeline })
    }

    /// Lower the storage binding limit scenes are checked against (to test the refusal).
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.max_binding = self.max_binding.min(bytes);
        self
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
        let sh = layout::sh(trace);
        let count = trace.scene().particles.len();
        let check = |buffer: &'static str, bytes: usize| {
            let bytes = bytes as u64;
            if bytes > ctx.max_binding {
                return Err(GpuError::SceneTooLarge { buffer, bytes, limit: ctx.max_binding, count });
            }
            Ok(())
        };
        check("particle", std::mem::size_of_val(particles.as_slice()))?;
        check("BVH node", std::mem::size_of_val(nodes.as_slice()))?;
        check("SH", std::mem::size_of_val(sh.as_slice()))?;
        let storage = |label, contents: &[u8]| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        Ok(Self {
            particles: storage("particles", bytemuck::cast_slice(&particles)),
            nodes: storage("nodes", bytemuck::cast_slice(&nodes)),
            sh: storage("sh", bytemuck::cast_slice(&sh)),
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
    /// GPU time of the dispatches (timestamp queries when available, else wall time around
    /// submit and poll).
    pub gpu_time: Duration,
}

/// The kernel's method code and parameters for a method; `exact` is the k-buffer with the
/// largest k, no early-out and no pass limit.
fn method_code(method: &Method) -> Result<(u32, u32, u32, f32, u32, u32), GpuError> {
    method.validate()?;
    Ok(match *method {
        Method::Exact => (1, MAX_SLOTS as u32, u32::MAX, 0.0, 1, 1),
        Method::KBuffer { k, max_passes, min_transmittance } => (1, k as u32, max_passes, min_transmittance, 1, 1),
        Method::Stochastic => (2, 1, 1, 0.0, 1, 1),
        Method::StochasticN { m, n } => (3, 1, 1, 0.0, n, m),
        Method::StochasticPass { k, max_passes } => (4, k as u32, max_passes, 0.0, 1, 1),
        Method::DepthSampling { k } => (5, k as u32, 1, 0.0, 1, 1),
        Method::Opaque => return Err(GpuError::Unsupported("the opaque baseline runs on the CPU only".into())),
    })
}

/// Render `frames.count` frames of `method` (one for a deterministic method) through pixel
/// centres, as [`splat_core::trace::render_frames`] does, on the GPU. Frames are dispatched in
/// chunks of [`FRAMES_PER_DISPATCH`]; each chunk's mean and variance are merged in f64.
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
    let pixels = camera.width as usize * camera.height as usize;
    let out_bytes = (pixels * 16) as u64;
    let storage_out = |label| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: out_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    };
    let (out_mean, out_var) = (storage_out("mean"), storage_out("variance"));
    let readback = |label| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: out_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    };
    let (read_mean, read_var) = (readback("read mean"), readback("read variance"));
    let mut merged = vec![[(0u64, 0.0f64, 0.0f64); 4]; pixels];
    let mut gpu_time = Duration::ZERO;
    let mut first = 0u32;
    while first < count {
        let chunk = FRAMES_PER_DISPATCH.min(count - first);
        let params = layout::params(trace, camera, code, frames, first, chunk);
        let uniform = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("trace"),
            layout: &ctx.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: scene.particles.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: scene.nodes.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: scene.sh.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: out_mean.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: out_var.as_entire_binding() },
            ],
        });
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("trace") });
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("trace"), timestamp_writes: None });
            pass.set_pipeline(&ctx.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
        }
        encoder.copy_buffer_to_buffer(&out_mean, 0, &read_mean, 0, out_bytes);
        encoder.copy_buffer_to_buffer(&out_var, 0, &read_var, 0, out_bytes);
        let start = Instant::now();
        ctx.queue.submit([encoder.finish()]);
        ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        gpu_time += start.elapsed();
        let (mean, var) = (ctx.read_buffer(&read_mean)?, ctx.read_buffer(&read_var)?);
        for (i, m) in merged.iter_mut().enumerate() {
            for (c, slot) in m.iter_mut().enumerate() {
                *slot = merge(*slot, (u64::from(chunk), f64::from(mean[4 * i + c]), f64::from(var[4 * i + c])));
            }
        }
        first += chunk;
    }
    let image = |c: usize, f: &dyn Fn(&(u64, f64, f64)) -> f64, offset: usize| {
        let data = merged.iter().flat_map(|m| m[offset..offset + c].iter().map(|v| f(v) as f32)).collect();
        Image::from_data(camera.width, camera.height, c as u32, data).expect("size")
    };
    Ok(GpuOutput {
        mean: image(3, &|v| v.1, 0),
        variance: image(3, &|v| v.2, 0),
        alpha: image(1, &|v| v.1, 3),
        gpu_time,
    })
}

/// Merge two (count, mean, unbiased variance) summaries (Chan et al.).
fn merge(a: (u64, f64, f64), b: (u64, f64, f64)) -> (u64, f64, f64) {
    if a.0 == 0 {
        return b;
    }
    let n = a.0 + b.0;
    let (na, nb) = (a.0 as f64, b.0 as f64);
    let delta = b.1 - a.1;
    let mean = a.1 + delta * nb / n as f64;
    let m2 = a.2 * (na - 1.0) + b.2 * (nb - 1.0) + delta * delta * na * nb / n as f64;
    (n, mean, if n > 1 { m2 / (n - 1) as f64 } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    use splat_core::stats::Welford;

    #[test]
    fn merging_chunks_equals_one_pass() {
        let xs: Vec<f64> = (0..37).map(|i| ((i * 7919) % 101) as f64 / 10.0).collect();
        let summary = |v: &[f64]| {
            let mut w = Welford::default();
            v.iter().for_each(|&x| w.push(x));
            (w.n, w.mean, w.variance())
        };
        let merged = merge(merge(summary(&xs[..5]), summary(&xs[5..6])), summary(&xs[6..]));
        let whole = summary(&xs);
        assert_eq!(merged.0, whole.0);
        assert!((merged.1 - whole.1).abs() < 1e-12 && (merged.2 - whole.2).abs() < 1e-10);
    }
}
