//! GPU ray tracing: the twin of [`splat_core::trace`]. The kernel (`shaders/bvh.wgsl` and
//! `shaders/trace.wgsl`) traverses the BVH that the core builds, in software (as Sun et al. do
//! on Metal and low-end GPUs), with the same counter-based decisions, hit conventions and
//! defaults, so a GPU frame makes the CPU frame's accept/reject choices.
//!
//! ```no_run
//! use splat_core::{RenderSettings, frame::Frames, scenes, trace::{Method, TraceScene}};
//! let ctx = splat_gpu::GpuContext::new()?;
//! let pipeline = splat_gpu::TracePipeline::new(&ctx)?;
//! let (scene, camera) = scenes::cloud();
//! let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
//! let tracer = splat_gpu::GpuTracer::new(&ctx, &pipeline, &trace)?;
//! let (images, stats) = tracer.render(&camera, &Method::Stochastic, &Frames::default())?;
//! # Ok::<(), splat_gpu::GpuError>(())
//! ```

use crate::context::{compute_pipeline, params_entry, storage_entry};
use crate::layout::{self, GpuPick, Params, PassState};
use crate::split::{BindGroups, MAX_ELEMENTS, PartBindings, PartBytes, Split, SplitArray, SplitLayout};
use crate::timing::Timer;
use crate::{GpuContext, GpuError, GpuStats, Remedy};
use splat_core::Camera;
use splat_core::MethodId;
use splat_core::catalogue::Param;
use splat_core::frame::{Frames, RenderOutput};
use splat_core::raster::RasterMethod;
use splat_core::sh::ShStorage;
use splat_core::trace::{DEFAULT_K, MAX_HITS, Method, TraceScene};
use splat_core::{RenderSettings, Scene};
use std::time::{Duration, Instant};

/// WGSL of the ray-tracing kernel (entry point `main`) and of the path tracer that calls its
/// traversals (`path_main`, `shaders/path.wgsl`), but for the scene arrays, which
/// [`TraceSplit`] declares.
const TRACE_SOURCE: &str = concat!(
    include_str!("../shaders/common.wgsl"),
    include_str!("../shaders/sh.wgsl"),
    include_str!("../shaders/lighting.wgsl"),
    include_str!("../shaders/bvh.wgsl"),
    include_str!("../shaders/triangle.wgsl"),
    include_str!("../shaders/mesh.wgsl"),
    include_str!("../shaders/pick.wgsl"),
    include_str!("../shaders/hybrid_fragment.wgsl"),
    include_str!("../shaders/trace.wgsl"),
    include_str!("../shaders/lens.wgsl"),
    include_str!("../shaders/stochastic.wgsl"),
    include_str!("../shaders/kbuffer.wgsl"),
    include_str!("../shaders/shadow.wgsl"),
    include_str!("../shaders/path.wgsl"),
    include_str!("../shaders/sampler.wgsl"),
    include_str!("../shaders/bsdf.wgsl")
);

/// The ray-tracing kernel of every scene that fits one binding per array.
pub static TRACE_WGSL: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| TraceSplit::WHOLE.wgsl());

/// The scene arrays of the ray tracer (bindings 1–3, the SH's as its storage holds them,
/// [`layout::sh_array`]), each split over as many bindings as it needs ([`crate::split`]);
/// parts after the first bind from 18 on.
const PARTICLES: SplitArray =
    SplitArray::of::<layout::GpuParticle>("particle", "particles", "particle_at", "Particle", 1);
const NODES: SplitArray = SplitArray::of::<crate::node::GpuNode>("BVH node", "nodes", "node_at", "Node", 2);
/// The SH array's binding.
const SH_BINDING: u32 = 3;
/// Bindings of the kernel beside the parts after the first of its split arrays.
const OWN_BINDINGS: u32 = 18;

/// How a scene's particles, BVH nodes and SH coefficients are split over bindings, and how the
/// SH are stored: the kernel's module and layout are made for it ([`TracePipeline`] keeps one
/// per split it has met).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TraceSplit {
    /// The particles (in BVH leaf order).
    pub particles: Split,
    /// The BVH nodes (splats', then meshes').
    pub nodes: Split,
    /// The SH coefficients (RGB + pad, scene order).
    pub sh: Split,
    /// Their precision ([`splat_core::RenderSettings::sh_storage`]).
    pub sh_storage: ShStorage,
    /// How the parts after the first are bound (the device's way).
    pub parts: PartBindings,
}

impl TraceSplit {
    /// Every array in one binding.
    pub const WHOLE: TraceSplit = TraceSplit {
        particles: Split::WHOLE,
        nodes: Split::WHOLE,
        sh: Split::WHOLE,
        sh_storage: ShStorage::F32,
        parts: PartBindings::Each,
    };

    /// The split of arrays of these lengths (elements; SH coefficients stored as `sh_storage`)
    /// on `ctx`, refused when it needs more bindings than the adapter has
    /// ([`GpuError::SceneOverBindings`]) with how many particles like these would fit.
    pub fn new(ctx: &GpuContext, [particles, nodes, sh]: [u64; 3], sh_storage: ShStorage) -> Result<Self, GpuError> {
        Self::checked(ctx, [particles, nodes, sh], [particles, nodes, sh], sh_storage)
    }

    /// About how many wide BVH nodes the build makes for `n` particles, before it has run: a
    /// node for four particles (0.24 for the 3,000 of the `cloud` fixture, 0.26 for the 272,956
    /// of the bonsai mini: leaves of up to four, four children a node).
    pub fn nodes_about(n: u64) -> u64 {
        n.div_ceil(4)
    }

    /// The split a scene of `count` particles of SH degree `sh_degree` needs at least (its
    /// BVH not built yet: one node), refused as [`TraceSplit::new`] refuses, so that a scene
    /// that cannot fit is refused before the BVH is built; what fits is estimated with
    /// [`TraceSplit::nodes_about`] wide nodes.
    pub fn at_least(ctx: &GpuContext, scene: &Scene, settings: &RenderSettings) -> Result<Self, GpuError> {
        let n = scene.particles.len() as u64;
        let coefficients = splat_core::particle::sh_coeff_count(scene.sh_degree) as u64;
        Self::checked(ctx, [n, 1, n * coefficients], [n, Self::nodes_about(n), n * coefficients], settings.sh_storage)
    }

    /// The most particles of SH degree `sh_degree`, their coefficients stored as `sh_storage`,
    /// whose arrays the ray tracer binds on `ctx` (with [`TraceSplit::nodes_about`] wide
    /// nodes): the bound the adapter's storage bindings set, whatever its memory.
    pub fn capacity(ctx: &GpuContext, sh_degree: u8, sh_storage: ShStorage) -> u64 {
        let coefficients = splat_core::particle::sh_coeff_count(sh_degree) as u64;
        let lengths = |m: u64| [m, Self::nodes_about(m), m * coefficients];
        crate::split::most_that_fit(MAX_ELEMENTS, |m| Self::fits(ctx, lengths(m), sh_storage))
    }

