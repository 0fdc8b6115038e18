//! GPU splatting: the twin of [`splat_core::raster`] for one sample per pixel (the 3DGS and
//! vk_gaussian_splatting rasterizers).
//!
//! Stages, each a kernel mirrored by a CPU function of the core:
//! 1. projection and culling, a compute pass (`shaders/raster.wgsl` `project` =
//!    [`splat_core::raster::project()`]), which also writes the depth sort keys and counts the
//!    visible splats into the indirect draw arguments;
//! 2. the global depth sort by (depth, id): the [`RadixSort`] of the depth keys with the
//!    particle ids as values (stable, and the ids start in order, so equal depths stay in id
//!    order like the CPU's `sort_by(depth, id)`);
//! 3. sorted splatting in a render pipeline of instanced quads with the blend states of the
//!    vk_gaussian_splatting lighting page §1.5 (back-to-front *over*, front-to-back *under* with
//!    premultiplied alpha), or
//!    StochasticSplats (no sort, depth test and write, no blending, discard), frames folded
//!    into a running Welford mean like the ray tracer's;
//! 4. for the iso-opacity depth and the picked splat, a compute tile rasterizer
//!    ([`GpuRasterizer::depth_pick`], `shaders/depth_pick.wgsl` over the tile lists of
//!    `shaders/binning.wgsl`), whose doc explains why; Enderton and Laine–Karras play each
//!    pixel's raster operations in `shaders/rop.wgsl` over the same lists.
//!
//! Each of `raster.wgsl`, `binning.wgsl`, `depth_pick.wgsl` and `rop.wgsl` is the twin of the
//! file of its name here (`mod.rs` for the projection), concatenated into [`RASTER_WGSL`].
//!
//! ```no_run
//! use splat_core::{RenderSettings, frame::Frames, raster::{Blend, RasterMethod}, scenes};
//! let ctx = splat_gpu::GpuContext::new()?;
//! let pipes = splat_gpu::RasterPipelines::new(&ctx)?;
//! let (scene, camera) = scenes::cloud();
//! let gpu_scene = splat_gpu::RasterScene::new(&ctx, &scene, &RenderSettings::default())?;
//! let raster = splat_gpu::GpuRasterizer::new(&ctx, &pipes, &gpu_scene, &camera, &Default::default())?;
//! let (sorted, _) = raster.render(&RasterMethod::Sorted { blend: Blend::Over }, &Frames::default())?;
//! let (stochastic, stats) = raster.render(&RasterMethod::StochasticSplat, &Frames { count: 64, ..Frames::default() })?;
//! # Ok::<(), splat_gpu::GpuError>(())
//! ```

mod binning;
mod depth_pick;
mod pipelines;
mod profile;
mod rop;
mod scene;

use binning::TileLists;
pub use depth_pick::{DepthPick, FirstHits};
pub use pipelines::RasterPipelines;
use pipelines::{DEPTH_FORMAT, STOCHASTIC_FORMAT, SplatKernels};
pub use profile::RasterTimings;
use scene::{
    Bindings, CANONICAL, DEPTH_KEYS, DRAWN_ORDER, DRAWN_SPLATS, OFFSETS, ORDER, PAIR_RANKS, PAIR_TILES, SPLATS,
    raster_params,
};
pub use scene::{FrameParams, GpuSplat, RasterParams, RasterParticle, RasterScene, RasterSplit};

use crate::context::{compute_pipeline, params_entry, storage_entry};
use crate::sort::{Culled, RadixSort, SortBuffers, groups};
use crate::split::BindGroups;
use crate::{GpuContext, GpuError, GpuStats, Remedy};
use bytemuck::{Pod, Zeroable};
use splat_core::Camera;
use splat_core::frame::{Frames, RenderOutput};
use splat_core::image::Image;
use splat_core::lighting::{Lighting, Look};
use splat_core::mesh::Meshes;
use splat_core::particle::Scene;
use splat_core::raster::project::FRUSTUM_GUARD;
use splat_core::raster::{
    Blend, FragmentDepth, RasterMethod, RasterSettings, Response, SamplePattern, sample_positions,
};
use splat_core::settings::{RenderError, RenderSettings, validate_scene};
use splat_core::tile::TILE;
use std::time::{Duration, Instant};
use wgpu::util::DeviceExt;

/// WGSL of the projection and tile kernels, but for the projected splats and canonical
/// transforms, which [`RasterSplit`] declares.
const RASTER_SOURCE: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/sh.wgsl"),
    include_str!("../../shaders/raster_types.wgsl"),
    include_str!("../../shaders/lighting.wgsl"),
    include_str!("../../shaders/raster_lighting.wgsl"),
    include_str!("../../shaders/lens.wgsl"),
    include_str!("../../shaders/raster.wgsl"),
    include_str!("../../shaders/triangle.wgsl"),
    include_str!("../../shaders/binning.wgsl"),
    include_str!("../../shaders/hybrid_fragment.wgsl"),
    include_str!("../../shaders/depth_pick.wgsl"),
    include_str!("../../shaders/rop.wgsl")
);
/// WGSL of the splatting render pipeline, but for the split arrays.
const SPLAT_SOURCE: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/raster_types.wgsl"),
    include_str!("../../shaders/lighting.wgsl"),
    include_str!("../../shaders/raster_lighting.wgsl"),
    include_str!("../../shaders/lens.wgsl"),
    include_str!("../../shaders/splat.wgsl")
);
/// The max-density-plane entry point of the splat draw, which needs sample-rate shading.
const SPLAT_PLANE_SOURCE: &str = include_str!("../../shaders/splat_plane.wgsl");
/// WGSL of the projection and tile kernels of every scene whose split arrays fit one binding.
pub static RASTER_WGSL: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| RasterSplit::WHOLE.raster_wgsl());
/// WGSL of the splatting render pipeline of those scenes.
pub static SPLAT_WGSL: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| RasterSplit::WHOLE.splat_wgsl(false));
/// The same with the max-density-plane entry point.
pub static SPLAT_PLANE_WGSL: std::sync::LazyLock<String> =
    std::sync::LazyLock::new(|| RasterSplit::WHOLE.splat_wgsl(true));
