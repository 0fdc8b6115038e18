//! The splatting path's data on the device: particles and SH in scene order, and the uniform
//! structs mirrored by `shaders/raster_types.wgsl`.

use super::*;
use crate::split::{Bound, MAX_ELEMENTS, PartBindings, PartBytes, Split, SplitArray, SplitLayout};
use splat_core::sh::ShStorage;

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
    /// The largest Mahalanobis term of the footprint ([`splat_core::raster::Splat::bound`]).
    pub bound: f32,
    /// Pixel rect [x0, y0, x1, y1); empty when the particle is culled.
    pub rect: [u32; 4],
}

/// Per-camera uniforms of the raster kernels (WGSL `RasterParams`, 256 bytes).
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
    /// Iso-opacity threshold on the transmittance: splatting's
    /// ([`RenderSettings::raster_iso_threshold`]).
    pub iso_threshold: f32,
    /// Frustum guard limits on |x/z|, |y/z|.
    pub guard: [f32; 2],
    /// Tiles across and down.
    pub tiles: [u32; 2],
    /// 0 over, 1 under, 2 stochastic splat.
    pub mode: u32,
    /// The splat extent ([`splat_core::raster::SplatExtent`] as u32: 0 3DGS tiles, 1 √8σ, 2
    /// alpha cull).
    pub extent: u32,
    /// 1 when lighting is on ([`Lighting::is_on`]).
    pub lit: u32,
    /// 0 surface, 1 volumetric (the `LOOK_*` constants of the shaders).
    pub look: u32,
    /// Lights (0: the headlight).
    pub light_count: u32,
    /// Splat sets.
    pub set_count: u32,
    /// Ray start of the mesh pre-pass.
    pub t_min: f32,
    /// Ray end of the mesh pre-pass.
    pub t_max: f32,
    /// 1 when the scene has meshes ([`RasterScene::with_meshes`]).
    pub meshes: u32,
    /// Which first hit the tile rasterizer writes for the hybrid pipeline (`FIRST_HIT_*`), 0
    /// for a pixel.
    pub first_hit: u32,
    /// Samples per pixel S.
    pub samples: u32,
    /// Order of the Hilbert curve over the image (Laine–Karras pixel ids).
    pub hilbert_order: u32,
    /// The scene's screen filter: the variance s added to Σ₂, px²
    /// ([`splat_core::ScreenFilter::variance`]).
    pub filter_variance: f32,
    /// 1 when the filter scales the opacity by ρ = √(det Σ₂ / det Σ′).
    pub filter_compensates: u32,
    /// The camera's lens (`LENS_*` of `lens.wgsl`).
    pub lens: u32,
    /// The near plane ([`RenderSettings::near`]).
    pub near: f32,
    /// Its distortion, as the trace kernel's `Params::distortion`.
    pub distortion: [[f32; 4]; 3],
    /// Per-particle normal (`NORMAL_*` in `lighting.wgsl`).
    pub normal_mode: u32,
    /// The cutoff of the ellipsoid normals (Eq. 2).
    pub cutoff: f32,
    /// The frame key of a StochasticSplats first hit ([`splat_core::rng::frame_key`]).
    pub frame_key: u32,
    /// Its [`splat_core::Frames::u_shift`].
    pub u_shift: f32,
}

/// Per-frame uniforms (WGSL `FrameParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FrameParams {
    /// The frame key of the hashes ([`splat_core::rng::frame_key`]).
    pub key: u32,
    /// Index of the frame in the running mean.
    pub index: u32,
    /// How the running mean is stored ([`splat_core::frame::AccumulationFormat::code`]).
    pub accumulation: u32,
    /// [`splat_core::Frames::u_shift`], subtracted from every u (a test hook; 0 in renders).
    pub u_shift: f32,
}

