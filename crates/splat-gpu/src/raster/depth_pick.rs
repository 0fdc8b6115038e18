//! Iso-opacity depth and picked splat of every pixel: the compute tile rasterizer.

use super::*;
use crate::layout::{
    FIRST_HIT_ACCEPTED, FIRST_HIT_COUNT, FIRST_HIT_FRAGMENTS, FIRST_HIT_SORTED, GpuFirstHit, GpuFragment,
};

/// Iso-opacity depth and picked splat of every pixel, with the front-to-back colour they come
/// from (the GPU twin of sorted splatting with [`Blend::Under`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthPick {
    /// Front-to-back colour over the background (RGB).
    pub color: Image,
    /// Coverage 1 − T.
    pub alpha: Image,
    /// Integrated unit normal (max-density plane), zero where no fragment.
    pub normal: Image,
    /// Iso-opacity depth: distance along the pixel-centre ray, `None` where T never fell
    /// below the threshold.
    pub depth: Vec<Option<f32>>,
    /// Scene index of the splat that set the depth.
    pub picked: Vec<Option<u32>>,
    /// (tile, splat) pairs the tile lists held.
    pub pairs: u32,
}

impl DepthPick {
    /// The depth as an image, NaN where there is none (the form of [`RenderOutput::depth`]).
    pub fn depth_image(&self) -> Image {
        let (w, h) = (self.color.width(), self.color.height());
        let data = self.depth.iter().map(|d| d.unwrap_or(f32::NAN)).collect();
        Image::from_data(w, h, 1, data).expect("one depth per pixel")
    }
}

/// The hybrid pipeline's first hits as the rasterizer gives them to the ray tracer.
#[derive(Clone, Debug, Default)]
pub struct FirstHits {
    /// S a pixel, sample i of pixel p at p S + i.
    pub hits: Vec<GpuFirstHit>,
    /// The volumetric look's fragments (`FIRST_HIT_FRAGMENTS`), each hit's
    /// `fragments` range of them; empty otherwise.
    pub fragments: Vec<GpuFragment>,
    /// The ray tracer's `Params::first_hit`: which first hit these are (`FIRST_HIT_*`).
    pub kind: u32,
}

/// [`HitBuffers`] read back: per entry RGBA colour, (depth bits, pick) and normal.
pub(super) struct Hits {
    color: Vec<f32>,
    pick: Vec<u32>,
    normal: Vec<f32>,
}

impl Hits {
    /// The first hits of a first-hit pass (colour with T in w), sample i of pixel p at p S + i,
    /// at the sub-pixel positions `offsets` (S).
    pub(super) fn first_hits(&self, offsets: &[glam::Vec2]) -> Vec<GpuFirstHit> {
        let Self { color, pick, normal } = self;
        (0..pick.len() / 2)
            .map(|i| GpuFirstHit {
                radiance: [color[4 * i], color[4 * i + 1], color[4 * i + 2]],
                transmittance: color[4 * i + 3],
                normal: [normal[4 * i], normal[4 * i + 1], normal[4 * i + 2]],
                depth: f32::from_bits(pick[2 * i]),
                picked: pick[2 * i + 1],
                offset: offsets[i % offsets.len()].to_array(),
                ..GpuFirstHit::default()
            })
            .collect()
    }
}

/// The buffers a tile pass or `rop_first_hit` writes, `entries` of each (a pixel's, or a
/// first-hit pass's sample's): RGBA colour (T in w for a first hit), (depth bits, pick) and
/// normal (bindings 11, 12 and 16 of the raster kernels).
pub(super) struct HitBuffers {
    pub(super) color: wgpu::Buffer,
    pub(super) pick: wgpu::Buffer,
    pub(super) normal: wgpu::Buffer,
    entries: usize,
}

impl HitBuffers {
    pub(super) fn new(ctx: &GpuContext, entries: usize) -> Self {
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let (rgba, pair) = (entries as u64 * 16, entries as u64 * 8);
        Self {
            color: ctx.buffer("hit colour", rgba, rw),
            pick: ctx.buffer("hit pick", pair, rw),
            normal: ctx.buffer("hit normal", rgba, rw),
            entries,
        }
    }

    /// Colour, (depth bits, pick) and normal, read back.
    pub(super) fn read(&self, ctx: &GpuContext) -> Result<Hits, GpuError> {
        let n = self.entries;
        Ok(Hits {
            color: ctx.read_f32(&self.color, n * 4)?,
            pick: ctx.read_u32(&self.pick, n * 2)?,
            normal: ctx.read_f32(&self.normal, n * 4)?,
        })
    }
}