    /// The split of arrays of `lengths` (particles, nodes, SH) by `ctx`'s binding limit.
    fn split(ctx: &GpuContext, lengths: [u64; 3], sh_storage: ShStorage) -> Self {
        let sh_array = layout::sh_array(sh_storage, SH_BINDING).0;
        let arrays = [&PARTICLES, &NODES, &sh_array];
        let [particles, nodes, sh] = std::array::from_fn(|k| Split::of(lengths[k], arrays[k].stride, ctx.max_binding));
        TraceSplit { particles, nodes, sh, sh_storage, parts: ctx.part_bindings() }
    }

    /// Whether arrays of `lengths` fit the adapter: element indices within u32 (the kernel's),
    /// every element within a binding, their parts within what a stage binds.
    fn fits(ctx: &GpuContext, lengths: [u64; 3], sh_storage: ShStorage) -> bool {
        let sh_array = layout::sh_array(sh_storage, SH_BINDING).0;
        let strides = [PARTICLES.stride, NODES.stride, sh_array.stride];
        lengths.iter().all(|&n| n <= MAX_ELEMENTS)
            && strides.iter().all(|&stride| stride <= ctx.max_binding)
            && Self::split(ctx, lengths, sh_storage).layout().over(ctx, OWN_BINDINGS).is_none()
    }

    /// The split of arrays of `lengths` (particles, nodes, SH), refused with the particles that
    /// would fit in arrays in the proportions of `like`, or when the device's memory left cannot
    /// hold arrays of `like` ([`GpuError::MemoryShort`]).
    fn checked(ctx: &GpuContext, lengths: [u64; 3], like: [u64; 3], sh_storage: ShStorage) -> Result<Self, GpuError> {
        let sh_array = layout::sh_array(sh_storage, SH_BINDING).0;
        let arrays = [&PARTICLES, &NODES, &sh_array];
        if let Some(k) = (0..3).find(|&k| lengths[k] > 0 && arrays[k].stride > ctx.max_binding) {
            let (buffer, bytes) = (arrays[k].what, lengths[k] * arrays[k].stride);
            return Err(GpuError::SceneTooLarge { buffer, bytes, limit: ctx.max_binding, count: lengths[0] as usize });
        }
        let split = Self::split(ctx, lengths, sh_storage);
        if Self::fits(ctx, lengths, sh_storage) {
            // The device's memory, where it can tell, holds the arrays of `like` (the BVH's
            // estimated nodes before it is built).
            ctx.check_memory("particles, BVH nodes and SH", (0..3).map(|k| like[k] * arrays[k].stride).sum())?;
            return Ok(split);
        }
        // The most particles m whose arrays, scaled from `like`, fit.
        let n = like[0].max(1);
        let scaled = |m: u64| like.map(|len| (u128::from(len) * u128::from(m) / u128::from(n)) as u64);
        let fits = crate::split::most_that_fit(n, |m| Self::fits(ctx, scaled(m), sh_storage));
        let (what, kernel, fits_what) = ("particles, BVH nodes and SH", "the ray tracer", "particles like these");
        // Past the kernel's indices (whatever the bindings), else over its storage bindings or
        // its elements of binding arrays.
        let elements = lengths.into_iter().max().unwrap_or(0);
        match split.layout().over(ctx, OWN_BINDINGS) {
            Some((needed, available)) if elements <= MAX_ELEMENTS => Err(GpuError::SceneOverBindings {
                arrays: what,
                kernel,
                needed,
                available,
                limit: ctx.max_binding,
                bytes: (0..3).map(|k| lengths[k] * arrays[k].stride).sum(),
                fits,
                fits_what,
            }),
            _ => Err(GpuError::SceneOverIndices { arrays: what, kernel, elements, fits, fits_what }),
        }
    }

    fn layout(&self) -> SplitLayout {
        let sh = layout::sh_array(self.sh_storage, SH_BINDING).0;
        SplitLayout {
            arrays: vec![(PARTICLES, self.particles), (NODES, self.nodes), (sh, self.sh)],
            first_extra: OWN_BINDINGS,
            parts: self.parts,
        }
    }

    /// The kernel's WGSL for this split.
    pub(crate) fn wgsl(&self) -> String {
        let split = self.layout();
        let sh_decode = layout::sh_array(self.sh_storage, SH_BINDING).1;
        format!("{}{TRACE_SOURCE}{}{sh_decode}", split.directives(), split.wgsl())
    }
}
/// Dispatches encoded into one submission.
pub const DISPATCHES_PER_SUBMIT: u32 = 64;
/// Frames rendered per dispatch on a real GPU; longer runs are split so that no dispatch runs
/// for long. CPU adapters (lavapipe) render as many as fit their loop budget (see
/// [`LOOP_BUDGET`]).
pub const FRAMES_PER_DISPATCH: u32 = 32;
/// lavapipe ends a loop after 65535 iterations of its SIMD loop per invocation (gallivm's loop
/// limiter), silently. A loop statement runs at most lanes × the busiest lane's total loop
/// iterations, which the kernel counts: on a CPU adapter [`GpuTracer::render`] batches the
/// frames that fit ¾ of it (by a probe of frame 0) and refuses a result where that bound
/// reaches the budget.
pub const LOOP_BUDGET: u32 = 65_535;
/// Most mirror and glass bounces the trace kernel follows in a world where a transparent surface
/// (an opacity below 1) is also a mirror or glass: its segment stack holds 16 pending segments,
/// and while a segment of bounce d is traced each bounce before it may hold two (a sibling ray and
/// the ray continued past a transparent surface), 2 d + 1 in all.
pub const MAX_LAYERED_BOUNCES: u32 = 7;

/// A method as the kernel reads it: its identity and every parameter, named.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MethodParams {
    /// Which method (`params.method` in WGSL is its [`MethodId::code`]).
    pub id: MethodId,
    /// Hits per pass.
    pub k: u32,
    /// Pass limit.
    pub max_passes: u32,
    /// Early-out transmittance of the k-buffer.
    pub min_transmittance: f32,
    /// Samples per traversal.
    pub n: u32,
    /// Traversals per frame.
    pub m: u32,
    /// Whether the kernel can run the method one pass (or, for `stochastic-n`, one slot) per
    /// dispatch, its ray's state kept between dispatches, when whole frames exceed lavapipe's
    /// loop budget.
    pub by_pass: bool,
}

impl TryFrom<&Method> for MethodParams {
    type Error = GpuError;

    /// The kernel's parameters of a method: the values of the parameters it reads (the
    /// catalogue's word), 1 (0 for the early-out) for the others; `exact` runs the k-buffer
    /// loop with no early-out and no pass limit (any k gives Eq. 3 then; 18 keeps each pass
    /// short).
    fn try_from(method: &Method) -> Result<Self, GpuError> {
        GpuTracer::supports(method)?;
        let (id, p) = method.identity();
        let read = |param, value: u32| if id.reads(param) { value } else { 1 };
        let (m, n) = kernel_traversals(read(Param::M, p.m), read(Param::N, p.n));
        let params = MethodParams {
            id,
            k: read(Param::K, p.k as u32),
            max_passes: read(Param::MaxPasses, p.max_passes),
            min_transmittance: if id.reads(Param::MinTransmittance) { p.min_transmittance } else { 0.0 },
            n,
            m,
            // The kernel keeps the ray's state between dispatches for these; a method not
            // listed runs whole frames (on lavapipe, one past the loop budget is refused).
            by_pass: matches!(
                id,
                MethodId::Exact | MethodId::KBuffer | MethodId::StochasticN | MethodId::StochasticPass
            ),
        };
        let exact = MethodParams { k: DEFAULT_K as u32, max_passes: u32::MAX, ..params };
        Ok(if id == MethodId::Exact { exact } else { params })
    }
}