/// The projected splats as the raster kernels write and read them (`splat_at`, `splat_set`), part
/// 0 at binding 3 ([`crate::split`]).
pub(super) const SPLATS: SplitArray =
    SplitArray::of::<GpuSplat>("projected splat", "splats", "splat_at", "Splat", 3).writable("splat_set");
/// The same splats as the splat draw's stages read them, part 0 at binding 2.
pub(super) const DRAWN_SPLATS: SplitArray =
    SplitArray::of::<GpuSplat>("projected splat", "splats", "splat_at", "Splat", 2);
/// The rows of each particle's canonical transform (three a particle, `canonical_at`), part 0 at
/// binding 15 in every module.
pub(super) const CANONICAL: SplitArray =
    SplitArray::of::<[f32; 4]>("canonical transform", "canonical", "canonical_at", "vec4<f32>", 15);
/// The depth sort's keys (depth bits) as the projection writes them, part 0 at binding 4; the
/// shuffle of the raster operations writes its hashes there.
pub(super) const DEPTH_KEYS: SplitArray =
    SplitArray::of::<u32>("sort key", "depth_keys", "depth_key_at", "u32", 4).writable("depth_key_set");
/// The particle of each rank after the sort (`order_at(r)`), part 0 at binding 5.
pub(super) const ORDER: SplitArray =
    SplitArray::of::<u32>("sort value", "order", "order_at", "u32", 5).writable("order_set");
/// The same order as the splat draw's vertex stage reads it, part 0 at binding 3.
pub(super) const DRAWN_ORDER: SplitArray = SplitArray::of::<u32>("sort value", "order", "order_at", "u32", 3);
/// Each rank's tile pairs, then their exclusive scan (`offset_at(r)`): the sort's histogram, part
/// 0 at binding 7.
pub(super) const OFFSETS: SplitArray =
    SplitArray::of::<u32>("sort histogram", "offsets", "offset_at", "u32", 7).writable("offset_set");
/// The tile of each (tile, rank) pair, part 0 at binding 8.
pub(super) const PAIR_TILES: SplitArray =
    SplitArray::of::<u32>("tile pair", "pair_tiles", "pair_tile_at", "u32", 8).writable("pair_tile_set");
/// The rank of each pair, part 0 at binding 9.
pub(super) const PAIR_RANKS: SplitArray =
    SplitArray::of::<u32>("tile pair", "pair_ranks", "pair_rank_at", "u32", 9).writable("pair_rank_set");
/// The binding of a projection chunk's SH.
const SH_BINDING: u32 = 2;
/// The binding of the first part after the first of the split arrays, in every splatting module.
const FIRST_EXTRA: u32 = 30;
/// The most storage buffers a splatting kernel or a stage of the splat draw binds beside the
/// parts after the first of its split arrays (checked against the shaders by a test).
pub(super) const OWN_BINDINGS: u32 = 16;

/// The bindings of a split array's parts.
pub(super) type Bindings<'b> = Vec<Bound<'b>>;

/// How a scene's projected splats (64 bytes each), canonical transforms (48), sort arrays (4 a
/// particle each: depth keys, order, offsets) and the tile pairs of a tile pass (4 bytes each
/// for the tile and the rank) are split over bindings, and how its SH are stored: the splatting
/// kernels and the splat draw are compiled for it ([`RasterPipelines`] keeps one set per split
/// it has met). The particles and SH need no split: the projection reads them in chunks of one
/// binding each ([`RasterScene::chunks`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RasterSplit {
    /// The projected splats, in scene order.
    pub splats: Split,
    /// The canonical transforms' rows, in scene order.
    pub canonical: Split,
    /// The depth sort's keys and values and the offsets of the tile pairs: the arrays of the
    /// sort of `count + 1` pairs ([`crate::sort::split_of`]).
    pub ranks: Split,
    /// The tile pairs: the arrays of their sort, set for each tile pass by the pairs it makes
    /// (`RasterSplit::with_pairs`).
    pub pairs: Split,
    /// The SH's precision ([`RenderSettings::sh_storage`]).
    pub sh_storage: ShStorage,
    /// How the parts after the first are bound (the device's way).
    pub parts: PartBindings,
}