/// WGSL of the mesh pre-pass (vk_gaussian_splatting Lighting §1.5.3 and §3).
pub const MESH_PREPASS_WGSL: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/raster_types.wgsl"),
    include_str!("../../shaders/lighting.wgsl"),
    include_str!("../../shaders/raster_lighting.wgsl"),
    include_str!("../../shaders/lens.wgsl"),
    include_str!("../../shaders/bvh.wgsl"),
    include_str!("../../shaders/triangle.wgsl"),
    include_str!("../../shaders/mesh.wgsl"),
    include_str!("../../shaders/mesh_prepass.wgsl")
);
/// WGSL of the frame accumulation.
pub const FOLD_WGSL: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/raster_types.wgsl"),
    include_str!("../../shaders/fold_target.wgsl"),
    include_str!("../../shaders/fold.wgsl")
);
/// WGSL of the frame accumulation from a multisampled target (resolving its samples).
pub const FOLD_MSAA_WGSL: &str = concat!(
    include_str!("../../shaders/common.wgsl"),
    include_str!("../../shaders/raster_types.wgsl"),
    include_str!("../../shaders/fold_target_msaa.wgsl"),
    include_str!("../../shaders/fold.wgsl")
);
/// Frames encoded into one submission (and uniform slots of per-frame parameters).
const FRAMES_PER_SUBMIT: u32 = 64;
/// No splat / no depth in a pick buffer.
const NONE: u32 = u32::MAX;

/// How a method is drawn: a render pipeline (sorted blending, StochasticSplats) or the
/// per-pixel raster operations of the compute tile pass (Enderton, Laine–Karras).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(u32)]
enum Draw {
    Over = 0,
    Under = 1,
    Stochastic = 2,
    Enderton = 3,
    Stratified = 4,
    StratifiedPlain = 5,
}

impl Draw {
    /// The shaders' draw of a method; `None` for a method they do not draw (the catalogue
    /// marks it CPU-only, and [`GpuRasterizer::supports`] refuses it).
    fn of(method: &RasterMethod) -> Option<Self> {
        Some(match method {
            RasterMethod::Sorted { blend: Blend::Over } => Draw::Over,
            RasterMethod::Sorted { blend: Blend::Under } => Draw::Under,
            RasterMethod::StochasticSplat => Draw::Stochastic,
            RasterMethod::Enderton => Draw::Enderton,
            RasterMethod::Stratified { scramble: true } => Draw::Stratified,
            RasterMethod::Stratified { scramble: false } => Draw::StratifiedPlain,
        })
    }

    /// `params.mode` of the raster shaders (`MODE_*`, checked by a test).
    fn mode(self) -> u32 {
        self as u32
    }

    /// Whether the compute tile pass plays the pixel's raster operations (no render pipeline).
    fn is_rop(self) -> bool {
        match self {
            Draw::Enderton | Draw::Stratified | Draw::StratifiedPlain => true,
            Draw::Over | Draw::Under | Draw::Stochastic => false,
        }
    }
}

/// A scene projected and depth-sorted for one camera on the GPU.
pub struct GpuRasterizer<'a> {
    pub(super) ctx: &'a GpuContext,
    pub(super) pipes: &'a RasterPipelines,
    pub(super) scene: &'a RasterScene,
    pub(super) camera: Camera,
    pub(super) params: RasterParams,
    pub(super) params_buffer: wgpu::Buffer,
    /// The kernels and splat draw of the scene's [`RasterSplit`].
    pub(super) k: std::sync::Arc<SplatKernels>,
    /// The projected splats, in the parts of the scene's [`RasterSplit`].
    pub(super) splats: Vec<wgpu::Buffer>,
    pub(super) depth: SortBuffers,
    /// At the max-density plane, the visible splats' ids in scene order, StochasticSplats'
    /// draw order there ([`GpuRasterizer::order_parts`] says why), cut as the depth sort's
    /// arrays; `None` at centre depth.
    pub(super) scene_order: Option<Vec<wgpu::Buffer>>,
    pub(super) draw_args: wgpu::Buffer,
    /// The projection's bind group of each chunk of the scene ([`scene::ProjectChunk`]).
    pub(super) project_groups: Vec<BindGroups>,
    /// The mesh pre-pass's colour and distance per sample (one unused entry without meshes).
    pub(super) behind: wgpu::Buffer,
    /// The mesh pre-pass's normal per sample (one unused entry without meshes).
    pub(super) behind_normal: wgpu::Buffer,
    /// Samples, their pattern, fragment depth and extent.
    pub(super) raster: RasterSettings,
    /// Sub-pixel position of each sample ([`splat_core::raster::sample_positions`]).
    pub(super) sample_offsets: wgpu::Buffer,
    /// The render pipelines at `raster.samples` per pixel, built on first use (S > 1).
    pub(super) msaa: std::sync::OnceLock<pipelines::SamplePipelines>,
}