/// `stochastic-n`'s m traversals of n samples as the kernel runs them: a traversal holds at
/// most [`MAX_HITS`] slots, so n beyond runs as traversals of the largest divisor c of n that
/// fits, (m·n/c, c). Slot j·n + i is the same slot in either grouping and each slot's closest
/// accepted hit does not depend on which traversal finds it, so the image is the same; only
/// the traversals' cost differs (Sun et al. Table 5's 4 × 256 runs as 16 × 64 on the GPU).
fn kernel_traversals(m: u32, n: u32) -> (u32, u32) {
    if n as usize <= MAX_HITS {
        return (m, n);
    }
    let c = (1..=MAX_HITS as u32).rev().find(|&c| n.is_multiple_of(c)).unwrap_or(1);
    (m * (n / c), c)
}

/// The ray-tracing kernel, compiled for each [`TraceSplit`] a scene needs (one, [`TraceSplit::WHOLE`],
/// for every scene whose arrays fit one binding each) on the first tracer of that split.
pub struct TracePipeline {
    kernels: crate::split::PerSplit<TraceSplit, TraceKernel>,
}

/// The kernel compiled for one split: its module, bind group layout and entry points.
pub(crate) struct TraceKernel {
    split: TraceSplit,
    pub(crate) pipeline: wgpu::ComputePipeline,
    pub(crate) layout: wgpu::BindGroupLayout,
    /// The layout of its binding arrays' group, where its split has any.
    arrays_layout: Option<wgpu::BindGroupLayout>,
    module: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    /// The kernel with `HYBRID_MODE` on, compiled on the first hybrid render.
    hybrid: std::sync::OnceLock<wgpu::ComputePipeline>,
    /// The path tracer (`path_main`, `PATH_MODE` on), compiled on the first path-traced render.
    path: std::sync::OnceLock<wgpu::ComputePipeline>,
    /// `split_gather`, compiled on first use ([`GpuTracer::arrays_as_read`]).
    gather: std::sync::OnceLock<wgpu::ComputePipeline>,
}

impl TracePipeline {
    /// A pipeline with no kernel compiled yet: each tracer compiles the kernel of its split on
    /// first use ([`GpuTracer::new`]), shader and pipeline errors coming back as
    /// [`GpuError::Shader`], not wgpu's panicking handler.
    pub fn new(_ctx: &GpuContext) -> Result<Self, GpuError> {
        Ok(Self { kernels: crate::split::PerSplit::new() })
    }

    /// The kernel of `split`, compiled on first use.
    pub(crate) fn kernel(&self, ctx: &GpuContext, split: TraceSplit) -> Result<std::sync::Arc<TraceKernel>, GpuError> {
        self.kernels.get(split, || TraceKernel::new(ctx, split))
    }

    /// The kernel's bindings for `split` (checked against its WGSL by
    /// `layout::tests::trace_layout_matches_the_shader`).
    pub(crate) fn layout_entries(split: &TraceSplit) -> Vec<wgpu::BindGroupLayoutEntry> {
        let storage = |binding, read_only| storage_entry(binding, wgpu::ShaderStages::COMPUTE, read_only);
        let mut entries = vec![
            params_entry(0, wgpu::ShaderStages::COMPUTE, true, std::mem::size_of::<Params>()),
            storage(1, true),
            storage(2, true),
            storage(3, true),
            storage(4, false),
            storage(5, false),
            storage(6, false),
            storage(7, true),
            storage(8, true),
            storage(9, false),
            storage(10, true),
            storage(11, true),
            storage(12, true),
            params_entry(13, wgpu::ShaderStages::COMPUTE, false, std::mem::size_of::<layout::PathParams>()),
            storage(14, true),
            storage(15, true),
            storage(16, true),
            storage(17, true),
        ];
        entries.extend(split.layout().extra_entries(0, |_| wgpu::ShaderStages::COMPUTE));
        entries
    }

    /// The kernel's bindings in its binding arrays' group for `split` (none, no such group).
    pub(crate) fn array_entries(split: &TraceSplit) -> Vec<wgpu::BindGroupLayoutEntry> {
        split.layout().extra_entries(crate::split::ARRAY_GROUP, |_| wgpu::ShaderStages::COMPUTE)
    }
}

impl TraceKernel {
    fn new(ctx: &GpuContext, split: TraceSplit) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let (module, layout, arrays_layout, pipeline_layout, pipeline) = crate::context::validated(device, || {
            let module = crate::context::shader_module(device, "trace.wgsl", &split.wgsl());
            let (entries, arrays) = (TracePipeline::layout_entries(&split), TracePipeline::array_entries(&split));
            let (layout, arrays_layout, pipeline_layout) = crate::split::layouts(device, "trace", &entries, &arrays);
            let pipeline = compute_pipeline(device, &module, Some(&pipeline_layout), "main");
            (module, layout, arrays_layout, pipeline_layout, pipeline)
        })?;
        let (hybrid, path, gather) =
            (std::sync::OnceLock::new(), std::sync::OnceLock::new(), std::sync::OnceLock::new());
        Ok(Self { split, pipeline, layout, arrays_layout, module, pipeline_layout, hybrid, path, gather })
    }

    /// The hybrid pipeline's kernel (`HYBRID_MODE`: the rasterizer's samples continued, the
    /// volumetric look's fragments lit), compiled on first use.
    fn hybrid(&self, ctx: &GpuContext) -> Result<&wgpu::ComputePipeline, GpuError> {
        Self::once(&self.hybrid, || self.specialised(ctx, "main", Some("HYBRID_MODE")))
    }

    /// The path tracer's kernel (`path_main`), compiled on first use.
    fn path(&self, ctx: &GpuContext) -> Result<&wgpu::ComputePipeline, GpuError> {
        Self::once(&self.path, || self.specialised(ctx, "path_main", Some("PATH_MODE")))
    }

    /// `split_gather`, the scene arrays as the kernel reads them, compiled on first use.
    fn gather(&self, ctx: &GpuContext) -> Result<&wgpu::ComputePipeline, GpuError> {
        Self::once(&self.gather, || self.specialised(ctx, "split_gather", None))
    }

    fn once(
        cell: &std::sync::OnceLock<wgpu::ComputePipeline>,
        compile: impl FnOnce() -> Result<wgpu::ComputePipeline, GpuError>,
    ) -> Result<&wgpu::ComputePipeline, GpuError> {
        if let Some(p) = cell.get() {
            return Ok(p);
        }
        let pipeline = compile()?;
        Ok(cell.get_or_init(|| pipeline))
    }

    /// Entry point `entry` of the kernel's module on its layout, with the pipeline-overridable
    /// constant `mode` set where given; shader and pipeline errors as [`GpuError::Shader`].
    fn specialised(
        &self,
        ctx: &GpuContext,
        entry: &str,
        mode: Option<&str>,
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        let constants: Vec<(&str, f64)> = mode.map(|m| (m, 1.0)).into_iter().collect();
        crate::context::validated(&ctx.device, || {
            ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(mode.unwrap_or(entry)),
                layout: Some(&self.pipeline_layout),
                module: &self.module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
                cache: None,
            })
        })
    }
}