impl RasterSplit {
    /// Every array in one binding.
    pub const WHOLE: RasterSplit = RasterSplit {
        splats: Split::WHOLE,
        canonical: Split::WHOLE,
        ranks: Split::WHOLE,
        pairs: Split::WHOLE,
        sh_storage: ShStorage::F32,
        parts: PartBindings::Each,
    };

    /// The split of a scene of `count` particles, SH stored as `sh_storage`, on `ctx`, refused
    /// when it needs more bindings than the adapter has ([`GpuError::SceneOverBindings`]) with how
    /// many particles would fit, or more memory than the device has left, where it can tell
    /// ([`GpuError::MemoryShort`]).
    pub fn new(ctx: &GpuContext, count: usize, sh_storage: ShStorage) -> Result<Self, GpuError> {
        let n = count as u64;
        if SPLATS.stride > ctx.max_binding {
            let (buffer, bytes) = (SPLATS.what, n.max(1) * SPLATS.stride);
            return Err(GpuError::SceneTooLarge { buffer, bytes, limit: ctx.max_binding, count });
        }
        let split = Self::split(ctx, n, sh_storage);
        let bytes = n * (SPLATS.stride + 3 * CANONICAL.stride + 3 * 4);
        if Self::fits(ctx, n) {
            ctx.check_memory("projected splats, canonical transforms and depth sort", bytes)?;
            return Ok(split);
        }
        let (arrays, kernel, fits_what) =
            ("projected splats, canonical transforms and depth sort", "the splatting kernels", "particles like these");
        let fits = crate::split::most_that_fit(n, |m| Self::fits(ctx, m));
        // Past the kernels' indices (three canonical rows a particle, whatever the bindings),
        // else over their storage bindings or their elements of binding arrays.
        let elements = 3 * n;
        match split.layout(false).over(ctx, OWN_BINDINGS) {
            Some((needed, available)) if elements <= MAX_ELEMENTS => Err(GpuError::SceneOverBindings {
                arrays,
                kernel,
                needed,
                available,
                limit: ctx.max_binding,
                bytes,
                fits,
                fits_what,
            }),
            _ => Err(GpuError::SceneOverIndices { arrays, kernel, elements, fits, fits_what }),
        }
    }

    /// The most particles whose projected splats, canonical transforms and depth sort the
    /// splatting kernels bind on `ctx` (before an image's tile pairs, which the tile pass checks
    /// for itself): the bound the adapter's storage bindings set, whatever its memory.
    pub fn capacity(ctx: &GpuContext) -> u64 {
        crate::split::most_that_fit(MAX_ELEMENTS, |n| Self::fits(ctx, n))
    }

    /// The split of a scene of `n` particles by `ctx`'s binding limits (tile pairs whole).
    fn split(ctx: &GpuContext, n: u64, sh_storage: ShStorage) -> Self {
        RasterSplit {
            splats: Split::of(n.max(1), SPLATS.stride, ctx.max_binding),
            canonical: Split::of(3 * n.max(1), CANONICAL.stride, ctx.max_binding),
            ranks: crate::sort::split_of(n.saturating_add(1).min(MAX_ELEMENTS) as u32, ctx.max_index_binding),
            pairs: Split::WHOLE,
            sh_storage,
            parts: ctx.part_bindings(),
        }
    }

    /// Whether a scene of `n` particles fits the adapter: element indices within u32 (the
    /// kernels'), a projected splat within a binding, the parts within what a stage binds (the
    /// SH's storage does not change the count: a projection chunk's SH is whole).
    fn fits(ctx: &GpuContext, n: u64) -> bool {
        3 * n <= MAX_ELEMENTS
            && SPLATS.stride <= ctx.max_binding
            && Self::split(ctx, n, ShStorage::F32).layout(false).over(ctx, OWN_BINDINGS).is_none()
    }