impl<'a> GpuRasterizer<'a> {
    /// Check the camera, allocate the per-camera buffers, and project and sort the scene.
    pub fn new(
        ctx: &'a GpuContext,
        pipes: &'a RasterPipelines,
        scene: &'a RasterScene,
        camera: &Camera,
        raster: &RasterSettings,
    ) -> Result<Self, GpuError> {
        camera.validate().map_err(RenderError::from)?;
        check_settings(raster)?;
        let entries = mesh_prepass_entries(ctx, scene, camera, raster)?;
        let k = pipes.kernels(ctx, scene.split)?;
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let splats =
            crate::split::alloc(ctx, "projected splat", SPLATS.stride, scene.split.splats, scene.count.into())?;
        // Room for count + 1 tile counts in the histogram (their scan's last entry is the total).
        let depth = pipes.sort.buffers(ctx, scene.count + 1)?;
        debug_assert_eq!(depth.split, scene.split.ranks, "the kernels index the sort's arrays as it cuts them");
        let plane = raster.fragment_depth == FragmentDepth::MaxDensityPlane;
        let order_len = crate::sort::array_len(scene.count + 1);
        let scene_order =
            plane.then(|| crate::split::alloc(ctx, "scene order", 4, depth.split, order_len)).transpose()?;
        let draw_args = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("draw args"),
            size: 16,
            usage: rw | wgpu::BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        let params = raster_params(scene, camera, raster);
        let params_buffer = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("raster params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        });
        let split = &scene.split;
        let parts = [
            split.bind(&SPLATS, &splats),
            split.bind(&CANONICAL, &scene.canonical),
            split.bind(&DEPTH_KEYS, &depth.keys),
            split.bind(&ORDER, &depth.vals),
        ]
        .concat();
        let project_groups = scene
            .chunks
            .iter()
            .map(|chunk| {
                let own =
                    [(0, &params_buffer), (1, &chunk.particles), (2, &chunk.sh), (6, &draw_args), (29, &chunk.range)];
                bind(ctx, &k.project, &own, &parts)
            })
            .collect();
        let pre_pass = |label| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: entries * 16,
                usage: rw,
                mapped_at_creation: false,
            })
        };
        let (behind, behind_normal) = (pre_pass("mesh pre-pass"), pre_pass("mesh pre-pass normal"));
        let offsets: Vec<[f32; 2]> =
            sample_positions(raster.samples, raster.sample_pattern).iter().map(|p| p.to_array()).collect();
        let sample_offsets = ctx.upload("sample offsets", bytemuck::cast_slice(&offsets));
        let raster = Self {
            ctx,
            pipes,
            scene,
            camera: *camera,
            params,
            params_buffer,
            k,
            splats,
            depth,
            scene_order,
            draw_args,
            project_groups,
            behind,
            behind_normal,
            raster: *raster,
            sample_offsets,
            msaa: std::sync::OnceLock::new(),
        };
        let mut encoder = raster.encoder("project and sort");
        raster.encode_project(&mut encoder, None);
        let compaction = raster.encode_scene_order(&mut encoder)?;
        raster.encode_sort(&mut encoder, None)?;
        raster.encode_mesh_prepass(&mut encoder);
        raster.submit(encoder)?;
        drop(compaction);
        Ok(raster)
    }

    /// The sub-pixel position of each sample ([`sample_positions`]; the `sample_offsets` buffer).
    pub(super) fn offsets(&self) -> Vec<glam::Vec2> {
        sample_positions(self.raster.samples, self.raster.sample_pattern)
    }

    /// The same scene and camera at other raster settings (projected and sorted anew).
    pub fn with_settings(&self, raster: &RasterSettings) -> Result<GpuRasterizer<'a>, GpuError> {
        Self::new(self.ctx, self.pipes, self.scene, &self.camera, raster)
    }

    /// The mesh pre-pass, once per camera: each sample's nearest mesh and its forward-shaded
    /// colour (`shaders/mesh_prepass.wgsl`).
    fn encode_mesh_prepass(&self, encoder: &mut wgpu::CommandEncoder) {
        if !self.scene.has_meshes {
            return;
        }
        let s = self.scene;
        let group = bind(
            self.ctx,
            &self.pipes.mesh_prepass,
            &[
                (0, &self.params_buffer),
                (1, &s.mesh_nodes),
                (2, &s.triangles),
                (3, &s.mesh_materials),
                (4, &self.behind),
                (5, &self.behind_normal),
                (6, &self.sample_offsets),
                (14, &s.lights),
            ],
            &[],
        );
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("mesh pre-pass"), timestamp_writes: None });
        pass.set_pipeline(&self.pipes.mesh_prepass);
        group.set_compute(&mut pass, &[]);
        self.ctx.dispatch(&mut pass, self.camera.width.div_ceil(8), self.camera.height.div_ceil(8), 1);
    }

    fn encoder(&self, label: &str) -> wgpu::CommandEncoder {
        self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
    }

    fn submit(&self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        self.ctx.submit(encoder.finish());
        self.ctx.wait()?;
        Ok(())
    }

    /// Projection: reset the visible count (6 vertices, 0 instances) and run `project` on each
    /// chunk of the scene.
    fn encode_project(&self, encoder: &mut wgpu::CommandEncoder, timestamps: Option<wgpu::ComputePassTimestampWrites>) {
        self.ctx.queue.write_buffer(&self.draw_args, 0, bytemuck::cast_slice(&[6u32, 0, 0, 0]));
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("project"), timestamp_writes: timestamps });
        pass.set_pipeline(&self.k.project);
        for (group, chunk) in self.project_groups.iter().zip(&self.scene.chunks) {
            group.set_compute(&mut pass, &[]);
            let (gx, gy) = groups(chunk.count.div_ceil(256));
            self.ctx.dispatch(&mut pass, gx, gy, 1);
        }
    }

    /// The global depth sort of the visible splats: the culled ones (value
    /// [`crate::sort::CULLED`], the shaders' NONE) dropped by its first pass, the later passes
    /// sized on the count the projection left in the draw arguments (their instance count).
    fn encode_sort(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Result<(), GpuError> {
        let pairs = Culled { buffers: &self.depth, n: self.scene.count, kept: &self.draw_args };
        self.pipes.sort.encode_culled(self.ctx, encoder, pairs, timestamps)
    }

    /// The scene order at the max-density plane, from the projection's values (ids, and
    /// [`crate::sort::CULLED`] for the culled splats) before the depth sort permutes them:
    /// copied into a sort's buffers, compacted there ([`crate::RadixSort::encode_compaction`];
    /// the keys are zero as wgpu creates every buffer, and the compaction, which moves only
    /// zeros, leaves them so) and copied out, so that the camera keeps 4 bytes a splat of it
    /// rather than a sort's 20. Returns the sort's buffers, to be dropped once submitted.
    fn encode_scene_order(&self, encoder: &mut wgpu::CommandEncoder) -> Result<Option<SortBuffers>, GpuError> {
        let Some(order) = &self.scene_order else { return Ok(None) };
        let sort = self.pipes.sort.buffers(self.ctx, self.scene.count + 1)?;
        let copy = |encoder: &mut wgpu::CommandEncoder, from: &[wgpu::Buffer], to: &[wgpu::Buffer]| {
            for (from, to) in from.iter().zip(to) {
                encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
            }
        };
        copy(encoder, &self.depth.vals, &sort.vals);
        let pairs = Culled { buffers: &sort, n: self.scene.count, kept: &self.draw_args };
        self.pipes.sort.encode_compaction(self.ctx, encoder, pairs)?;
        copy(encoder, &sort.vals, order);
        Ok(Some(sort))
    }

    /// The order the splat draw walks for `draw` (`order_at` in splat.wgsl): the visible splats
    /// in (depth, id) order, or for StochasticSplats at the max-density plane in scene order.
    /// The depth test keeps the first of two fragments at equal depths, and the CPU twin the
    /// lower id. At centre depth two splats tie only at equal centre depths, which the depth
    /// order breaks by the lower id too, and front to back the depth test rejects what lies
    /// behind before it is shaded; at the plane, per-sample depths can tie between splats of
    /// different centre depths, so only scene order breaks every tie as the CPU does.
    fn order_parts(&self, draw: Draw) -> &[wgpu::Buffer] {
        match (&self.scene_order, draw) {
            (Some(order), Draw::Stochastic) => order,
            _ => &self.depth.vals,
        }
    }

    /// Bytes of a camera's arrays on the device: the projected splats and the depth sort's keys,
    /// values and histogram, and at the max-density plane the scene order's (the tile pairs
    /// come and go with each tile pass).
    pub fn camera_bytes(&self) -> u64 {
        let order = self.scene_order.iter().flatten();
        self.splats.iter().chain(order).map(wgpu::Buffer::size).sum::<u64>() + self.depth.bytes()
    }

    /// The projected splats in scene order (culled ones have an empty rect).
    pub fn splats(&self) -> Result<Vec<GpuSplat>, GpuError> {
        let mut words = Vec::with_capacity(self.scene.count as usize * 16);
        for (part, range) in self.splats.iter().zip(self.scene.split.splats.ranges(u64::from(self.scene.count))) {
            words.extend(self.ctx.read_u32(part, (range.end - range.start) as usize * 16)?);
        }
        Ok(bytemuck::cast_slice(&words).to_vec())
    }

    /// The parts of the projected splats and, with `canonical`, of the canonical transforms,
    /// as the raster kernels bind them (`drawn`: as the splat draw does).
    pub(super) fn split_parts(&self, drawn: bool, canonical: bool) -> Bindings<'_> {
        let split = &self.scene.split;
        let mut parts = split.bind(if drawn { &DRAWN_SPLATS } else { &SPLATS }, &self.splats);
        if canonical {
            parts.extend(split.bind(&CANONICAL, &self.scene.canonical));
        }
        parts
    }

    /// The visible splats' scene indices in (depth, id) order.
    pub fn order(&self) -> Result<Vec<u32>, GpuError> {
        self.read_order(&self.depth.vals)
    }

    /// The visible splats' scene indices in the order StochasticSplats draws them at these
    /// settings: (depth, id) at centre depth, scene order at the max-density plane.
    pub fn stochastic_order(&self) -> Result<Vec<u32>, GpuError> {
        self.read_order(self.order_parts(Draw::Stochastic))
    }

    /// The first (visible) entries of `parts`, an order of the depth sort's cut.
    fn read_order(&self, parts: &[wgpu::Buffer]) -> Result<Vec<u32>, GpuError> {
        let visible = self.ctx.read_u32(&self.draw_args, 4)?[1];
        self.depth.read(self.ctx, parts, 0..u64::from(visible))
    }

    /// Render `frames.count` frames of `method` (one for sorted splatting) and fold them into
    /// the per-pixel running mean and M2 (f32 Welford, as the ray-tracing kernel does).
    ///
    /// Sorted splatting and StochasticSplats draw in a render pipeline, at S > 1 samples per
    /// pixel through the hardware's multisampling (a sample mask per fragment, the depth test
    /// per sample, the fold resolving the samples). Enderton and Laine–Karras run their raster
    /// operations in the compute tile pass ([`GpuRasterizer::render`]'s `tile_rop`, whose
    /// comment in `shaders/rop.wgsl` says why). Lit, sorted splatting runs on the compute
    /// tile rasterizer ([`GpuRasterizer::depth_pick`]), which composites front to back with the
    /// transmittance at hand (as the CPU does when lit), integrates the normals and lights each
    /// pixel once (the surface look) or each fragment (the volumetric look); StochasticSplats
    /// lights each written fragment.
    pub fn render(&self, method: &RasterMethod, frames: &Frames) -> Result<(RenderOutput, GpuStats), GpuError> {
        let keys = frames.keys(method.is_stochastic())?;
        self.render_keys(method, &keys, frames)
    }

    /// The frames of keys `keys` (frame i of the running mean drawn with `keys[i]`), the
    /// decisions' shift and the mean's storage from `frames`: [`GpuRasterizer::render`], or one
    /// frame of a camera drawn per frame ([`crate::render`]).
    pub fn render_keys(
        &self,
        method: &RasterMethod,
        keys: &[u32],
        frames: &Frames,
    ) -> Result<(RenderOutput, GpuStats), GpuError> {
        let draw = self.check_scene(method)?;
        if self.scene.is_lit() && matches!(draw, Draw::Over | Draw::Under) {
            return self.render_lit_sorted(frames);
        }
        if frames.rng != splat_core::rng::RngScheme::Hash {
            return Err(GpuError::Unsupported(
                "the raster methods draw their decisions with the hash generator".into(),
            ));
        }
        let count = keys.len() as u32;
        self.set_mode(draw);
        let (w, h) = (self.camera.width, self.camera.height);
        let pixels = (w * h) as usize;
        let target_samples = if draw.is_rop() { 1 } else { self.raster.samples };
        let targets = RasterTargets::new(self.ctx, self.pipes, w, h, draw, target_samples);
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
        let draw_group = self.draw_group(&slots.buffer, draw);
        let fold_group = self.fold_group(&slots.buffer, &targets.color_view, &mean, &m2, target_samples > 1);
        let fold = if target_samples > 1 { &self.pipes.fold_msaa } else { &self.pipes.fold };
        let rop = draw.is_rop().then(|| rop::RopPass::new(self, &targets, false)).transpose()?;
        let mut gpu_time = Duration::ZERO;
        for (batch_index, batch) in keys.chunks(FRAMES_PER_SUBMIT as usize).enumerate() {
            let first = batch_index as u32 * FRAMES_PER_SUBMIT;
            slots.write(self.ctx, batch, first, frames);
            let mut encoder = self.encoder("raster frames");
            for slot in 0..batch.len() as u32 {
                let offset = slots.offset(slot);
                match &rop {
                    Some(rop) => rop.encode(self, &mut encoder, &slots, slot)?,
                    None => self.encode_draw(&mut encoder, draw, &targets, &draw_group, offset, None)?,
                }
                let mut pass = encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("fold"), timestamp_writes: None });
                pass.set_pipeline(fold);
                pass.set_bind_group(0, &fold_group, &[offset]);
                self.ctx.dispatch(&mut pass, w.div_ceil(8), h.div_ceil(8), 1);
            }
            let start = Instant::now();
            self.submit(encoder)?;
            gpu_time += start.elapsed();
        }
        let mean = self.ctx.read_f32(&mean, pixels * 4)?;
        let m2 = self.ctx.read_f32(&m2, pixels * 4)?;
        Ok(crate::output(&self.camera, &mean, &m2, count, gpu_time, false))
    }

    /// The shaders' draw of `method` where [`GpuRasterizer::supports`] accepts it at these
    /// settings and a render pipeline multisamples at the counts the adapter has.
    fn check_scene(&self, method: &RasterMethod) -> Result<Draw, GpuError> {
        Self::supports(method, &self.raster)?;
        let draw = Draw::of(method).ok_or_else(|| {
            GpuError::Unsupported(format!(
                "the catalogue gives {} a GPU kernel, but the raster shaders do not draw it",
                method.id().name()
            ))
        })?;
        if !draw.is_rop() {
            self.check_opaque_meshes(&format!("{} on the GPU", method.id().name()))?;
        }
        let s = self.raster.samples;
        if !draw.is_rop() && !self.ctx.msaa_counts.contains(&s) {
            let reason = format!(
                "{} multisamples the raster targets at {:?} samples per pixel, not {s} (Enderton and stratified run at 1, 2, 4, 8 or 16 on any adapter)",
                self.ctx.info.name, self.ctx.msaa_counts
            );
            return Err(GpuError::refused(reason, &[Remedy::Cpu]));
        }
        Ok(draw)
    }

    /// Refuse transparent mesh triangles in `what`, which draws splats only: the render
    /// pipelines' hardware blending and depth test (sorted splatting, StochasticSplats) and the
    /// tile rasterizer's depth pick and first hits have no place for a triangle among them.
    pub(super) fn check_opaque_meshes(&self, what: &str) -> Result<(), GpuError> {
        if self.scene.transparent.is_empty() {
            return Ok(());
        }
        Err(GpuError::refused(
            format!("{what} draws no transparent mesh triangles"),
            &[Remedy::RasterOperations, Remedy::Cpu],
        ))
    }

    /// One lit frame of sorted splatting from the compute tile rasterizer.
    fn render_lit_sorted(&self, frames: &Frames) -> Result<(RenderOutput, GpuStats), GpuError> {
        frames.keys(false)?;
        let start = Instant::now();
        let pick = self.depth_pick()?;
        let stats = GpuStats {
            loop_iterations: 0,
            mean_loop_iterations: 0.0,
            frames_per_dispatch: 1,
            pass_per_dispatch: false,
            gpu_time: start.elapsed(),
            timestamps: false,
        };
        let out = RenderOutput {
            variance: Image::filled(self.camera.width, self.camera.height, 3, 0.0),
            depth: pick.depth_image(),
            mean: pick.color,
            alpha: pick.alpha,
            normal: pick.normal,
            picked: pick.picked,
        };
        Ok((out, stats))
    }

    /// Whether the GPU rasterizer renders `method` with `settings`, before the scene and the
    /// adapter are known (the one place that decides it; [`GpuRasterizer::render`] then checks
    /// the adapter's sample counts and the scene): every raster method, at the standard sample
    /// pattern, without the early stop; sorted splatting at centre depth (the max-density plane
    /// orders each sample's fragments apart, which blending hardware cannot). The CPU reference
    /// renders everything.
    pub fn supports(method: &RasterMethod, settings: &RasterSettings) -> Result<(), GpuError> {
        check_settings(settings)?;
        crate::error::supports_method(method.id())?;
        if settings.lk_variant != splat_core::raster::LkVariant::Paper {
            return Err(GpuError::refused(
                format!("the Laine–Karras control '{}' runs on the CPU only", settings.lk_variant.name()),
                &[Remedy::Cpu],
            ));
        }
        if matches!(method, RasterMethod::Sorted { .. }) && settings.fragment_depth == FragmentDepth::MaxDensityPlane {
            return Err(GpuError::refused(
                "raster-sorted at the max-density plane sorts each sample's fragments apart, which hardware blending cannot",
                &[Remedy::CenterDepth, Remedy::Cpu],
            ));
        }
        Ok(())
    }

    /// Whether the hybrid pipeline's first hits ([`GpuRasterizer::first_hits`]) take `settings`:
    /// at any sample count (the ray-tracing kernel continues each sample's ray), at centre depth
    /// (the tile pass walks the splats in centre-depth order).
    pub fn supports_first_hits(settings: &RasterSettings) -> Result<(), GpuError> {
        centre_depth_order(settings, "the GPU hybrid's first hits walk")
    }

    /// Whether the tile rasterizer's iso-opacity depth pick ([`GpuRasterizer::depth_pick`]) takes
    /// `settings`: at any sample count (the pick is sample 0's), at centre depth (the tile
    /// lists hold the splats in centre-depth order).
    pub fn supports_depth_pick(settings: &RasterSettings) -> Result<(), GpuError> {
        centre_depth_order(settings, "the GPU's iso-opacity depth walks")
    }

    fn set_mode(&self, draw: Draw) {
        let params = RasterParams { mode: draw.mode(), ..self.params };
        self.ctx.queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
    }

    /// The splat draw's bindings for `draw`.
    fn draw_group(&self, frame_params: &wgpu::Buffer, draw: Draw) -> BindGroups {
        let own = [
            wgpu::BindGroupEntry { binding: 0, resource: self.params_buffer.as_entire_binding() },
            frame_entry(1, frame_params),
            wgpu::BindGroupEntry { binding: 4, resource: self.draw_args.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 5, resource: self.behind.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 6, resource: self.sample_offsets.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 13, resource: self.scene.materials.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 14, resource: self.scene.lights.as_entire_binding() },
        ];
        let parts =
            [self.split_parts(true, true), self.scene.split.bind(&DRAWN_ORDER, self.order_parts(draw))].concat();
        let layouts = (&self.k.splat_layout, self.k.splat_arrays_layout.as_ref());
        BindGroups::new(&self.ctx.device, Some("splat"), layouts.0, layouts.1, &own, &parts)
    }

    fn fold_group(
        &self,
        frame_params: &wgpu::Buffer,
        color: &wgpu::TextureView,
        mean: &wgpu::Buffer,
        m2: &wgpu::Buffer,
        multisampled: bool,
    ) -> wgpu::BindGroup {
        self.ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fold"),
            layout: if multisampled { &self.pipes.fold_msaa_layout } else { &self.pipes.fold_layout },
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: self.params_buffer.as_entire_binding() },
                frame_entry(1, frame_params),
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(color) },
                wgpu::BindGroupEntry { binding: 3, resource: mean.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: m2.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: self.behind.as_entire_binding() },
            ],
        })
    }

    /// One render pass drawing every splat quad of `draw` into `targets`.
    fn encode_draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        draw: Draw,
        targets: &RasterTargets,
        group: &BindGroups,
        frame_offset: u32,
        timestamps: Option<wgpu::RenderPassTimestampWrites>,
    ) -> Result<(), GpuError> {
        let pipelines = match self.raster.samples {
            1 => &self.k.single,
            s => match self.msaa.get() {
                Some(p) => p,
                None => {
                    let built = self.k.at_samples(self.ctx, s)?;
                    self.msaa.get_or_init(|| built)
                }
            },
        };
        let plane = self.raster.fragment_depth == FragmentDepth::MaxDensityPlane;
        let pipeline = pipelines.get(draw, self.scene.is_lit(), plane)?;
        let bg = self.scene.settings.background.as_dvec3();
        // Over and stochastic frames start from the background; under accumulates premultiplied
        // colour from zero and the fold adds the background behind the remaining transmittance.
        // Among meshes every draw starts transparent and the fold adds what lies behind.
        let clear = match draw {
            _ if self.scene.has_meshes => wgpu::Color::TRANSPARENT,
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
        pass.set_pipeline(pipeline);
        group.set_render(&mut pass, &[frame_offset]);
        self.ctx.count_draw();
        // The visible splats alone, in the order the group binds ([`Self::order_parts`]): an
        // indirect draw of the projection's count.
        pass.draw_indirect(&self.draw_args, 0);
        Ok(())
    }
}

