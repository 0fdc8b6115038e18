//! GPU splatting: the twin of [`splat_core::raster`] for one sample per pixel (the 3DGS and
//! vk_gaussian_splatting rasterizers).
//!
//! Stages, each a kernel mirrored by a CPU function of the core:
//! 1. projection and culling, a compute pass (`shaders/raster.wgsl` `project` =
//!    [`splat_core::raster::project`]), which also writes the depth sort keys and counts the
//!    visible splats into the indirect draw arguments;
//! 2. the global depth sort by (depth, id): the [`RadixSort`] of the depth keys with the
//!    particle ids as values (stable, and the ids start in order, so equal depths stay in id
//!    order like the CPU's `sort_by(depth, id)`);
//! 3. sorted splatting in a render pipeline of instanced quads with the blend states of seed
//!    003 §1.5 (back-to-front *over*, front-to-back *under* with premultiplied alpha), or
//!    StochasticSplats (no sort, depth test and write, no blending, discard), frames folded
//!    into a running Welford mean like the ray tracer's;
//! 4. for the iso-opacity depth and the picked splat, a compute tile rasterizer
//!    ([`GpuRasterizer::depth_pick`]), whose doc explains why.
//!
//! ```no_run
//! use splat_core::{raster::{Blend, RasterMethod}, render::RenderSettings, scenes, trace::Frames};
//! let ctx = splat_gpu::GpuContext::new()?;
//! let pipes = splat_gpu::RasterPipelines::new(&ctx)?;
//! let (scene, camera) = scenes::cloud();
//! let gpu_scene = splat_gpu::RasterScene::new(&ctx, &scene, &RenderSettings::default())?;
//! let raster = splat_gpu::GpuRasterizer::new(&ctx, &pipes, &gpu_scene, &camera)?;
//! let sorted = raster.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default())?;
//! let stochastic = raster.render(&RasterMethod::StochasticSplat, &Frames { count: 64, ..Frames::default() })?;
//! # Ok::<(), splat_gpu::GpuError>(())
//! ```

use crate::sort::{RadixSort, SortBuffers, groups};
use crate::{GpuContext, GpuError, GpuOutput, compute_pipeline, storage_entry, uniform_entry};
use bytemuck::{Pod, Zeroable};
use splat_core::Camera;
use splat_core::image::Image;
use splat_core::particle::Scene;
use splat_core::raster::project::FRUSTUM_GUARD;
use splat_core::raster::{Blend, FragmentDepth, RasterMethod, RasterSettings};
use splat_core::render::{RenderError, RenderSettings, TILE, validate_scene};
use splat_core::trace::Frames;
use std::time::{Duration, Instant};
use wgpu::util::DeviceExt;

/// WGSL of the projection and tile kernels.
pub const RASTER_WGSL: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/sh.wgsl"),
    include_str!("../../../shaders/raster_types.wgsl"),
    include_str!("../../../shaders/raster.wgsl")
);
/// WGSL of the splatting render pipeline.
pub const SPLAT_WGSL: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/raster_types.wgsl"),
    include_str!("../../../shaders/splat.wgsl")
);
/// WGSL of the frame accumulation.
pub const FOLD_WGSL: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/raster_types.wgsl"),
    include_str!("../../../shaders/fold.wgsl")
);
/// Frames encoded into one submission (and uniform slots of per-frame parameters).
const FRAMES_PER_SUBMIT: u32 = 64;
/// No splat / no depth in a pick buffer.
const NONE: u32 = u32::MAX;

/// One particle in scene order (WGSL `RasterParticle`, 48 bytes): the 3D covariance is
/// computed once on the CPU, as the rasterizers of 3DGS precompute it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RasterParticle {
    /// Mean μ.
    pub mean: [f32; 3],
    /// Opacity.
    pub opacity: f32,
    /// Σ_xx, Σ_xy, Σ_xz.
    pub cov_a: [f32; 3],
    /// Padding.
    pub pad0: f32,
    /// Σ_yy, Σ_yz, Σ_zz.
    pub cov_b: [f32; 3],
    /// Padding.
    pub pad1: f32,
}

/// A projected splat (WGSL `Splat`, 64 bytes), the GPU form of [`splat_core::raster::Splat`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuSplat {
    /// Projected centre, pixels.
    pub mean: [f32; 2],
    /// View depth z.
    pub depth: f32,
    /// Opacity.
    pub opacity: f32,
    /// Inverse 2D covariance (a, b, c).
    pub conic: [f32; 3],
    /// Scene index.
    pub id: u32,
    /// SH colour.
    pub color: [f32; 3],
    /// Padding.
    pub pad: u32,
    /// Pixel rect [x0, y0, x1, y1); empty when the particle is culled.
    pub rect: [u32; 4],
}