    /// The split of a tile pass whose tile pairs are sorted in `pairs`: their arrays cut as that
    /// sort cuts them, refused when the kernels would need more bindings than the adapter has.
    pub(super) fn with_pairs(self, ctx: &GpuContext, pairs: &crate::sort::SortBuffers) -> Result<Self, GpuError> {
        let split = RasterSplit { pairs: pairs.split, ..self };
        let Some((needed, available)) = split.layout(false).over(ctx, OWN_BINDINGS) else { return Ok(split) };
        let with = |m: u64| RasterSplit { pairs: crate::sort::split_of(m as u32, ctx.max_index_binding), ..self };
        let fits = |m: u64| with(m).layout(false).over(ctx, OWN_BINDINGS).is_none();
        let pairs = pairs.capacity();
        Err(GpuError::SceneOverBindings {
            arrays: "tile pairs",
            kernel: "the tile pass",
            needed,
            available,
            limit: ctx.max_index_binding,
            bytes: 8 * u64::from(pairs),
            fits: crate::split::most_that_fit(u64::from(pairs), fits),
            fits_what: "tile pairs (a smaller image or fewer splats make fewer)",
        })
    }

    /// The split arrays of the raster kernels, with a chunk's SH whole (`drawn`: of the splat
    /// draw, which reads no SH).
    pub(super) fn layout(&self, drawn: bool) -> SplitLayout {
        let arrays = if drawn {
            vec![(DRAWN_SPLATS, self.splats), (CANONICAL, self.canonical), (DRAWN_ORDER, self.ranks)]
        } else {
            vec![
                (SPLATS, self.splats),
                (CANONICAL, self.canonical),
                (DEPTH_KEYS, self.ranks),
                (ORDER, self.ranks),
                (OFFSETS, self.ranks),
                (PAIR_TILES, self.pairs),
                (PAIR_RANKS, self.pairs),
                (crate::layout::sh_array(self.sh_storage, SH_BINDING).0, Split::WHOLE),
            ]
        };
        SplitLayout { arrays, first_extra: FIRST_EXTRA, parts: self.parts }
    }

    /// The raster kernels' WGSL for this split.
    pub(super) fn raster_wgsl(&self) -> String {
        let sh_decode = crate::layout::sh_array(self.sh_storage, SH_BINDING).1;
        let layout = self.layout(false);
        format!("{}{RASTER_SOURCE}{}{sh_decode}", layout.directives(), layout.wgsl())
    }

    /// The splat draw's WGSL for this split, with the max-density-plane entry point or not.
    pub(super) fn splat_wgsl(&self, plane: bool) -> String {
        let plane = if plane { SPLAT_PLANE_SOURCE } else { "" };
        let layout = self.layout(true);
        format!("{}{SPLAT_SOURCE}{plane}{}", layout.directives(), layout.wgsl())
    }

    /// The splat draw's layout entries in bind group `group` of the parts after the first: the
    /// splats' in both stages, the canonical transforms' in the fragment stage, the order's in
    /// the vertex stage.
    pub(super) fn draw_extra_entries(&self, group: u32) -> Vec<wgpu::BindGroupLayoutEntry> {
        let stages = [wgpu::ShaderStages::VERTEX_FRAGMENT, wgpu::ShaderStages::FRAGMENT, wgpu::ShaderStages::VERTEX];
        self.layout(true).extra_entries(group, |a| stages[a])
    }

    /// The bindings of `array`'s parts, held in `parts`, in a raster kernel or the splat draw
    /// (whichever has the array).
    pub(super) fn bind<'b>(&self, array: &SplitArray, parts: &'b [wgpu::Buffer]) -> Bindings<'b> {
        let raster = self.layout(false).bind(array, parts);
        if raster.is_empty() { self.layout(true).bind(array, parts) } else { raster }
    }
}