/// What one tile pass reads back: per pixel (per sample for a first-hit pass) its [`Hits`], and
/// the (tile, splat) pair count.
struct TilePass {
    hits: Hits,
    pairs: u32,
}

impl GpuRasterizer<'_> {
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
    ///
    /// At S samples per pixel each sample is composited (the fragment's alpha at the pixel
    /// centre, its coverage and depth at the sample) and the colour is their mean; the depth,
    /// normal and pick are sample 0's, as the CPU reference takes them.
    pub fn depth_pick(&self) -> Result<DepthPick, GpuError> {
        Self::supports_depth_pick(&self.raster)?;
        self.check_opaque_meshes("the GPU's iso-opacity depth pick")?;
        let TilePass { hits: Hits { color, pick, normal }, pairs } =
            self.tile_pass(RasterParams { mode: Draw::Under.mode(), ..self.params }, None)?;
        let image = |channels, f: &dyn Fn(usize) -> f32| crate::context::rgba_image(&self.camera, channels, f);
        let picked: Vec<Option<u32>> = pick.chunks(2).map(|p| (p[1] != NONE).then_some(p[1])).collect();
        Ok(DepthPick {
            color: image(3, &|i| color[i]),
            alpha: image(1, &|i| color[i + 3]),
            normal: image(3, &|i| normal[i]),
            // Negative where neither a splat nor a mesh set the depth.
            depth: pick.chunks(2).map(|p| Some(f32::from_bits(p[0])).filter(|&d| d >= 0.0)).collect(),
            picked,
            pairs,
        })
    }

    /// The hybrid pipeline's first hit of every sample of every pixel (vk_gaussian_splatting
    /// Lighting §5; S a pixel, sample i of pixel p at p S + i, with its sub-pixel position), by
    /// the same tile pass, for the first-hit `method`:
    ///
    /// - sorted splatting: each sample's radiance and transmittance in front of its mesh, and
    ///   in sample 0 the integrated normal, the picked depth and splat, and in the surface look
    ///   the mean radiance of the samples, before lighting (the tracer lights it once, as
    ///   `Rasterizer::light_surface` does); in the volumetric look, each sample's fragments
    ///   with their weights Tᵢ αᵢ instead of its radiance, which the tracer lights one by one
    ///   with its shadow rays, as `Rasterizer::hybrid` lights every fragment;
    /// - StochasticSplats (the stochastic transparency page's hybrid case): each sample's
    ///   closest fragment accepted in frame `frame_key` (u < α with the sample's own u, every u
    ///   drawn as u − `u_shift`, as [`splat_core::Frames::u_shift`]), written opaque: its unlit
    ///   colour, T = 0, its normal, depth and id; T = 1 where none is accepted;
    /// - Enderton and stratified: the splat their raster operations write to each sample in
    ///   that frame, the same way.
    ///
    /// The ray tracer then lights the picks with shadows and continues from each sample's ray
    /// at its mesh ([`crate::GpuTracer::render_hybrid`]).
    pub fn first_hits(&self, method: &RasterMethod, frame_key: u32, u_shift: f32) -> Result<FirstHits, GpuError> {
        Self::supports_first_hits(&self.raster)?;
        self.check_opaque_meshes("the GPU hybrid's rasterized first hit")?;
        let volumetric = self.params.lit == 1 && self.params.look == crate::layout::LOOK_VOLUMETRIC;
        let first_hit = match method {
            RasterMethod::Sorted { .. } if volumetric => return self.fragment_first_hits(),
            RasterMethod::Sorted { .. } => FIRST_HIT_SORTED,
            RasterMethod::StochasticSplat => FIRST_HIT_ACCEPTED,
            RasterMethod::Enderton | RasterMethod::Stratified { .. } => {
                let hits = self.rop_first_hits(method, frame_key, u_shift)?;
                return Ok(FirstHits { hits, fragments: Vec::new(), kind: FIRST_HIT_ACCEPTED });
            }
        };
        let params = RasterParams { mode: Draw::Under.mode(), first_hit, frame_key, u_shift, ..self.params };
        let hits = self.tile_pass(params, None)?.hits.first_hits(&self.offsets());
        Ok(FirstHits { hits, fragments: Vec::new(), kind: first_hit })
    }

    /// Sorted splatting's first hits in the volumetric look: one tile pass counts each sample's
    /// fragments in front of its mesh, their starts are the counts' running sum, and a second
    /// pass writes them (splat colour, weight Tᵢ αᵢ, normal, distance, id) beside the hits.
    fn fragment_first_hits(&self) -> Result<FirstHits, GpuError> {
        let counted =
            self.tile_pass(RasterParams { mode: Draw::Under.mode(), first_hit: FIRST_HIT_COUNT, ..self.params }, None)?;
        let counts: Vec<u32> = counted.hits.pick.chunks(2).map(|p| p[0]).collect();
        let mut start = Vec::with_capacity(counts.len());
        let mut total = 0u64;
        for &c in &counts {
            start.push(total as u32);
            total += u64::from(c);
        }
        let bytes = total.max(1) * size_of::<GpuFragment>() as u64;
        if bytes > self.ctx.max_binding || total > u64::from(u32::MAX) {
            let reason = format!(
                "the volumetric look's first hits hold {total} fragments ({bytes} bytes) for the ray tracer to light, but the adapter binds at most {} bytes per storage buffer (a smaller image or fewer samples would fit)",
                self.ctx.max_binding
            );
            return Err(GpuError::refused(reason, &[Remedy::Cpu]));
        }
        let starts = self.ctx.upload("fragment starts", bytemuck::cast_slice(&start));
        let rw = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let fragments = self.ctx.buffer("fragments", bytes, rw);
        let params = RasterParams { mode: Draw::Under.mode(), first_hit: FIRST_HIT_FRAGMENTS, ..self.params };
        let mut hits = self.tile_pass(params, Some((&starts, &fragments)))?.hits.first_hits(&self.offsets());
        for ((hit, &s), &c) in hits.iter_mut().zip(&start).zip(&counts) {
            hit.fragments = [s, c];
        }
        let words = (total as usize) * size_of::<GpuFragment>() / 4;
        let fragments =
            if total == 0 { Vec::new() } else { bytemuck::cast_slice(&self.ctx.read_u32(&fragments, words)?).to_vec() };
        Ok(FirstHits { hits, fragments, kind: FIRST_HIT_FRAGMENTS })
    }

    /// One tile pass under `params`: per pixel (per sample for a first-hit pass) RGBA colour,
    /// (depth bits, pick) and normal, and the pair count; `fragments` (their starts and the
    /// list) for a [`FIRST_HIT_FRAGMENTS`] pass.
    fn tile_pass(
        &self,
        params: RasterParams,
        fragments: Option<(&wgpu::Buffer, &wgpu::Buffer)>,
    ) -> Result<TilePass, GpuError> {
        self.ctx.queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        let ctx = self.ctx;
        let [tiles_x, tiles_y] = self.params.tiles;
        // 1. Pairs per rank and their exclusive scan in depth order (offsets[n] is the total).
        let pairs = self.pair_count()?;
        // 2. Emit the pairs, sort them by tile, find each tile's range, composite.
        let lists = TileLists::new(self, &self.depth, pairs)?;
        let per_pixel = if params.first_hit != 0 { self.raster.samples } else { 1 };
        let out = HitBuffers::new(ctx, (self.camera.width * self.camera.height * per_pixel) as usize);
        let storage = wgpu::BufferUsages::STORAGE;
        let none = (
            ctx.buffer("no fragment starts", 4, storage),
            ctx.buffer("no fragments", size_of::<GpuFragment>() as u64, storage),
        );
        let (starts, list) = fragments.unwrap_or((&none.0, &none.1));
        let own = [
            (0, &self.params_buffer),
            (10, &lists.ranges),
            (11, &out.color),
            (12, &out.pick),
            (13, &self.scene.materials),
            (14, &self.scene.lights),
            (16, &out.normal),
            (17, &self.behind),
            (18, &self.behind_normal),
            (20, &self.sample_offsets),
            (24, starts),
            (25, list),
        ];
        let split = &lists.k.split;
        let lists_parts = [split.bind(&ORDER, &self.depth.vals), split.bind(&PAIR_RANKS, &lists.pairs.vals)].concat();
        let parts = [self.split_parts(false, true), lists_parts].concat();
        let blend_group = bind(ctx, &lists.k.tile_blend, &own, &parts);
        let mut encoder = self.encoder("tile lists");
        lists.encode_lists(self, &mut encoder)?;
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile blend"), timestamp_writes: None });
            pass.set_pipeline(&lists.k.tile_blend);
            blend_group.set_compute(&mut pass, &[]);
            ctx.dispatch(&mut pass, tiles_x, tiles_y, 1);
        }
        self.submit(encoder)?;
        Ok(TilePass { hits: out.read(ctx)?, pairs })
    }
}