/// Per-camera uniforms of the raster kernels (WGSL `RasterParams`, 160 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RasterParams {
    /// World-to-camera rotation, row 0.
    pub cam_row0: [f32; 4],
    /// Row 1.
    pub cam_row1: [f32; 4],
    /// Row 2.
    pub cam_row2: [f32; 4],
    /// World-to-camera translation.
    pub cam_translation: [f32; 4],
    /// fx, fy, cx, cy.
    pub intrinsics: [f32; 4],
    /// Background RGB.
    pub background: [f32; 4],
    /// Image width and height.
    pub size: [u32; 2],
    /// Particles.
    pub count: u32,
    /// SH degree.
    pub sh_degree: u32,
    /// Kernel degree.
    pub kernel_degree: u32,
    /// Alpha clamp.
    pub alpha_clamp: f32,
    /// Alpha cull.
    pub alpha_cull: f32,
    /// Iso-opacity threshold on the transmittance.
    pub iso_threshold: f32,
    /// Frustum guard limits on |x/z|, |y/z|.
    pub guard: [f32; 2],
    /// Tiles across and down.
    pub tiles: [u32; 2],
    /// 0 over, 1 under, 2 stochastic splat.
    pub mode: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
    /// Padding.
    pub pad2: u32,
}

/// Per-frame uniforms (WGSL `FrameParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FrameParams {
    /// The frame key of the hashes ([`splat_core::rng::frame_key`]).
    pub key: u32,
    /// Index of the frame in the running mean.
    pub index: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
}

/// Which render pipeline draws a method.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Draw {
    Over,
    Under,
    Stochastic,
}

impl Draw {
    fn of(method: &RasterMethod) -> Result<Self, GpuError> {
        Ok(match method {
            RasterMethod::Sorted { blend: Blend::Over } => Draw::Over,
            RasterMethod::Sorted { blend: Blend::Under } => Draw::Under,
            RasterMethod::StochasticSplat => Draw::Stochastic,
            other => {
                return Err(GpuError::Unsupported(format!(
                    "{other:?} runs on the CPU only; the GPU rasterizes raster-sorted and stochastic-splat"
                )));
            }
        })
    }

    fn mode(self) -> u32 {
        match self {
            Draw::Over => 0,
            Draw::Under => 1,
            Draw::Stochastic => 2,
        }
    }
}

/// The compiled kernels and pipelines of the splatting path.
pub struct RasterPipelines {
    sort: RadixSort,
    project: wgpu::ComputePipeline,
    tile_count: wgpu::ComputePipeline,
    tile_emit: wgpu::ComputePipeline,
    tile_ranges: wgpu::ComputePipeline,
    tile_blend: wgpu::ComputePipeline,
    splat_layout: wgpu::BindGroupLayout,
    over: wgpu::RenderPipeline,
    under: wgpu::RenderPipeline,
    stochastic: wgpu::RenderPipeline,
    fold_layout: wgpu::BindGroupLayout,
    fold: wgpu::ComputePipeline,
    /// Colour target of sorted blending: RGBA32F where the adapter blends it, else RGBA16F.
    pub blend_format: wgpu::TextureFormat,
}