/// The raster settings the GPU renders: no early stop, the standard pattern, the projected
/// response.
fn check_settings(settings: &RasterSettings) -> Result<(), GpuError> {
    settings.validate()?;
    if settings.early_stop {
        return Err(GpuError::refused(
            "early stop needs the transmittance before each fragment, which hardware blending does not give",
            &[Remedy::NoEarlyStop, Remedy::Cpu],
        ));
    }
    if settings.response == Response::AlongRay {
        return Err(GpuError::refused(
            "the GPU rasterizer evaluates the projected 2D Gaussians; evaluating each particle along the pixel's ray (3DGUT, 2DGS) runs on the CPU",
            &[Remedy::Cpu],
        ));
    }
    if settings.samples > 1 && settings.sample_pattern != SamplePattern::Standard {
        let reason = format!(
            "the GPU's {} samples per pixel lie at the hardware's standard positions, not the {} pattern",
            settings.samples,
            settings.sample_pattern.name()
        );
        return Err(GpuError::refused(reason, &[Remedy::StandardPattern, Remedy::Cpu]));
    }
    Ok(())
}

/// The tile pass's rule: its lists hold the splats in centre-depth order, so what walks them
/// (`walker`, as the refusal says it) takes `settings` at centre depth only.
fn centre_depth_order(settings: &RasterSettings, walker: &str) -> Result<(), GpuError> {
    if settings.fragment_depth != FragmentDepth::Center {
        let reason = format!("{walker} the splats in centre-depth order, not at {:?} depth", settings.fragment_depth);
        return Err(GpuError::refused(reason, &[Remedy::CenterDepth, Remedy::Cpu]));
    }
    Ok(())
}