/// A scene uploaded for rasterization: particles (mean, opacity, covariance) and SH in scene
/// order, and its lighting (materials, lights, and each particle's canonical transform for its
/// normal).
pub struct RasterScene {
    /// The particles and SH coefficients in chunks of one binding each.
    pub(super) chunks: Vec<ProjectChunk>,
    pub(super) count: u32,
    pub(super) sh_degree: u32,
    pub(super) screen_filter: splat_core::ScreenFilter,
    pub(super) settings: RenderSettings,
    pub(super) lighting: Lighting,
    pub(super) materials: wgpu::Buffer,
    pub(super) lights: wgpu::Buffer,
    /// The canonical transforms' rows, in the parts of `split.canonical`.
    pub(super) canonical: Vec<wgpu::Buffer>,
    /// How the projected splats and canonical transforms are split over bindings.
    pub(super) split: RasterSplit,
    /// The meshes' BVH nodes, triangles and materials (one unused entry each without meshes).
    pub(super) mesh_nodes: wgpu::Buffer,
    pub(super) triangles: wgpu::Buffer,
    pub(super) mesh_materials: wgpu::Buffer,
    /// Every triangle in the meshes' order, for the raster operations' transparent fragments
    /// (one unused entry without meshes).
    pub(super) ordered_triangles: wgpu::Buffer,
    /// The transparent triangles, ascending in the meshes' order: their place and vertices, which
    /// each camera bins into its tiles ([`super::rop::TriangleLists`]).
    pub(super) transparent: Vec<(u32, [glam::Vec3; 3])>,
    pub(super) has_meshes: bool,
}

/// Particles `first..first + count` of the scene and their SH coefficients, each in a binding
/// of its own, projected by a dispatch of their own (`project_chunk` in `shaders/raster.wgsl`):
/// so neither array bounds a scene.
pub(super) struct ProjectChunk {
    pub(super) particles: wgpu::Buffer,
    pub(super) sh: wgpu::Buffer,
    /// `[first, count]`.
    pub(super) range: wgpu::Buffer,
    pub(super) count: u32,
}

impl ProjectChunk {
    /// The particles of `scene` and their SH (stored as `sh_storage`) in chunks of the most
    /// particles, a power of two, whose particles and SH each fit a binding, each chunk made as
    /// it is uploaded.
    fn split(ctx: &GpuContext, scene: &Scene, sh_storage: ShStorage) -> Result<Vec<Self>, GpuError> {
        use crate::split::upload_parts;
        let (count, per) = (scene.particles.len(), splat_core::particle::sh_coeff_count(scene.sh_degree) as u64);
        let sh_bytes = 4 * crate::layout::sh_words(sh_storage) as u64 * per;
        let particle_bytes = size_of::<RasterParticle>() as u64;
        let split = Split::of(count as u64, particle_bytes.max(sh_bytes), ctx.max_binding);
        let particle = |p: &splat_core::Particle| {
            let c = p.covariance();
            RasterParticle {
                mean: p.mean.to_array(),
                opacity: p.opacity,
                cov_a: [c.x_axis.x, c.y_axis.x, c.z_axis.x],
                pad0: 0.0,
                cov_b: [c.y_axis.y, c.z_axis.y, c.z_axis.z],
                pad1: 0.0,
            }
        };
        let of = |range: std::ops::Range<u64>| &scene.particles[range.start as usize..range.end as usize];
        // `upload_parts` gives an empty scene one zeroed particle, as a binding needs.
        let particles = upload_parts(ctx, "raster particle", particle_bytes, split, count as u64, |range| {
            PartBytes(of(range).iter().map(particle).collect::<Vec<_>>())
        })?;
        let sh = upload_parts(ctx, "SH", sh_bytes, split, count as u64, |range| {
            PartBytes(crate::layout::sh_range(scene, sh_storage, range.start * per..range.end * per))
        })?;
        Ok(particles
            .into_iter()
            .zip(sh)
            .zip(split.ranges(count as u64))
            .map(|((particles, sh), range)| {
                let (first, n) = (range.start as u32, (range.end - range.start) as u32);
                let range = ctx.upload("project chunk", bytemuck::cast_slice(&[first, n]));
                ProjectChunk { particles, sh, range, count: n }
            })
            .collect())
    }
}