/// Colour target of a stochastic frame (written, never blended).
const STOCHASTIC_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl RasterPipelines {
    /// Compile every raster kernel; a typed error when the device rejects one.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let sort = RadixSort::new(ctx)?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = |label, source: &str| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        };
        let raster = module("raster.wgsl", RASTER_WGSL);
        let splat = module("splat.wgsl", SPLAT_WGSL);
        let fold = module("fold.wgsl", FOLD_WGSL);
        let draw_stages = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let splat_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat"),
            entries: &[
                uniform_entry(0, draw_stages, false, size_of::<RasterParams>()),
                uniform_entry(1, draw_stages, true, size_of::<FrameParams>()),
                storage_entry(2, draw_stages, true),
                storage_entry(3, wgpu::ShaderStages::VERTEX, true),
                storage_entry(4, wgpu::ShaderStages::VERTEX, true),
            ],
        });
        let fold_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("fold"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::COMPUTE, false, size_of::<RasterParams>()),
                uniform_entry(1, wgpu::ShaderStages::COMPUTE, true, size_of::<FrameParams>()),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                storage_entry(3, wgpu::ShaderStages::COMPUTE, false),
                storage_entry(4, wgpu::ShaderStages::COMPUTE, false),
            ],
        });
        let pipeline_layout = |label, layout: &wgpu::BindGroupLayout| {
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(layout)],
                immediate_size: 0,
            })
        };
        let splat_pipeline_layout = pipeline_layout("splat", &splat_layout);
        let blend_format = if device.features().contains(wgpu::Features::FLOAT32_BLENDABLE) {
            wgpu::TextureFormat::Rgba32Float
        } else {
            wgpu::TextureFormat::Rgba16Float
        };
        let render = |entry, format, blend: Option<wgpu::BlendState>, depth: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&splat_pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &splat,
                    entry_point: Some("vs"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: depth.then(|| wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &splat,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState { format, blend, write_mask: wgpu::ColorWrites::ALL })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let component =
            |src, dst| wgpu::BlendComponent { src_factor: src, dst_factor: dst, operation: wgpu::BlendOperation::Add };
        use wgpu::BlendFactor::{One, OneMinusDstAlpha, OneMinusSrcAlpha, SrcAlpha};
        // Seed 003 §1.5.1 for the colour. The alpha channel uses the over operator too (ONE,
        // ONE_MINUS_SRC_ALPHA) so that it holds the coverage 1 − T; vk's additive ONE / ONE
        // alpha (a sum of opacities) is read only by its mesh pass, which we do not have.
        let over =
            wgpu::BlendState { color: component(SrcAlpha, OneMinusSrcAlpha), alpha: component(One, OneMinusSrcAlpha) };
        // Seed 003 §1.5.2: premultiplied colour and alpha, ONE_MINUS_DST_ALPHA / ONE.
        let under =
            wgpu::BlendState { color: component(OneMinusDstAlpha, One), alpha: component(OneMinusDstAlpha, One) };
        let pipes = Self {
            project: compute_pipeline(device, &raster, None, "project"),
            tile_count: compute_pipeline(device, &raster, None, "tile_count"),
            tile_emit: compute_pipeline(device, &raster, None, "tile_emit"),
            tile_ranges: compute_pipeline(device, &raster, None, "tile_ranges"),
            tile_blend: compute_pipeline(device, &raster, None, "tile_blend"),
            over: render("fs_sorted", blend_format, Some(over), false),
            under: render("fs_sorted", blend_format, Some(under), false),
            stochastic: render("fs_stochastic", STOCHASTIC_FORMAT, None, true),
            fold: compute_pipeline(device, &fold, Some(&pipeline_layout("fold", &fold_layout)), "fold"),
            splat_layout,
            fold_layout,
            blend_format,
            sort,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(e.to_string()));
        }
        Ok(pipes)
    }

    /// The radix sort.
    pub fn sort(&self) -> &RadixSort {
        &self.sort
    }

    fn render_pipeline(&self, draw: Draw) -> &wgpu::RenderPipeline {
        match draw {
            Draw::Over => &self.over,
            Draw::Under => &self.under,
            Draw::Stochastic => &self.stochastic,
        }
    }
}

/// A scene uploaded for rasterization: particles (mean, opacity, covariance) and SH in scene
/// order.
pub struct RasterScene {
    particles: wgpu::Buffer,
    sh: wgpu::Buffer,
    count: u32,
    sh_degree: u32,
    settings: RenderSettings,
}

impl RasterScene {
    /// Validate and upload `scene`; refuse buffers above the adapter's binding limit.
    pub fn new(ctx: &GpuContext, scene: &Scene, settings: &RenderSettings) -> Result<Self, GpuError> {
        validate_scene(scene, settings)?;
        let count = scene.particles.len();
        let particles: Vec<RasterParticle> = scene
            .particles
            .iter()
            .map(|p| {
                let c = p.covariance();
                RasterParticle {
                    mean: p.mean.to_array(),
                    opacity: p.opacity,
                    cov_a: [c.x_axis.x, c.y_axis.x, c.z_axis.x],
                    pad0: 0.0,
                    cov_b: [c.y_axis.y, c.z_axis.y, c.z_axis.z],
                    pad1: 0.0,
                }
            })
            .collect();
        let sh = crate::layout::sh(scene);
        ctx.check_binding("splat", (count.max(1) * size_of::<GpuSplat>()) as u64, count)?;
        ctx.check_binding("SH", (sh.len() * 16) as u64, count)?;
        if particles.is_empty() {
            return Err(GpuError::Render(RenderError::Settings("the scene has no particles".into())));
        }
        Ok(Self {
            particles: ctx.upload("raster particles", bytemuck::cast_slice(&particles)),
            sh: ctx.upload("raster sh", bytemuck::cast_slice(&sh)),
            count: count as u32,
            sh_degree: u32::from(scene.sh_degree),
            settings: *settings,
        })
    }
}