/// A scene on the GPU, ready to trace: particles in BVH leaf order, BVH nodes and SH
/// coefficients uploaded beside the [`TraceScene`] they came from, each in as many parts as
/// its [`TraceSplit`] cuts it into.
pub struct GpuTracer<'a> {
    ctx: &'a GpuContext,
    kernel: std::sync::Arc<TraceKernel>,
    trace: &'a TraceScene<'a>,
    particles: Vec<wgpu::Buffer>,
    nodes: Vec<wgpu::Buffer>,
    sh: Vec<wgpu::Buffer>,
    /// Elements of each: particles, nodes, SH coefficients.
    lengths: [u64; 3],
    materials: wgpu::Buffer,
    lights: wgpu::Buffer,
    triangles: wgpu::Buffer,
    mesh_materials: wgpu::Buffer,
    /// Binding 12 when no first hits are given (one unused entry).
    no_first_hits: wgpu::Buffer,
    /// Binding 17 without the volumetric look's first hits (one unused entry).
    no_fragments: wgpu::Buffer,
    /// Binding 13 outside path-traced renders.
    no_path: wgpu::Buffer,
    /// The Sobol direction numbers (binding 14).
    sobol: wgpu::Buffer,
    /// The emissive triangles (binding 15) and every triangle's emitter density (binding 16).
    emitters: wgpu::Buffer,
    emitter_density: wgpu::Buffer,
    /// Emissive triangles.
    emitter_count: u32,
}

/// Rasterized first hits on the device ([`crate::FirstHits`]): the hits, `samples` of them a
/// pixel, their fragments (the volumetric look's only) and which first hit they are
/// (`Params::first_hit`).
pub(crate) struct DeviceFirstHits {
    hits: wgpu::Buffer,
    fragments: Option<wgpu::Buffer>,
    samples: u32,
    kind: u32,
}

/// Frame f's pinhole camera and the first hits rasterized through it.
type FrameFirstHits<'a> = dyn Fn(u32) -> Result<(Camera, DeviceFirstHits), GpuError> + 'a;

/// The hybrid pipeline's rasterized first hits ([`GpuTracer::render_hybrid`]).
#[derive(Clone, Copy)]
enum FirstHits<'a> {
    /// One rasterization for every frame: sorted splatting through a still camera.
    Still(&'a DeviceFirstHits),
    /// One rasterization per frame.
    PerFrame(&'a FrameFirstHits<'a>),
}

impl<'a> GpuTracer<'a> {
    /// Upload the particles, BVH, materials and lights of `trace`, the particles, nodes and SH
    /// split over as many bindings as they need ([`TraceSplit`]; refused when the adapter has
    /// too few, [`GpuError::SceneOverBindings`], or too little memory,
    /// [`GpuError::DeviceMemory`]), and compile the kernel of that split if `pipeline` has not.
    pub fn new(ctx: &'a GpuContext, pipeline: &TracePipeline, trace: &'a TraceScene<'a>) -> Result<Self, GpuError> {
        check_segment_stack(trace)?;
        let nodes = layout::nodes(trace);
        let sh_storage = trace.settings().sh_storage;
        let (scene, len) = (trace.scene(), |n: usize| n as u64);
        let lengths = [len(trace.leaf_particles().len()), len(nodes.len()), len(layout::sh_len(scene))];
        let split = TraceSplit::new(ctx, lengths, sh_storage)?;
        let kernel = pipeline.kernel(ctx, split)?;
        // The particles and SH made a part at a time as they are uploaded (the SH of an SH-3
        // scene are 256 bytes a particle in f32).
        let particles = PARTICLES
            .upload_parts(ctx, split.particles, lengths[0], |range| PartBytes(layout::particles(trace, range)))?;
        let nodes = NODES.upload(ctx, split.nodes, bytemuck::cast_slice(&nodes))?;
        let sh_array = layout::sh_array(sh_storage, SH_BINDING).0;
        let sh = sh_array
            .upload_parts(ctx, split.sh, lengths[2], |range| PartBytes(layout::sh_range(scene, sh_storage, range)))?;
        let (mut emitters, mut density) = splat_core::path::emitter_table(trace);
        let emitter_count = emitters.len() as u32;
        // A binding cannot be empty.
        emitters.push([0, 0]);
        density.push(0.0);
        Ok(Self {
            no_path: ctx.upload("no path", bytemuck::bytes_of(&layout::PathParams::default())),
            sobol: ctx.upload("sobol", bytemuck::cast_slice(&splat_core::path::sampler::sobol_directions())),
            emitters: ctx.upload("emitters", bytemuck::cast_slice(&emitters)),
            emitter_density: ctx.upload("emitter density", bytemuck::cast_slice(&density)),
            emitter_count,
            ctx,
            kernel,
            trace,
            particles,
            nodes,
            sh,
            lengths,
            materials: ctx.upload("materials", bytemuck::cast_slice(&layout::materials(trace.lighting()))),
            lights: ctx.upload("lights", bytemuck::cast_slice(&layout::lights(trace.lighting()))),
            triangles: ctx.upload("triangles", bytemuck::cast_slice(&layout::triangles(trace.meshes()))),
            mesh_materials: ctx.upload("mesh materials", bytemuck::cast_slice(&layout::mesh_materials(trace.meshes()))),
            no_first_hits: ctx.upload("no first hits", bytemuck::cast_slice(&[layout::GpuFirstHit::default()])),
            no_fragments: ctx.upload("no fragments", bytemuck::cast_slice(&[layout::GpuFragment::default()])),
        })
    }

    /// Whether the kernel runs `method`: valid parameters, and a GPU kernel in the catalogue
    /// (`supports_method`); the CPU backend runs every method.
    pub fn supports(method: &Method) -> Result<(), GpuError> {
        method.validate()?;
        crate::error::supports_method(method.id())
    }

    /// Render `frames.count` frames of `method` (one for a deterministic method) through pixel
    /// centres, as [`splat_core::trace::render_frames`] does: per pixel a running Welford mean
    /// and M2 in f32, frames in dispatches of up to [`FRAMES_PER_DISPATCH`]; with the depth, normal
    /// and picked particle of frame 0, as the CPU reports them (max-density-plane normals).
    ///
    /// On a CPU adapter (lavapipe), whose loop limiter counts per invocation, a dispatch
    /// renders as many frames as fit ¾ of the budget by a probe of frame 0 (one frame when a
    /// batch goes over, then one pass per dispatch), and the render fails with
    /// [`GpuError::LoopBudget`] rather than return an image whose rays may have been cut short
    /// (see [`LOOP_BUDGET`]). Batching matters there: each dispatch costs lavapipe about 40 ms
    /// and 3 MB that it does not return to the system.
    pub fn render(
        &self,
        camera: &Camera,
        method: &Method,
        frames: &Frames,
    ) -> Result<(RenderOutput, GpuStats), GpuError> {
        self.render_with(camera, method, frames, None, None)
    }