impl RasterScene {
    /// The chunks the projection runs in: particles and SH coefficients in as many bindings
    /// as they need, one dispatch each.
    pub fn chunks(&self) -> usize {
        self.chunks.len()
    }

    /// Validate and upload `scene`, unlit; refuse buffers above the adapter's binding limit.
    pub fn new(ctx: &GpuContext, scene: &Scene, settings: &RenderSettings) -> Result<Self, GpuError> {
        Self::new_lit(ctx, scene, settings, &Lighting::default())
    }

    /// Validate and upload `scene` lit by `lighting` (no shadows: the raster pipelines have
    /// none, vk_gaussian_splatting Lighting §3).
    pub fn new_lit(
        ctx: &GpuContext,
        scene: &Scene,
        settings: &RenderSettings,
        lighting: &Lighting,
    ) -> Result<Self, GpuError> {
        validate_scene(scene, settings)?;
        lighting.validate(scene.particles.len()).map_err(RenderError::Settings)?;
        let count = scene.particles.len();
        let split = RasterSplit::new(ctx, count, settings.sh_storage)?;
        // Rows of M = S⁻¹ Rᵀ with the mean in w, three per particle, for the normals: made a part
        // at a time as they are uploaded.
        let rows = |range: std::ops::Range<u64>| {
            let row = |r: u64| {
                let p = &scene.particles[(r / 3) as usize];
                let (i, m) = ((r % 3) as usize, p.canonical_transform());
                let v = m.row(i);
                [v.x, v.y, v.z, p.mean[i]]
            };
            PartBytes(range.map(row).collect::<Vec<[f32; 4]>>())
        };
        let canonical = CANONICAL.upload_parts(ctx, split.canonical, 3 * count as u64, rows)?;
        Ok(Self {
            chunks: ProjectChunk::split(ctx, scene, settings.sh_storage)?,
            count: count as u32,
            sh_degree: u32::from(scene.sh_degree),
            screen_filter: scene.screen_filter,
            settings: *settings,
            materials: ctx.upload("raster materials", bytemuck::cast_slice(&crate::layout::materials(lighting))),
            lights: ctx.upload("raster lights", bytemuck::cast_slice(&crate::layout::lights(lighting))),
            canonical,
            split,
            lighting: lighting.clone(),
            mesh_nodes: ctx.upload("raster mesh nodes", bytemuck::cast_slice(&[crate::node::GpuNode::default()])),
            triangles: ctx.upload("raster triangles", bytemuck::cast_slice(&[crate::layout::GpuTriangle::default()])),
            mesh_materials: ctx
                .upload("raster mesh materials", bytemuck::cast_slice(&[crate::layout::GpuMeshMaterial::default()])),
            ordered_triangles: ctx
                .upload("raster ordered triangles", bytemuck::cast_slice(&[crate::layout::GpuTriangle::default()])),
            transparent: Vec::new(),
            has_meshes: false,
        })
    }