/// Iso-opacity depth and picked splat of every pixel, with the front-to-back colour they come
/// from (the GPU twin of sorted splatting with [`Blend::Under`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthPick {
    /// Front-to-back colour over the background (RGB).
    pub color: Image,
    /// Coverage 1 − T.
    pub alpha: Image,
    /// Iso-opacity depth: distance along the pixel-centre ray, `None` where T never fell
    /// below the threshold.
    pub depth: Vec<Option<f32>>,
    /// Scene index of the splat that set the depth.
    pub picked: Vec<Option<u32>>,
    /// (tile, splat) pairs the tile lists held.
    pub pairs: u32,
}

/// GPU times of one frame's stages, from timestamp queries when the adapter has them, else
/// wall time around each stage's own submission.
#[derive(Clone, Copy, Debug, Default)]
pub struct RasterTimings {
    /// Projection and culling.
    pub project: Duration,
    /// Depth sort.
    pub sort: Duration,
    /// Sorted splatting (over) of every visible splat.
    pub draw_sorted: Duration,
    /// One StochasticSplats frame (1 spp) of every particle.
    pub draw_stochastic: Duration,
    /// Whether the times come from timestamp queries.
    pub timestamps: bool,
}

impl RasterTimings {
    /// A sorted frame: projection, sort and draw.
    pub fn sorted_frame(&self) -> Duration {
        self.project + self.sort + self.draw_sorted
    }

    /// A stochastic frame: projection and draw, no sort.
    pub fn stochastic_frame(&self) -> Duration {
        self.project + self.draw_stochastic
    }
}

/// A scene projected and depth-sorted for one camera on the GPU.
pub struct GpuRasterizer<'a> {
    ctx: &'a GpuContext,
    pipes: &'a RasterPipelines,
    scene: &'a RasterScene,
    camera: Camera,
    params: RasterParams,
    params_buffer: wgpu::Buffer,
    splats: wgpu::Buffer,
    depth: SortBuffers,
    draw_args: wgpu::Buffer,
    compute_group: wgpu::BindGroup,
}