    /// The hybrid pipeline (vk_gaussian_splatting Lighting §5; the twin of
    /// `splat_core::raster::Rasterizer::hybrid`): the first hit of every sample of every pixel
    /// (the rasterizer's S) is rasterized by `first` (sorted splatting; StochasticSplats, the stochastic
    /// transparency page's own case; Enderton or stratified) by `raster(camera)` (the same
    /// scene, meshes and lighting; [`crate::GpuRasterizer::first_hits`]), and this tracer
    /// continues from it: the pick lit with shadow rays, the mesh behind the splats shaded with
    /// shadows and its mirror and glass bounces traced by `method`.
    ///
    /// Sorted splatting through a still camera is rasterized once for every frame. The
    /// stochastic methods decide again each frame, and a camera drawn per frame (a box pixel
    /// filter or a thin lens, [`splat_core::camera_sampling`]) rasterizes frame f through its
    /// own pinhole camera, as the CPU's `render_raster_frames` does; the kernel folds each frame
    /// into the same running mean.
    pub fn render_hybrid<'r>(
        &self,
        raster: &dyn Fn(&Camera) -> Result<crate::GpuRasterizer<'r>, GpuError>,
        camera: &Camera,
        first: &RasterMethod,
        method: &Method,
        frames: &Frames,
    ) -> Result<(RenderOutput, GpuStats), GpuError> {
        layout::check_opaque(self.trace.meshes(), "the GPU hybrid")?;
        let sampling = self.trace.settings().sampling;
        // The first hits on the device, and how many a pixel (the rasterizer's samples).
        let upload = |frame_camera: &Camera, first: crate::FirstHits| {
            let pixels = (frame_camera.width * frame_camera.height) as usize;
            if first.hits.is_empty() || !first.hits.len().is_multiple_of(pixels) {
                return Err(GpuError::Unsupported("the rasterizer's camera is not the tracer's".into()));
            }
            let fragments = (!first.fragments.is_empty())
                .then(|| self.ctx.upload("first-hit fragments", bytemuck::cast_slice(&first.fragments)));
            Ok(DeviceFirstHits {
                hits: self.ctx.upload("first hits", bytemuck::cast_slice(&first.hits)),
                fragments,
                samples: (first.hits.len() / pixels) as u32,
                kind: first.kind,
            })
        };
        if !sampling.is_random() && !first.is_stochastic() {
            let hits = upload(camera, raster(camera)?.first_hits(first, 0, 0.0)?)?;
            return self.render_with(camera, method, frames, Some(FirstHits::Still(&hits)), None);
        }
        let still = if sampling.is_random() { None } else { Some(raster(camera)?) };
        let per_frame = |f: u32| -> Result<(Camera, DeviceFirstHits), GpuError> {
            let key = splat_core::rng::frame_key(frames.seed, frames.index(f));
            let (frame_camera, hits) = match &still {
                Some(r) => (*camera, r.first_hits(first, key, frames.u_shift)?),
                None => {
                    let sample = splat_core::camera_sampling::frame_sample(frames.seed, frames.index(f));
                    let frame_camera = sampling.pinhole(camera, &sample)?;
                    (frame_camera, raster(&frame_camera)?.first_hits(first, key, frames.u_shift)?)
                }
            };
            Ok((frame_camera, upload(&frame_camera, hits)?))
        };
        self.render_with(camera, method, frames, Some(FirstHits::PerFrame(&per_frame)), None)
    }

    /// The Monte Carlo path tracer (the twin of [`splat_core::path::PathTracer::render`]):
    /// `frames.count` paths per pixel with the CPU's decisions for the same seed, frames batched
    /// as in [`GpuTracer::render`] (on lavapipe within its loop budget, or refused with the
    /// pixel named). Every Gaussian estimator but depth sampling (the CPU's control) runs.
    pub fn render_path(
        &self,
        camera: &Camera,
        settings: &splat_core::path::PathSettings,
        frames: &Frames,
    ) -> Result<(RenderOutput, GpuStats), GpuError> {
        settings.validate()?;
        let params = layout::path_params(settings, self.emitter_count).ok_or_else(|| {
            GpuError::refused("depth sampling in the path tracer runs on the CPU only", &[Remedy::Cpu])
        })?;
        let buffer = self.ctx.upload("path", bytemuck::bytes_of(&params));
        let frames = Frames { rng: splat_core::rng::RngScheme::Hash, ..*frames };
        let pipeline = self.kernel.path(self.ctx)?;
        self.render_with(camera, &Method::Stochastic, &frames, None, Some((pipeline, &buffer)))
    }

    /// The kernel's bind group over this scene's buffers, the per-pixel `targets`, the
    /// dispatch parameters `uniform` (one [`Params`] per dynamic offset, [`params_buffer`]) and, where given, the
    /// hybrid pipeline's first hits and the path tracer's parameters.
    pub(crate) fn bind_group(
        &self,
        uniform: &wgpu::Buffer,
        targets: &TraceTargets,
        first_hits: Option<&DeviceFirstHits>,
        path: Option<&wgpu::Buffer>,
    ) -> BindGroups {
        let params = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: uniform,
            offset: 0,
            size: wgpu::BufferSize::new(std::mem::size_of::<Params>() as u64),
        });
        let buffers = [
            &self.particles[0],
            &self.nodes[0],
            &self.sh[0],
            &targets.mean,
            &targets.m2,
            &targets.pass_state,
            &self.materials,
            &self.lights,
            &targets.pick,
            &self.triangles,
            &self.mesh_materials,
            first_hits.map_or(&self.no_first_hits, |f| &f.hits),
            path.unwrap_or(&self.no_path),
            &self.sobol,
            &self.emitters,
            &self.emitter_density,
            first_hits.and_then(|f| f.fragments.as_ref()).unwrap_or(&self.no_fragments),
        ];
        // The parts after the first of the split arrays.
        let layout = self.kernel.split.layout();
        let arrays = [(&PARTICLES, &self.particles), (&NODES, &self.nodes), (&layout.arrays[2].0, &self.sh)];
        let parts: Vec<_> =
            arrays.iter().flat_map(|(array, buffers)| layout.bind(array, buffers).into_iter().skip(1)).collect();
        let entries: Vec<wgpu::BindGroupEntry> = std::iter::once(wgpu::BindGroupEntry { binding: 0, resource: params })
            .chain(
                buffers
                    .iter()
                    .zip(1..)
                    .map(|(b, binding)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }),
            )
            .collect();
        let kernel = &self.kernel;
        let layouts = (&kernel.layout, kernel.arrays_layout.as_ref());
        BindGroups::new(&self.ctx.device, Some("trace"), layouts.0, layouts.1, &entries, &parts)
    }

    /// The scene this tracer holds.
    pub fn trace(&self) -> &TraceScene<'a> {
        self.trace
    }

    /// The context it runs on.
    pub fn context(&self) -> &'a GpuContext {
        self.ctx
    }

    /// The compiled ray-tracing kernel.
    pub(crate) fn kernel(&self) -> &wgpu::ComputePipeline {
        &self.kernel.pipeline
    }

    /// How its scene arrays are split over bindings.
    pub fn split(&self) -> TraceSplit {
        self.kernel.split
    }

    /// Bytes of its scene arrays on the device: particles, BVH nodes (the meshes' too) and SH.
    pub fn scene_bytes(&self) -> u64 {
        self.particles.iter().chain(&self.nodes).chain(&self.sh).map(wgpu::Buffer::size).sum()
    }

    /// The particles, BVH nodes and SH coefficients as the kernel reads them through its
    /// accessors (`split_gather` in `shaders/trace.wgsl`), in element order, as the u32 words
    /// of their 16-byte rows (four a particle, eight a node, one a coefficient): the same for
    /// every split of a scene, which a test checks without compiling the whole kernel for each.
    pub fn arrays_as_read(&self) -> Result<[Vec<[u32; 4]>; 3], GpuError> {
        /// Rows `split_gather` writes an element: a particle's, a node's and a coefficient's.
        const ROWS: u32 = 9;
        let ctx = self.ctx;
        let lengths = self.lengths.map(|n| n as usize);
        let longest = lengths.iter().copied().max().unwrap_or(0).max(1);
        let targets = TraceTargets::new(ctx, ROWS * longest as u32, 1);
        let uniform = params_buffer(ctx);
        let group = self.bind_group(&uniform, &targets, None, None);
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("gather") });
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("gather"), timestamp_writes: None });
            pass.set_pipeline(self.kernel.gather(ctx)?);
            group.set_compute(&mut pass, &[0]);
            let (gx, gy) = crate::sort::groups(longest.div_ceil(64) as u32);
            ctx.dispatch(&mut pass, gx, gy, 1);
        }
        ctx.submit(encoder.finish());
        let words = ctx.read_u32(&targets.mean, 4 * ROWS as usize * longest)?;
        let rows: Vec<[u32; 4]> = words.chunks(4).map(|w| [w[0], w[1], w[2], w[3]]).collect();
        let take = |k: std::ops::Range<usize>, n: usize| -> Vec<[u32; 4]> {
            rows.chunks(ROWS as usize).take(n).flat_map(|element| element[k.clone()].to_vec()).collect()
        };
        Ok([take(0..4, lengths[0]), take(4..8, lengths[1]), take(8..9, lengths[2])])
    }

    fn render_with(
        &self,
        camera: &Camera,
        method: &Method,
        frames: &Frames,
        first_hits: Option<FirstHits>,
        path: Option<(&wgpu::ComputePipeline, &wgpu::Buffer)>,
    ) -> Result<(RenderOutput, GpuStats), GpuError> {
        camera.validate().map_err(splat_core::RenderError::from)?;
        splat_core::trace::check_camera(self.trace.settings(), camera)?;
        let params = MethodParams::try_from(method)?;
        let per_frame = matches!(first_hits, Some(FirstHits::PerFrame(_)));
        let count = frames.keys(method.is_stochastic() || self.trace.is_random() || per_frame)?.len() as u32;
        let ctx = self.ctx;
        let cpu_adapter = ctx.info.device_type == wgpu::DeviceType::Cpu;
        let kernel = match (path, first_hits) {
            (Some((pipeline, _)), _) => pipeline,
            (None, Some(_)) => self.kernel.hybrid(ctx)?,
            (None, None) => &self.kernel.pipeline,
        };
        let path = path.map(|(_, buffer)| buffer);
        let run = Run { tracer: self, camera, params, frames, count, first_hits, path, kernel };
        let lanes = u64::from(ctx.lanes());
        let over = |f: &Finished| cpu_adapter && u64::from(f.stats.loop_iterations) * lanes >= u64::from(LOOP_BUDGET);
        let mut out = if per_frame {
            // A dispatch per frame (its first hits rasterized before it).
            run.execute(1, false)?
        } else if cpu_adapter {
            // Frame 0 alone first: it is the whole render of one frame, shows a ray too long
            // for one invocation before any other frame is spent, and measures how many frames
            // a dispatch can batch within ¾ of the budget.
            let probe = Run { count: 1, ..run }.execute(1, false)?;
            if count == 1 || over(&probe) {
                probe
            } else {
                let per_frame = u64::from(probe.stats.loop_iterations.max(1)) * lanes;
                let batch = (3 * u64::from(LOOP_BUDGET) / (4 * per_frame)).clamp(1, u64::from(ctx.frames_per_dispatch));
                let out = run.execute(batch as u32, false)?;
                if over(&out) && batch > 1 { run.execute(1, false)? } else { out }
            }
        } else {
            run.execute(ctx.frames_per_dispatch, false)?
        };
        // Multi-pass methods (and stochastic-n, slot by slot: `MethodParams::by_pass`) that do
        // not fit run again with one pass per dispatch. Mirror and glass bounces, and rays continued
        // past transparent surfaces, run whole frames only: the state between passes is the camera
        // ray's.
        let meshes = self.trace.meshes();
        let bounces =
            meshes.has_transparent() || meshes.materials().iter().any(|m| m.mirror > 0.0 || m.transmission > 0.0);
        if over(&out) && params.by_pass && !bounces && first_hits.is_none() && path.is_none() {
            out = run.execute(1, true)?;
        }
        if over(&out) {
            let (iterations, pixel) = (out.stats.loop_iterations, out.busiest_pixel);
            let lanes = lanes as u32;
            return Err(GpuError::LoopBudget { x: pixel % camera.width, y: pixel / camera.width, iterations, lanes });
        }
        Ok((out.output, out.stats))
    }
}