    /// The same scene among `meshes` (vk_gaussian_splatting Lighting §1.5.3 and §3): a mesh
    /// pre-pass per camera finds each pixel's nearest mesh and forward-shades it, the splats are
    /// depth tested against it and it is blended under them with their transmittance, as the
    /// CPU reference `splat_core::raster::Rasterizer::with_meshes` does, at one sample per pixel.
    pub fn with_meshes(mut self, ctx: &GpuContext, meshes: &Meshes) -> Result<Self, GpuError> {
        if meshes.is_empty() {
            return Ok(self);
        }
        let nodes = crate::node::bvh_nodes(meshes.bvh(), 0);
        let triangles = crate::layout::triangles(meshes);
        let count = meshes.triangles().len();
        ctx.check_binding("mesh BVH node", (nodes.len() * size_of::<crate::node::GpuNode>()) as u64, count)?;
        ctx.check_binding("triangle", (triangles.len() * size_of::<crate::layout::GpuTriangle>()) as u64, count)?;
        self.mesh_nodes = ctx.upload("raster mesh nodes", bytemuck::cast_slice(&nodes));
        self.triangles = ctx.upload("raster triangles", bytemuck::cast_slice(&triangles));
        self.mesh_materials =
            ctx.upload("raster mesh materials", bytemuck::cast_slice(&crate::layout::mesh_materials(meshes)));
        self.ordered_triangles =
            ctx.upload("raster ordered triangles", bytemuck::cast_slice(&crate::layout::triangles_in_order(meshes)));
        self.transparent = meshes
            .triangles()
            .iter()
            .filter(|t| t.is_transparent())
            .map(|t| (t.order, [t.p0, t.p0 + t.e1, t.p0 + t.e2]))
            .collect();
        self.transparent.sort_unstable_by_key(|&(order, _)| order);
        self.has_meshes = true;
        Ok(self)
    }

    /// Bytes of its particle arrays on the device: particles, SH and canonical transforms (the
    /// projected splats and sort buffers are each camera's, [`GpuRasterizer::camera_bytes`]).
    pub fn scene_bytes(&self) -> u64 {
        let chunks = self.chunks.iter().map(|c| c.particles.size() + c.sh.size());
        chunks.chain(self.canonical.iter().map(wgpu::Buffer::size)).sum()
    }

    /// How its projected splats and canonical transforms are split over bindings.
    pub fn split(&self) -> RasterSplit {
        self.split
    }

    /// Whether the scene has meshes.
    pub fn has_meshes(&self) -> bool {
        self.has_meshes
    }

    /// Whether lighting is on.
    pub fn is_lit(&self) -> bool {
        self.lighting.is_on()
    }
}

/// The uniforms of a camera.
pub(super) fn raster_params(scene: &RasterScene, camera: &Camera, raster: &RasterSettings) -> RasterParams {
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
        iso_threshold: s.raster_iso_threshold,
        guard: [
            FRUSTUM_GUARD * camera.cx.max(w - camera.cx) / camera.fx,
            FRUSTUM_GUARD * camera.cy.max(h - camera.cy) / camera.fy,
        ],
        tiles: [camera.width.div_ceil(TILE), camera.height.div_ceil(TILE)],
        mode: 0,
        extent: raster.extent as u32,
        lit: u32::from(scene.lighting.is_on()),
        look: match scene.lighting.look {
            Look::Surface => crate::layout::LOOK_SURFACE,
            Look::Volumetric => crate::layout::LOOK_VOLUMETRIC,
        },
        light_count: scene.lighting.lights.len() as u32,
        set_count: scene.lighting.sets.len() as u32,
        t_min: s.t_min,
        t_max: s.t_max,
        meshes: u32::from(scene.has_meshes),
        first_hit: 0,
        samples: raster.samples,
        hilbert_order: splat_core::rng::hilbert_order(camera.width, camera.height),
        filter_variance: scene.screen_filter.variance(),
        filter_compensates: u32::from(scene.screen_filter.compensates()),
        lens: crate::layout::lens_code(&camera.lens),
        near: s.near,
        distortion: crate::layout::distortion(&camera.lens),
        normal_mode: crate::layout::normal_code(s.normal_mode),
        cutoff: s.kernel.cutoff,
        frame_key: 0,
        u_shift: 0.0,
    }
}