impl<'a> GpuRasterizer<'a> {
    /// Check the camera, allocate the per-camera buffers, and project and sort the scene.
    pub fn new(
        ctx: &'a GpuContext,
        pipes: &'a RasterPipelines,
        scene: &'a RasterScene,
        camera: &Camera,
    ) -> Result<Self, GpuError> {
        camera.validate().map_err(RenderError::from)?;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let splats = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("splats"),
            size: (scene.count as usize * size_of::<GpuSplat>()) as u64,
            usage: rw,
            mapped_at_creation: false,
        });
        // Room for count + 1 tile counts in the histogram (their scan's last entry is the total).
        let depth = pipes.sort.buffers(ctx, scene.count + 1)?;
        let draw_args = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("draw args"),
            size: 16,
            usage: rw | wgpu::BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        let params = raster_params(scene, camera);
        let params_buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("raster params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let compute_group = bind(
            ctx,
            &pipes.project,
            &[
                (0, &params_buffer),
                (1, &scene.particles),
                (2, &scene.sh),
                (3, &splats),
                (4, &depth.keys),
                (5, &depth.vals),
                (6, &draw_args),
            ],
        );
        let raster =
            Self { ctx, pipes, scene, camera: *camera, params, params_buffer, splats, depth, draw_args, compute_group };
        let mut encoder = raster.encoder("project and sort");
        raster.encode_project(&mut encoder, None);
        raster.encode_sort(&mut encoder, None)?;
        raster.submit(encoder)?;
        Ok(raster)
    }

    fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    fn submit(&self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(())
    }

    /// Projection: reset the visible count (6 vertices, 0 instances) and run `project`.
    fn encode_project(&self, encoder: &mut wgpu::CommandEncoder, timestamps: Option<wgpu::ComputePassTimestampWrites>) {
        self.ctx.queue.write_buffer(&self.draw_args, 0, bytemuck::cast_slice(&[6u32, 0, 0, 0]));
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("project"), timestamp_writes: timestamps });
        pass.set_pipeline(&self.pipes.project);
        pass.set_bind_group(0, &self.compute_group, &[]);
        let (gx, gy) = groups(self.scene.count.div_ceil(256));
        pass.dispatch_workgroups(gx, gy, 1);
    }

    /// The global depth sort: all particles, culled ones (key u32::MAX) last.
    fn encode_sort(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Result<(), GpuError> {
        self.pipes.sort.encode(self.ctx, encoder, &self.depth, self.scene.count, 32, timestamps)
    }

    /// The projected splats in scene order (culled ones have an empty rect).
    pub fn splats(&self) -> Result<Vec<GpuSplat>, GpuError> {
        let words = self.ctx.read_u32(&self.splats, self.scene.count as usize * 16)?;
        Ok(bytemuck::cast_slice(&words).to_vec())
    }

    /// The visible splats' scene indices in (depth, id) order.
    pub fn order(&self) -> Result<Vec<u32>, GpuError> {
        let visible = self.ctx.read_u32(&self.draw_args, 4)?[1];
        self.ctx.read_u32(&self.depth.vals, visible as usize)
    }

    /// Render `frames.count` frames of `method` (one for sorted splatting) and fold them into
    /// the per-pixel running mean and M2 (f32 Welford, as the ray-tracing kernel does).
    pub fn render(&self, method: &RasterMethod, frames: &Frames) -> Result<GpuOutput, GpuError> {
        let draw = Draw::of(method)?;
        if frames.rng != splat_core::rng::RngScheme::Hash {
            return Err(GpuError::Unsupported(
                "the raster methods draw their decisions with the hash generator".into(),
            ));
        }
        if frames.count == 0 {
            return Err(GpuError::Unsupported("at least one frame is needed".into()));
        }
        let count = if draw == Draw::Stochastic { frames.count } else { 1 };
        self.set_mode(draw);
        let (w, h) = (self.camera.width, self.camera.height);
        let pixels = (w * h) as usize;
        let targets = Targets::new(self.ctx, self.pipes, w, h, draw);
        let out_bytes = (pixels * 16) as u64;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let make = |label| {
            self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: out_bytes,
                usage: rw,
                mapped_at_creation: false,
            })
        };
        let (mean, m2) = (make("raster mean"), make("raster m2"));
        let slots = FrameSlots::new(self.ctx);
        let draw_group = self.draw_group(&slots.buffer);
        let fold_group = self.fold_group(&slots.buffer, &targets.color_view, &mean, &m2);
        let keys: Vec<u32> = (0..count).map(|f| splat_core::rng::frame_key(frames.seed, f)).collect();
        let mut gpu_time = Duration::ZERO;
        for (batch_index, batch) in keys.chunks(FRAMES_PER_SUBMIT as usize).enumerate() {
            let first = batch_index as u32 * FRAMES_PER_SUBMIT;
            slots.write(self.ctx, batch, first);
            let mut encoder = self.encoder("raster frames");
            for slot in 0..batch.len() as u32 {
                let offset = slots.offset(slot);
                self.encode_draw(&mut encoder, draw, &targets, &draw_group, offset, None);
                let mut pass = encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("fold"), timestamp_writes: None });
                pass.set_pipeline(&self.pipes.fold);
                pass.set_bind_group(0, &fold_group, &[offset]);
                pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
            }
            let start = Instant::now();
            self.submit(encoder)?;
            gpu_time += start.elapsed();
        }
        let mean = self.ctx.read_f32(&mean, pixels * 4)?;
        let m2 = self.ctx.read_f32(&m2, pixels * 4)?;
        Ok(crate::output(&self.camera, &mean, &m2, count, gpu_time, false))
    }

    fn set_mode(&self, draw: Draw) {
        let params = RasterParams { mode: draw.mode(), ..self.params };
        self.ctx.queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
    }

    fn draw_group(&self, frame_params: &wgpu::Buffer) -> wgpu::BindGroup {
        self.ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat"),
            layout: &self.pipes.splat_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.params_buffer.as_entire_binding() },
                frame_entry(1, frame_params),
                wgpu::BindGroupEntry { binding: 2, resource: self.splats.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: self.depth.vals.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: self.draw_args.as_entire_binding() },
            ],
        })
    }

    fn fold_group(
        &self,
        frame_params: &wgpu::Buffer,
        color: &wgpu::TextureView,
        mean: &wgpu::Buffer,
        m2: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        self.ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fold"),
            layout: &self.pipes.fold_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.params_buffer.as_entire_binding() },
                frame_entry(1, frame_params),
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(color) },
                wgpu::BindGroupEntry { binding: 3, resource: mean.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: m2.as_entire_binding() },
            ],
        })
    }

    /// One render pass drawing every splat quad of `draw` into `targets`.
    fn encode_draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        draw: Draw,
        targets: &Targets,
        group: &wgpu::BindGroup,
        frame_offset: u32,
        timestamps: Option<wgpu::RenderPassTimestampWrites>,
    ) {
        let bg = self.scene.settings.background.as_dvec3();
        // Over and stochastic frames start from the background; under accumulates premultiplied
        // colour from zero and the fold adds the background behind the remaining transmittance.
        let clear = match draw {
            Draw::Under => wgpu::Color::TRANSPARENT,
            _ => wgpu::Color { r: bg.x, g: bg.y, b: bg.z, a: 0.0 },
        };
        let depth_attachment = targets.depth_view.as_ref().map(|view| wgpu::RenderPassDepthStencilAttachment {
            view,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
            stencil_ops: None,
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("splat"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &targets.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: depth_attachment,
            timestamp_writes: timestamps,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(self.pipes.render_pipeline(draw));
        pass.set_bind_group(0, group, &[frame_offset]);
        match draw {
            Draw::Stochastic => pass.draw(0..6, 0..self.scene.count),
            _ => pass.draw_indirect(&self.draw_args, 0),
        }
    }

    /// Front-to-back iso-opacity depth and picked splat per pixel, by a compute tile rasterizer
    /// in the 3DGS style: the sorted splats are binned into 16 × 16 tiles as (tile, rank)
    /// pairs, the pairs sorted by tile with the radix sort (stable, so each tile's list stays
    /// in depth order), and one invocation per pixel walks its tile's list front to back,
    /// compositing with the under operator and recording the first fragment after which the
    /// transmittance is below the iso threshold.
    ///
    /// Why not the render pipeline: the fixed-function blend gives the composited colour but
    /// never the transmittance before a fragment, and reading it in the fragment shader from a
    /// storage image needs fragment-shader interlock for overlapping fragments (what
    /// vk_gaussian_splatting uses); wgpu has none, and without it the read-modify-write races.
    /// Here each pixel is owned by one invocation that visits its fragments in the global
    /// (depth, id) order of the CPU reference, so the result is exact and deterministic.
    pub fn depth_pick(&self) -> Result<DepthPick, GpuError> {
        self.set_mode(Draw::Under);
        let (ctx, pipes, n) = (self.ctx, self.pipes, self.scene.count);
        let [tiles_x, tiles_y] = self.params.tiles;
        // 1. Pairs per rank and their exclusive scan (offsets[n] is the total).
        let count_group = bind(
            ctx,
            &pipes.tile_count,
            &[
                (0, &self.params_buffer),
                (3, &self.splats),
                (5, &self.depth.vals),
                (6, &self.draw_args),
                (7, &self.depth.hist),
            ],
        );
        let mut encoder = self.encoder("tile count");
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile count"), timestamp_writes: None });
            pass.set_pipeline(&pipes.tile_count);
            pass.set_bind_group(0, &count_group, &[]);
            let (gx, gy) = groups((n + 1).div_ceil(256));
            pass.dispatch_workgroups(gx, gy, 1);
        }
        pipes.sort.encode_scan(ctx, &mut encoder, &self.depth, n + 1);
        self.submit(encoder)?;
        let pairs = ctx.read_u32_at(&self.depth.hist, n as usize, 1)?[0];
        // 2. Emit the pairs, sort them by tile, find each tile's range, composite.
        let pair_sort = pipes.sort.buffers(ctx, pairs.max(1))?;
        let tiles = tiles_x * tiles_y;
        let pixels = (self.camera.width * self.camera.height) as usize;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let buffer = |label, bytes: usize| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes as u64,
                usage: rw,
                mapped_at_creation: false,
            })
        };
        let ranges = buffer("tile ranges", tiles as usize * 8);
        let out_color = buffer("depth pick colour", pixels * 16);
        let out_pick = buffer("depth pick", pixels * 8);
        let emit_group = bind(
            ctx,
            &pipes.tile_emit,
            &[
                (0, &self.params_buffer),
                (3, &self.splats),
                (5, &self.depth.vals),
                (6, &self.draw_args),
                (7, &self.depth.hist),
                (8, &pair_sort.keys),
                (9, &pair_sort.vals),
            ],
        );
        let ranges_group = bind(
            ctx,
            &pipes.tile_ranges,
            &[(0, &self.params_buffer), (7, &self.depth.hist), (8, &pair_sort.keys), (10, &ranges)],
        );
        let blend_group = bind(
            ctx,
            &pipes.tile_blend,
            &[
                (0, &self.params_buffer),
                (3, &self.splats),
                (5, &self.depth.vals),
                (9, &pair_sort.vals),
                (10, &ranges),
                (11, &out_color),
                (12, &out_pick),
            ],
        );
        let mut encoder = self.encoder("tile lists");
        encoder.clear_buffer(&ranges, 0, None);
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile emit"), timestamp_writes: None });
            pass.set_pipeline(&pipes.tile_emit);
            pass.set_bind_group(0, &emit_group, &[]);
            let (gx, gy) = groups(n.div_ceil(256));
            pass.dispatch_workgroups(gx, gy, 1);
        }
        let tile_bits = u32::BITS - (tiles - 1).leading_zeros();
        pipes.sort.encode(ctx, &mut encoder, &pair_sort, pairs, tile_bits, None)?;
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile blend"), timestamp_writes: None });
            pass.set_pipeline(&pipes.tile_ranges);
            pass.set_bind_group(0, &ranges_group, &[]);
            let (gx, gy) = groups(pairs.div_ceil(256));
            pass.dispatch_workgroups(gx, gy, 1);
            pass.set_pipeline(&pipes.tile_blend);
            pass.set_bind_group(0, &blend_group, &[]);
            pass.dispatch_workgroups(tiles_x, tiles_y, 1);
        }
        self.submit(encoder)?;
        let color = ctx.read_f32(&out_color, pixels * 4)?;
        let pick = ctx.read_u32(&out_pick, pixels * 2)?;
        let image = |channels, f: &dyn Fn(usize) -> f32| crate::rgba_image(&self.camera, channels, f);
        let picked: Vec<Option<u32>> = pick.chunks(2).map(|p| (p[1] != NONE).then_some(p[1])).collect();
        Ok(DepthPick {
            color: image(3, &|i| color[i]),
            alpha: image(1, &|i| color[i + 3]),
            depth: pick.chunks(2).zip(&picked).map(|(p, id)| id.map(|_| f32::from_bits(p[0]))).collect(),
            picked,
            pairs,
        })
    }

    /// Time one frame's stages: projection, sort, a sorted (over) draw and a StochasticSplats
    /// draw at 1 spp; the fastest of `repeat` runs of each.
    pub fn profile(&self, repeat: u32) -> Result<RasterTimings, GpuError> {
        let (w, h) = (self.camera.width, self.camera.height);
        let sorted_targets = Targets::new(self.ctx, self.pipes, w, h, Draw::Over);
        let stochastic_targets = Targets::new(self.ctx, self.pipes, w, h, Draw::Stochastic);
        let slots = FrameSlots::new(self.ctx);
        slots.write(self.ctx, &[splat_core::rng::frame_key(1, 0)], 0);
        let group = self.draw_group(&slots.buffer);
        let timer = self.ctx.timestamps.then(|| crate::Timer::new(self.ctx));
        let mut best = [Duration::MAX; 4];
        for _ in 0..repeat.max(1) {
            for (phase, slot) in best.iter_mut().enumerate() {
                let mut encoder = self.encoder("profile");
                let writes = timer.as_ref().map(|t| (&t.queries, 0u32, 1u32));
                let compute_ts = writes.map(|(q, b, e)| wgpu::ComputePassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                });
                let render_ts = writes.map(|(q, b, e)| wgpu::RenderPassTimestampWrites {
                    query_set: q,
                    beginning_of_pass_write_index: Some(b),
                    end_of_pass_write_index: Some(e),
                });
                match phase {
                    0 => self.encode_project(&mut encoder, compute_ts),
                    1 => self.encode_sort(&mut encoder, compute_ts)?,
                    2 => {
                        self.set_mode(Draw::Over);
                        self.encode_draw(&mut encoder, Draw::Over, &sorted_targets, &group, 0, render_ts);
                    }
                    _ => {
                        self.set_mode(Draw::Stochastic);
                        self.encode_draw(&mut encoder, Draw::Stochastic, &stochastic_targets, &group, 0, render_ts);
                    }
                }
                if let Some(t) = &timer {
                    t.resolve(&mut encoder);
                }
                let start = Instant::now();
                self.submit(encoder)?;
                let elapsed = match &timer {
                    Some(t) => t.elapsed(self.ctx)?,
                    None => start.elapsed(),
                };
                *slot = (*slot).min(elapsed);
            }
        }
        Ok(RasterTimings {
            project: best[0],
            sort: best[1],
            draw_sorted: best[2],
            draw_stochastic: best[3],
            timestamps: timer.is_some(),
        })
    }
}