/// Frame 0's depth, normal and picked particle of every pixel into `out`.
pub(crate) fn set_picks(out: &mut RenderOutput, picks: &[GpuPick]) {
    let (w, h) = (out.depth.width(), out.depth.height());
    let depth = picks.iter().map(|p| if p.depth >= 0.0 { p.depth } else { f32::NAN }).collect();
    let normal = picks.iter().flat_map(|p| p.normal).collect();
    out.depth = splat_core::Image::from_data(w, h, 1, depth).expect("one depth per pixel");
    out.normal = splat_core::Image::from_data(w, h, 3, normal).expect("one normal per pixel");
    out.picked = picks.iter().map(|p| (p.picked != u32::MAX).then_some(p.picked)).collect();
}

/// A finished render and the index of the pixel that ran the most loop iterations
/// (`stats.loop_iterations`).
struct Finished {
    output: RenderOutput,
    stats: GpuStats,
    busiest_pixel: u32,
}

/// One attempt at a render.
struct Run<'a> {
    tracer: &'a GpuTracer<'a>,
    camera: &'a Camera,
    params: MethodParams,
    frames: &'a Frames,
    count: u32,
    /// The hybrid pipeline's rasterized first hits, if this is a hybrid render.
    first_hits: Option<FirstHits<'a>>,
    /// The path tracer's parameters, if this is a path-traced render.
    path: Option<&'a wgpu::Buffer>,
    /// The kernel that runs: the path tracer's, the hybrid's or the ray tracer's.
    kernel: &'a wgpu::ComputePipeline,
}