/// Entries of the mesh pre-pass's buffers: one per sample of every pixel among meshes (one
/// unused entry without), refused above the adapter's binding limit.
fn mesh_prepass_entries(
    ctx: &GpuContext,
    scene: &RasterScene,
    camera: &Camera,
    raster: &RasterSettings,
) -> Result<u64, GpuError> {
    if !scene.has_meshes {
        return Ok(1);
    }
    let entries = u64::from(camera.width) * u64::from(camera.height) * u64::from(raster.samples);
    let bytes = entries * 16;
    if bytes > ctx.max_binding {
        let reason = format!(
            "the mesh pre-pass holds 16 bytes for each of the {} × {} × {} samples, {bytes} bytes, but the adapter binds at most {} bytes per storage buffer (fewer samples per pixel or a smaller image would fit)",
            camera.width, camera.height, raster.samples, ctx.max_binding
        );
        return Err(GpuError::refused(reason, &[Remedy::Cpu]));
    }
    Ok(entries)
}

/// The bind groups of a compute pipeline whose layout is derived from its module (the bindings
/// its entry point uses alone): whole buffers `own` and the split arrays' `parts`.
fn bind(
    ctx: &GpuContext,
    pipeline: &wgpu::ComputePipeline,
    own: &[(u32, &wgpu::Buffer)],
    parts: &[crate::split::Bound],
) -> BindGroups {
    let own: Vec<_> =
        own.iter().map(|&(binding, b)| wgpu::BindGroupEntry { binding, resource: b.as_entire_binding() }).collect();
    BindGroups::auto(&ctx.device, None, pipeline, &own, parts)
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

/// Render targets of one draw: colour (written by the raster operations' kernel for Enderton
/// and stratified), and depth for StochasticSplats; `samples` per pixel.
struct RasterTargets {
    pub(super) color_view: wgpu::TextureView,
    pub(super) depth_view: Option<wgpu::TextureView>,
}

impl RasterTargets {
    fn new(ctx: &GpuContext, pipes: &RasterPipelines, width: u32, height: u32, draw: Draw, samples: u32) -> Self {
        let texture = |label, format, usage| {
            ctx.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: samples,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let blended = matches!(draw, Draw::Over | Draw::Under);
        // The format the draw's pipeline was built for.
        let format = if blended { pipes.blend_format } else { STOCHASTIC_FORMAT };
        let usage = match draw {
            _ if draw.is_rop() => wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
            _ => wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        };
        Self {
            color_view: texture("splat colour", format, usage),
            depth_view: (draw == Draw::Stochastic)
                .then(|| texture("splat depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT)),
        }
    }
}

/// Per-frame parameter slots of one submission, addressed by dynamic offset.
struct FrameSlots {
    pub(super) buffer: wgpu::Buffer,
    pub(super) stride: u64,
}

impl FrameSlots {
    fn new(ctx: &GpuContext) -> Self {
        let stride = (size_of::<FrameParams>() as u64).next_multiple_of(ctx.storage_alignment);
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame params"),
            size: stride * u64::from(FRAMES_PER_SUBMIT),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Self { buffer, stride }
    }

    fn write(&self, ctx: &GpuContext, keys: &[u32], first: u32, frames: &Frames) {
        let mut bytes = vec![0u8; (self.stride as usize) * keys.len()];
        for (slot, &key) in keys.iter().enumerate() {
            let (index, accumulation, u_shift) = (first + slot as u32, frames.accumulation.code(), frames.u_shift);
            let p = FrameParams { key, index, accumulation, u_shift };
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
    use crate::layout::wgsl_check::{assert_constants, assert_mirrors, check_layout, validate, validate_with};

    /// Every constant the raster shaders share with the core has the core's value, and the
    /// draw modes equal the pipeline's [`Draw`] codes.
    #[test]
    fn raster_constants_equal_their_rust_twins() {
        use splat_core::raster::project;
        assert_constants!(
            &RASTER_WGSL,
            [
                "TILE" = TILE,
                "EXTENT_SQ" = project::EXTENT_SQ,
                "BOX_SIGMAS" = project::BOX_SIGMAS,
                "EIGEN_FLOOR" = project::EIGEN_FLOOR,
                "EXTENT_3DGS" = project::SplatExtent::ThreeDgs as u32,
                "EXTENT_SQRT8" = project::SplatExtent::Sqrt8 as u32,
                "NONE" = NONE,
                "SH_C0" = splat_core::sh::SH_C0,
                "ACCUMULATION_F16" = splat_core::frame::AccumulationFormat::F16.code(),
                "ACCUMULATION_UNORM8" = splat_core::frame::AccumulationFormat::Unorm8.code(),
                "DEGENERATE_NORMAL" = splat_core::composite::DEGENERATE_NORMAL as f32,
                "NORMAL_PLANE" = crate::layout::normal_code(splat_core::normal::NormalMode::MaxDensityPlane),
                "NORMAL_ELLIPSOID" = crate::layout::normal_code(splat_core::normal::NormalMode::KernelEllipsoid),
                "LOOK_SURFACE" = crate::layout::LOOK_SURFACE,
                "LOOK_VOLUMETRIC" = crate::layout::LOOK_VOLUMETRIC,
                "LIGHT_SPOT" = crate::layout::LIGHT_SPOT,
                "ORDER_ID" = splat_core::raster::ORDER_ID,
                "SURFACE_ID" = splat_core::raster::SURFACE_ID,
                "ENDERTON_XI_SLOT" = splat_core::raster::ENDERTON_XI_SLOT,
                "MESH" = splat_core::raster::MESH,
                "ROP_SAMPLES" = splat_core::raster::STANDARD_COUNTS[4],
                "MODE_ENDERTON" = Draw::Enderton.mode(),
                "MODE_STRATIFIED" = Draw::Stratified.mode(),
                "MODE_STRATIFIED_PLAIN" = Draw::StratifiedPlain.mode(),
                "FIRST_HIT_SORTED" = crate::layout::FIRST_HIT_SORTED,
                "FIRST_HIT_ACCEPTED" = crate::layout::FIRST_HIT_ACCEPTED,
                "FIRST_HIT_COUNT" = crate::layout::FIRST_HIT_COUNT,
                "FIRST_HIT_FRAGMENTS" = crate::layout::FIRST_HIT_FRAGMENTS,
            ]
        );
        assert_constants!(
            &SPLAT_WGSL,
            [
                "MODE_OVER" = Draw::Over.mode(),
                "MODE_UNDER" = Draw::Under.mode(),
                "MODE_STOCHASTIC" = Draw::Stochastic.mode()
            ]
        );
    }

    /// Sizes and offsets of the Rust mirrors equal naga's layout of the WGSL structs.
    #[test]
    fn rust_structs_mirror_the_raster_wgsl_structs() {
        assert_mirrors!(&RASTER_WGSL, RasterParticle, "RasterParticle", [mean, opacity, cov_a, pad0, cov_b, pad1]);
        assert_mirrors!(&RASTER_WGSL, GpuSplat, "Splat", [mean, depth, opacity, conic, id, color, bound, rect]);
        assert_mirrors!(
            &RASTER_WGSL,
            crate::layout::GpuFragment,
            "Fragment",
            [color, weight, normal, t, id, pad0, pad1, pad2]
        );
        assert_mirrors!(
            &RASTER_WGSL,
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
                extent,
                lit,
                look,
                light_count,
                set_count,
                t_min,
                t_max,
                meshes,
                first_hit,
                samples,
                hilbert_order,
                filter_variance,
                filter_compensates,
                lens,
                near,
                distortion,
                normal_mode,
                cutoff,
                frame_key,
                u_shift
            ]
        );
        assert_mirrors!(&SPLAT_WGSL, FrameParams, "FrameParams", [key, index, accumulation, u_shift]);
    }

    /// Every raster module is valid WGSL for naga (a shader error fails `cargo test`).
    #[test]
    fn raster_wgsl_validates() {
        let modules = [
            ("raster", RASTER_WGSL.as_str()),
            ("splat", SPLAT_WGSL.as_str()),
            ("fold", FOLD_WGSL),
            ("fold (multisampled)", FOLD_MSAA_WGSL),
            ("mesh pre-pass", MESH_PREPASS_WGSL),
        ];
        for (name, source) in modules {
            validate(name, source);
        }
        validate_with("splat (plane)", &SPLAT_PLANE_WGSL, naga::valid::Capabilities::MULTISAMPLED_SHADING);
    }

    /// [`scene::OWN_BINDINGS`] is the most storage buffers a splatting kernel (its automatic
    /// layout) or a stage of the splat draw (its written one) binds beside the split arrays'
    /// extra parts: the budget [`RasterSplit::new`] leaves them.
    #[test]
    fn own_bindings_are_the_most_a_splatting_stage_binds() {
        use crate::layout::wgsl_check::storage_buffers_used;
        let kernels = storage_buffers_used("raster", &RASTER_WGSL);
        let draw = super::pipelines::splat_layout_entries(&RasterSplit::WHOLE);
        let stage = |stage: wgpu::ShaderStages| {
            let storage = |e: &&wgpu::BindGroupLayoutEntry| matches!(e.ty, wgpu::BindingType::Buffer { .. });
            draw.iter().filter(storage).filter(|e| e.visibility.contains(stage)).count() as u32
        };
        let most = kernels
            .iter()
            .map(|(_, n)| *n)
            .chain([stage(wgpu::ShaderStages::VERTEX), stage(wgpu::ShaderStages::FRAGMENT)])
            .max();
        assert_eq!(most, Some(scene::OWN_BINDINGS), "{kernels:?}");
    }

    /// A split scene's modules validate, and the splat draw's layout of that split matches its
    /// WGSL (the kernels' layouts are automatic).
    #[test]
    fn split_modules_validate_and_their_draw_layout_matches() {
        use crate::split::Split;
        use naga::valid::Capabilities;
        let split = RasterSplit {
            splats: Split { parts: 3, shift: 4 },
            canonical: Split { parts: 2, shift: 6 },
            ranks: Split { parts: 2, shift: 8 },
            pairs: Split { parts: 3, shift: 9 },
            sh_storage: splat_core::sh::ShStorage::F16,
            parts: crate::split::PartBindings::Each,
        };
        let raster = split.raster_wgsl();
        validate("raster (split, f16 SH)", &raster);
        assert!(raster.contains("case 2u: { splats_2[j] = v; }"), "the setter writes every part");
        assert!(raster.contains("@binding(32) var<storage, read> canonical_1"), "canonical parts follow the splats'");
        assert!(raster.contains("case 1u: { offsets_1[j] = v; }"), "the offsets are split as the sort cuts them");
        assert!(raster.contains("case 2u: { v = pair_ranks_2[j]; }"), "the pairs are split as their sort cuts them");
        assert!(split.splat_wgsl(false).contains("case 1u: { v = order_1[j]; }"), "the draw reads the split order");
        let entries = super::pipelines::splat_layout_entries(&split);
        check_layout("splat (split)", &split.splat_wgsl(false), Capabilities::empty(), &entries);
        check_layout("splat (split, plane)", &split.splat_wgsl(true), Capabilities::MULTISAMPLED_SHADING, &entries);
        // The same split with the parts after the first in binding arrays.
        let arrayed = RasterSplit { parts: crate::split::PartBindings::Array, ..split };
        let arrays = crate::layout::wgsl_check::BINDING_ARRAYS;
        let raster = arrayed.raster_wgsl();
        crate::layout::wgsl_check::validate_with("raster (split, binding arrays)", &raster, arrays);
        assert!(raster.contains("binding_array<pair_ranks_part, 2>"), "the pairs' parts after the first");
        let entries = super::pipelines::splat_layout_entries(&arrayed);
        let array_entries = super::pipelines::splat_array_entries(&arrayed);
        assert_eq!(array_entries.len(), 3, "the splats', canonical transforms' and order's parts after the first");
        let groups: [&[_]; 2] = [&entries, &array_entries];
        use crate::layout::wgsl_check::check_layouts;
        check_layouts("splat (split, binding arrays)", &arrayed.splat_wgsl(false), arrays, &groups);
        let plane = arrays | Capabilities::MULTISAMPLED_SHADING;
        check_layouts("splat (split, plane, binding arrays)", &arrayed.splat_wgsl(true), plane, &groups);
    }

    /// The hand-written layouts of the splat draw and the fold match their shaders' bindings
    /// (the compute passes of `raster.wgsl` and the mesh pre-pass take theirs from the shader).
    #[test]
    fn raster_layouts_match_their_shaders() {
        use super::pipelines::{fold_layout_entries, splat_layout_entries};
        use naga::valid::Capabilities;
        let splat = splat_layout_entries(&RasterSplit::WHOLE);
        check_layout("splat", &SPLAT_WGSL, Capabilities::empty(), &splat);
        check_layout("splat (plane)", &SPLAT_PLANE_WGSL, Capabilities::MULTISAMPLED_SHADING, &splat);
        check_layout("fold", FOLD_WGSL, Capabilities::empty(), &fold_layout_entries(false));
        check_layout("fold (multisampled)", FOLD_MSAA_WGSL, Capabilities::empty(), &fold_layout_entries(true));
    }
}