/// Whether the GPU rasterizer renders `settings`: one sample per pixel at the centre, billboard
/// (centre) fragment depth. MSAA sample sets and max-density-plane depths are CPU-only.
pub fn check_settings(settings: &RasterSettings) -> Result<(), GpuError> {
    settings.validate()?;
    if settings.samples != 1 || settings.fragment_depth != FragmentDepth::Center {
        return Err(GpuError::Unsupported(format!(
            "the GPU rasterizer renders one sample per pixel with centre fragment depth ({} samples and {:?} depth asked for); use --backend cpu",
            settings.samples, settings.fragment_depth
        )));
    }
    Ok(())
}

/// The uniforms of a camera.
fn raster_params(scene: &RasterScene, camera: &Camera) -> RasterParams {
    let s = &scene.settings;
    let row = |i: usize| {
        let v = camera.rotation.row(i);
        [v.x, v.y, v.z, 0.0]
    };
    let t = camera.translation;
    let (w, h) = (camera.width as f32, camera.height as f32);
    RasterParams {
        cam_row0: row(0),
        cam_row1: row(1),
        cam_row2: row(2),
        cam_translation: [t.x, t.y, t.z, 0.0],
        intrinsics: [camera.fx, camera.fy, camera.cx, camera.cy],
        background: [s.background.x, s.background.y, s.background.z, 0.0],
        size: [camera.width, camera.height],
        count: scene.count,
        sh_degree: scene.sh_degree,
        kernel_degree: s.kernel.degree,
        alpha_clamp: s.kernel.alpha_clamp,
        alpha_cull: s.kernel.alpha_cull,
        iso_threshold: s.iso_threshold,
        guard: [
            FRUSTUM_GUARD * camera.cx.max(w - camera.cx) / camera.fx,
            FRUSTUM_GUARD * camera.cy.max(h - camera.cy) / camera.fy,
        ],
        tiles: [camera.width.div_ceil(TILE), camera.height.div_ceil(TILE)],
        mode: 0,
        pad0: 0,
        pad1: 0,
        pad2: 0,
    }
}