impl Run<'_> {
    fn storage(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.tracer.ctx.buffer(label, bytes, usage)
    }

    /// Render with `per_dispatch` frames a dispatch, or, with `by_pass`, one pass of one frame
    /// per dispatch (k-buffer and stochastic pass), the rays' state kept between dispatches.
    fn execute(&self, per_dispatch: u32, by_pass: bool) -> Result<Finished, GpuError> {
        let (ctx, camera, tracer) = (self.tracer.ctx, self.camera, self.tracer);
        let targets = TraceTargets::new(ctx, camera.width, camera.height);
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let (out_bytes, pick_bytes, state_bytes) = (targets.rgba_bytes(), targets.pick_bytes(), targets.state_bytes());
        let (read_mean, read_var) =
            (self.storage("read mean", out_bytes, read), self.storage("read m2", out_bytes, read));
        let read_pick = self.storage("read pick", pick_bytes, read);
        let read_state = self.storage("read pass state", state_bytes, read);
        let TraceTargets { mean: out_mean, m2: out_var, pick: out_pick, pass_state, .. } = &targets;
        let uniform = params_buffer(ctx);
        let still_hits = match self.first_hits {
            Some(FirstHits::Still(hits)) => Some(hits),
            _ => None,
        };
        let bind_group = tracer.bind_group(&uniform, &targets, still_hits, self.path);
        let mut gpu_time = Duration::ZERO;
        let timer = ctx.timestamps.then(|| Timer::new(ctx));
        // Submit the dispatches of `params`, one batch per submission.
        let mut submit = |bind_group: &BindGroups, params: &[Params]| -> Result<(), GpuError> {
            for batch in params.chunks(DISPATCHES_PER_SUBMIT as usize) {
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
                    pass.set_pipeline(self.kernel);
                    dispatch_batch(ctx, &mut pass, &uniform, bind_group, batch, camera);
                }
                if let Some(t) = &timer {
                    t.resolve(&mut encoder);
                }
                let start = Instant::now();
                ctx.submit(encoder.finish());
                ctx.wait()?;
                gpu_time += match &timer {
                    Some(t) => t.elapsed(ctx)?,
                    None => start.elapsed(),
                };
            }
            Ok(())
        };
        if by_pass {
            // stochastic-n runs one slot per dispatch: m × n "passes" of n = 1 slot.
            let MethodParams { id, max_passes, n, m, .. } = self.params;
            let (max_passes, slots, chunk) =
                if id == MethodId::StochasticN { (n * m, n * m, 1) } else { (max_passes, m, n) };
            for frame in 0..self.count {
                let mut pass_index = 0u32;
                while pass_index < max_passes {
                    let batch: Vec<Params> = (pass_index..max_passes.min(pass_index.saturating_add(8)))
                        .map(|p| Params {
                            mode: layout::MODE_PASS,
                            pass_index: p,
                            max_passes,
                            m: slots,
                            n: chunk,
                            ..layout::params(tracer.trace, camera, &self.params, self.frames, frame, 1)
                        })
                        .collect();
                    pass_index += batch.len() as u32;
                    submit(&bind_group, &batch)?;
                    let states = ctx.read_through(pass_state, 0, &read_state, state_bytes)?;
                    let words = std::mem::size_of::<PassState>() / 4;
                    let flags = std::mem::offset_of!(PassState, flags) / 4;
                    if states.chunks(words).all(|s| s[flags].to_bits() & 1 == 1) {
                        break;
                    }
                }
            }
        } else if let Some(FirstHits::PerFrame(hits)) = self.first_hits {
            for frame in 0..self.count {
                // Frame f through its own pinhole camera, whose pixel centres are the frame's rays.
                let (frame_camera, first) = hits(frame)?;
                let group = tracer.bind_group(&uniform, &targets, Some(&first), None);
                let params = layout::params(tracer.trace, &frame_camera, &self.params, self.frames, frame, 1);
                let still = Params { pixel_filter: layout::FILTER_CENTER, aperture: 0.0, ..params };
                let (first_hit, raster_samples) = (first.kind, first.samples);
                submit(&group, &[Params { mode: layout::MODE_HYBRID, first_hit, raster_samples, ..still }])?;
            }
        } else {
            let (mode, first_hit, raster_samples) = match self.first_hits {
                Some(FirstHits::Still(first)) => (layout::MODE_HYBRID, first.kind, first.samples),
                _ => (layout::MODE_FRAMES, 0, 1),
            };
            let frames = 0..self.count;
            let params = frame_params(tracer.trace, camera, &self.params, self.frames, mode, frames, per_dispatch);
            let params: Vec<Params> = params.into_iter().map(|p| Params { first_hit, raster_samples, ..p }).collect();
            submit(&bind_group, &params)?;
        }
        let mean = ctx.read_through(out_mean, 0, &read_mean, out_bytes)?;
        let m2 = ctx.read_through(out_var, 0, &read_var, out_bytes)?;
        let busiest = busiest_pixel(&m2);
        let picks = ctx.read_through(out_pick, 0, &read_pick, pick_bytes)?;
        let (mut output, stats) = crate::output(camera, &mean, &m2, self.count, gpu_time, timer.is_some());
        set_picks(&mut output, bytemuck::cast_slice(&picks));
        let stats = GpuStats {
            loop_iterations: busiest.0,
            mean_loop_iterations: mean_iterations(&m2),
            frames_per_dispatch: per_dispatch,
            pass_per_dispatch: by_pass,
            ..stats
        };
        Ok(Finished { output, stats, busiest_pixel: busiest.1 })
    }
}

/// The per-pixel state a render writes: the running Welford mean (RGBA) and M2 (RGB, with the
/// loop-iteration count in w), frame 0's pick and, between passes, each ray's [`PassState`].
pub(crate) struct TraceTargets {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) mean: wgpu::Buffer,
    pub(crate) m2: wgpu::Buffer,
    pub(crate) pick: wgpu::Buffer,
    pub(crate) pass_state: wgpu::Buffer,
}

impl TraceTargets {
    /// Buffers for a `width` × `height` image.
    pub(crate) fn new(ctx: &GpuContext, width: u32, height: u32) -> Self {
        let pixels = u64::from(width) * u64::from(height);
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let buffer = |label, bytes| ctx.buffer(label, bytes, rw);
        Self {
            width,
            height,
            mean: buffer("mean", pixels * 16),
            m2: buffer("m2", pixels * 16),
            pick: buffer("pick", pixels * std::mem::size_of::<GpuPick>() as u64),
            pass_state: buffer("pass state", pixels * std::mem::size_of::<PassState>() as u64),
        }
    }

    fn pixels(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height)
    }

    /// Bytes of the mean (and of the M2) buffer.
    pub(crate) fn rgba_bytes(&self) -> u64 {
        self.pixels() * 16
    }

    /// Bytes of the pick buffer.
    pub(crate) fn pick_bytes(&self) -> u64 {
        self.pixels() * std::mem::size_of::<GpuPick>() as u64
    }

    /// Bytes of the pass-state buffer.
    pub(crate) fn state_bytes(&self) -> u64 {
        self.pixels() * std::mem::size_of::<PassState>() as u64
    }
}

/// The buffer of one submission's [`Params`], one per dynamic offset (a read-only storage
/// buffer, [`crate::context::params_entry`]).
pub(crate) fn params_buffer(ctx: &GpuContext) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    ctx.buffer("params", ctx.params_stride() * u64::from(DISPATCHES_PER_SUBMIT), usage)
}

/// The parameters of frames `frames` of a render in `mode`, `per_dispatch` frames a dispatch.
pub(crate) fn frame_params(
    trace: &TraceScene,
    camera: &Camera,
    method: &MethodParams,
    frames: &Frames,
    mode: u32,
    range: std::ops::Range<u32>,
    per_dispatch: u32,
) -> Vec<Params> {
    let mut params = Vec::new();
    let mut first = range.start;
    while first < range.end {
        let chunk = per_dispatch.min(range.end - first);
        params.push(Params { mode, ..layout::params(trace, camera, method, frames, first, chunk) });
        first += chunk;
    }
    params
}

/// Write `batch` into `uniform`, one [`Params`] per dynamic offset, and encode one dispatch of
/// `pass`'s kernel over `camera`'s pixels per entry (at most [`DISPATCHES_PER_SUBMIT`]).
pub(crate) fn dispatch_batch(
    ctx: &GpuContext,
    pass: &mut wgpu::ComputePass,
    uniform: &wgpu::Buffer,
    bind_group: &BindGroups,
    batch: &[Params],
    camera: &Camera,
) {
    let stride = ctx.params_stride() as usize;
    let mut bytes = vec![0u8; stride * batch.len()];
    for (slot, p) in batch.iter().enumerate() {
        bytes[slot * stride..slot * stride + std::mem::size_of::<Params>()].copy_from_slice(bytemuck::bytes_of(p));
    }
    ctx.queue.write_buffer(uniform, 0, &bytes);
    for slot in 0..batch.len() {
        bind_group.set_compute(pass, &[(slot * stride) as u32]);
        ctx.dispatch(pass, camera.width.div_ceil(8), camera.height.div_ceil(8), 1);
    }
}

/// The loop iterations of each pixel's busiest dispatch (M2's w channel), averaged.
fn mean_iterations(m2: &[f32]) -> f64 {
    let pixels = (m2.len() / 4).max(1);
    m2.chunks(4).map(|v| f64::from(v[3])).sum::<f64>() / pixels as f64
}

/// The most loop iterations any pixel ran (M2's w channel) and that pixel's index.
pub(crate) fn busiest_pixel(m2: &[f32]) -> (u32, u32) {
    m2.chunks(4).enumerate().map(|(p, v)| (v[3] as u32, p as u32)).max().unwrap_or((0, 0))
}

/// Refuse a world whose paths the trace kernel's segment stack cannot hold: more than
/// [`MAX_LAYERED_BOUNCES`] bounces where a transparent surface is also a mirror or glass.
fn check_segment_stack(trace: &TraceScene) -> Result<(), GpuError> {
    let meshes = trace.meshes();
    let bounces = trace.settings().max_bounces.min(splat_core::settings::MAX_BOUNCES);
    let layered = meshes.triangles().iter().any(|t| {
        let m = meshes.material(t.mesh);
        t.is_transparent() && (m.mirror > 0.0 || m.transmission > 0.0)
    });
    if layered && bounces > MAX_LAYERED_BOUNCES {
        return Err(GpuError::refused(
            format!(
                "{bounces} bounces among transparent mirrors or glass: the GPU ray tracer follows at most {MAX_LAYERED_BOUNCES} there"
            ),
            &[Remedy::Cpu],
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::{Algorithm, Parameters};

    /// The kernel reads each parameter a method reads and the neutral value of the others (a
    /// k-buffer given n = 16 would run its passes in chunks of 16 slots).
    #[test]
    fn the_kernel_gets_the_parameters_each_method_reads() {
        let p = Parameters { k: 5, max_passes: 7, min_transmittance: 0.25, n: 3, m: 2, ..Parameters::default() };
        let base = |id| MethodParams { id, k: 1, max_passes: 1, min_transmittance: 0.0, n: 1, m: 1, by_pass: false };
        let expected = |id| match id {
            MethodId::Exact => MethodParams { k: 18, max_passes: u32::MAX, by_pass: true, ..base(id) },
            MethodId::KBuffer => {
                MethodParams { k: 5, max_passes: 7, min_transmittance: 0.25, by_pass: true, ..base(id) }
            }
            MethodId::StochasticN => MethodParams { n: 3, m: 2, by_pass: true, ..base(id) },
            MethodId::StochasticPass => MethodParams { k: 5, max_passes: 7, by_pass: true, ..base(id) },
            MethodId::DepthSampling => MethodParams { k: 5, ..base(id) },
            _ => base(id),
        };
        for id in MethodId::ALL.into_iter().filter(|id| id.entry().gpu) {
            let Algorithm::Trace(method) = id.algorithm(&p) else { continue };
            assert_eq!(MethodParams::try_from(&method).unwrap(), expected(id), "{}", id.name());
        }
        let opaque = Method::Opaque;
        assert!(MethodParams::try_from(&opaque).is_err(), "the catalogue has no GPU kernel for opaque");
        // More samples than a traversal of the kernel holds: traversals of a divisor of n.
        for ((m, n), kernel) in [((4, 256), (16, 64)), ((1, 100), (2, 50)), ((2, 67), (134, 1)), ((8, 64), (8, 64))] {
            let p = MethodParams::try_from(&Method::StochasticN { m, n }).unwrap();
            assert_eq!((p.m, p.n), kernel, "{m} × {n}");
        }
    }

    /// The kernel reads its split arrays only through their accessors, which are all that know
    /// the parts: an access by index (`particles[i]`) would read part 0 of a split scene.
    #[test]
    fn the_kernel_reads_the_scene_arrays_through_their_accessors() {
        // The kernel reads the SH through `sh_at` in either storage (f16's decodes `sh_half_at`).
        for array in [PARTICLES, NODES, layout::sh_array(ShStorage::F32, SH_BINDING).0] {
            let index = format!("{}[", array.var);
            let direct = TRACE_SOURCE
                .match_indices(&index)
                .filter(|&(at, _)| !TRACE_SOURCE[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_'));
            assert_eq!(direct.count(), 0, "`{}[` in the kernel: read it through `{}`", array.var, array.accessor);
            assert!(TRACE_SOURCE.contains(&format!("{}(", array.accessor)), "{} unused", array.accessor);
        }
    }
}