/// A bind group for an auto-layout compute pipeline: just the bindings its entry point uses.
fn bind(ctx: &GpuContext, pipeline: &wgpu::ComputePipeline, buffers: &[(u32, &wgpu::Buffer)]) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> =
        buffers.iter().map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }).collect();
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

fn frame_entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer,
            offset: 0,
            size: wgpu::BufferSize::new(size_of::<FrameParams>() as u64),
        }),
    }
}

/// Render targets of one draw: colour, and depth for StochasticSplats.
struct Targets {
    color_view: wgpu::TextureView,
    depth_view: Option<wgpu::TextureView>,
}

impl Targets {
    fn new(ctx: &GpuContext, pipes: &RasterPipelines, width: u32, height: u32, draw: Draw) -> Self {
        let texture = |label, format, usage| {
            ctx.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        // The format the draw's pipeline was built for.
        let format = if draw == Draw::Stochastic { STOCHASTIC_FORMAT } else { pipes.blend_format };
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        Self {
            color_view: texture("splat colour", format, usage),
            depth_view: (draw == Draw::Stochastic)
                .then(|| texture("splat depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT)),
        }
    }
}

/// Per-frame uniform slots of one submission, addressed by dynamic offset.
struct FrameSlots {
    buffer: wgpu::Buffer,
    stride: u64,
}

impl FrameSlots {
    fn new(ctx: &GpuContext) -> Self {
        let stride = (size_of::<FrameParams>() as u64).next_multiple_of(ctx.uniform_alignment);
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame params"),
            size: stride * u64::from(FRAMES_PER_SUBMIT),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self { buffer, stride }
    }

    fn write(&self, ctx: &GpuContext, keys: &[u32], first: u32) {
        let mut bytes = vec![0u8; (self.stride as usize) * keys.len()];
        for (slot, &key) in keys.iter().enumerate() {
            let p = FrameParams { key, index: first + slot as u32, pad0: 0, pad1: 0 };
            let at = slot * self.stride as usize;
            bytes[at..at + size_of::<FrameParams>()].copy_from_slice(bytemuck::bytes_of(&p));
        }
        ctx.queue.write_buffer(&self.buffer, 0, &bytes);
    }

    fn offset(&self, slot: u32) -> u32 {
        (self.stride * u64::from(slot)) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::wgsl_check::{assert_mirrors, validate};

    /// Sizes and offsets of the Rust mirrors equal naga's layout of the WGSL structs.
    #[test]
    fn rust_structs_mirror_the_raster_wgsl_structs() {
        assert_mirrors!(RASTER_WGSL, RasterParticle, "RasterParticle", [mean, opacity, cov_a, pad0, cov_b, pad1]);
        assert_mirrors!(RASTER_WGSL, GpuSplat, "Splat", [mean, depth, opacity, conic, id, color, pad, rect]);
        assert_mirrors!(
            RASTER_WGSL,
            RasterParams,
            "RasterParams",
            [
                cam_row0,
                cam_row1,
                cam_row2,
                cam_translation,
                intrinsics,
                background,
                size,
                count,
                sh_degree,
                kernel_degree,
                alpha_clamp,
                alpha_cull,
                iso_threshold,
                guard,
                tiles,
                mode,
                pad0,
                pad1,
                pad2
            ]
        );
        assert_mirrors!(SPLAT_WGSL, FrameParams, "FrameParams", [key, index, pad0, pad1]);
    }

    /// Every raster module is valid WGSL for naga (a shader error fails `cargo test`).
    #[test]
    fn raster_wgsl_validates() {
        for (name, source) in [("raster", RASTER_WGSL), ("splat", SPLAT_WGSL), ("fold", FOLD_WGSL)] {
            validate(name, source);
        }
    }
}
