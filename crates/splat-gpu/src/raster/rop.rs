//! Enderton and Laine–Karras on the GPU: the compute tile pass plays each pixel's raster
//! operations in the frame's draw order (`shaders/rop.wgsl` `tile_rop`, whose comment says
//! why not a fragment shader).
//!
//! Per frame: the draw order of the CPU reference's [`splat_core::raster::Rasterizer::shuffle`]
//! (every particle keyed by a hash of its id and the frame, radix sorted), the tile lists
//! binned in that order (the depth pick's binning with the shuffled order), and `tile_rop`,
//! which writes the frame's resolved colour to the target the fold reads.
//!
//! Transparent mesh triangles are fragments too (the CPU's `Rasterizer::triangle_fragments`),
//! drawn before the splats in the meshes' order: each camera bins them into per-tile lists on
//! the host ([`TriangleLists`]), and `tile_rop` walks a tile's triangle list before its splat
//! list, testing each sample's ray against each triangle as the CPU's ray cast does.
//!
//! lavapipe stops an invocation's loops after [`crate::LOOP_BUDGET`] iterations in all (every
//! loop of the inlined shader counts, for the SIMD group as a whole), silently: a tile of the
//! bonsai at 300 × 200 holds tens of thousands of splats. On a CPU adapter the lists are
//! therefore walked in chunks, one dispatch each, that stay below the budget, the pixels' state
//! kept in a buffer between them; other adapters take each list in one chunk.

use super::*;

/// The buffers and bind groups of the raster-operations frames of one render.
pub(super) struct RopPass {
    shuffle: SortBuffers,
    /// The tile lists in the shuffled order.
    lists: TileLists,
    frame: wgpu::Buffer,
    keys_group: BindGroups,
    rop_group: BindGroups,
    /// The current chunk (index, length, count), and every chunk's, copied in before its dispatch.
    chunk: wgpu::Buffer,
    chunks: wgpu::Buffer,
    chunk_count: u32,
    /// Each pixel's state between chunks (2 S + 2 words), kept whole for the hybrid's first hit.
    state: wgpu::Buffer,
}

/// Each tile's transparent triangles for one camera (rop.wgsl `rop_triangle_lists`): words 2 t
/// and 2 t + 1 bound tile t's list of entries, which follow the 2 × tiles header words, three
/// words each: the triangle's place in the meshes' order (ascending: the draw order) and the
/// pixels it may reach, x0 | x1 << 16 and y0 | y1 << 16 (inclusive), so that a pixel outside
/// skips it without casting its sample rays.
pub(super) struct TriangleLists {
    buffer: wgpu::Buffer,
    /// The most triangles any tile's list holds.
    longest: u32,
}

/// Words of one entry of a triangle list.
const ENTRY_WORDS: usize = 3;

impl TriangleLists {
    /// Bin the scene's transparent triangles into the tiles of the rasterizer's camera.
    fn new(r: &GpuRasterizer) -> Result<Self, GpuError> {
        if r.camera.width > 0xffff || r.camera.height > 0xffff {
            return Err(GpuError::refused(
                "transparent triangles on the GPU need images of at most 65,535 pixels a side",
                &[Remedy::Cpu],
            ));
        }
        let lists = Self::bin(r);
        let tiles = lists.len();
        let total: usize = lists.iter().map(Vec::len).sum();
        let count = r.scene.transparent.len();
        r.ctx.check_binding("transparent triangle list", 4 * (2 * tiles + ENTRY_WORDS * total) as u64, count)?;
        let mut words = vec![0u32; 2 * tiles];
        let mut entries = 0u32;
        for (t, list) in lists.iter().enumerate() {
            words[2 * t] = entries;
            for &(order, [x0, y0, x1, y1]) in list {
                words.extend([order, x0 | x1 << 16, y0 | y1 << 16]);
            }
            entries += list.len() as u32;
            words[2 * t + 1] = entries;
        }
        let longest = lists.iter().map(Vec::len).max().unwrap_or(0) as u32;
        Ok(Self { buffer: r.ctx.upload("transparent triangle lists", bytemuck::cast_slice(&words)), longest })
    }

    /// Each tile's list: the place and pixel rect of each transparent triangle whose
    /// [`pixel_span`] reaches the tile.
    fn bin(r: &GpuRasterizer) -> Vec<Vec<(u32, [u32; 4])>> {
        let [tiles_x, tiles_y] = r.params.tiles;
        let mut lists = vec![Vec::new(); (tiles_x * tiles_y) as usize];
        for (order, vertices) in &r.scene.transparent {
            let Some(rect) = pixel_span(&r.camera, vertices) else { continue };
            let [x0, y0, x1, y1] = rect.map(|v| v / TILE);
            for ty in y0..=y1 {
                for tx in x0..=x1 {
                    lists[(ty * tiles_x + tx) as usize].push((*order, rect));
                }
            }
        }
        lists
    }
}

/// The pixels (x0, y0, x1, y1, inclusive) whose sample rays may cross the triangle of
/// `vertices`, `None` where none can. Through a pinhole, a point the rays reach projects to the
/// sample position of its ray, so the crossing points of a triangle in front of the camera lie
/// within its projected vertices' bounding box (grown by a pixel, for the edge slack); a
/// triangle partly behind the camera, or any triangle through another lens (whose image of a
/// straight edge bends), may reach every pixel.
fn pixel_span(camera: &Camera, vertices: &[glam::Vec3; 3]) -> Option<[u32; 4]> {
    let every = Some([0, 0, camera.width - 1, camera.height - 1]);
    let local = vertices.map(|v| camera.to_camera(v));
    if camera.is_pinhole() && local.iter().all(|p| p.z <= 0.0) {
        return None;
    }
    if !camera.is_pinhole() || !local.iter().all(|p| p.z > 0.0) {
        return every;
    }
    let [a, b, c] = local.map(|p| camera.project_camera(p));
    let (lo, hi) = (a.min(b).min(c) - 1.0, a.max(b).max(c) + 1.0);
    if !(lo.is_finite() && hi.is_finite()) {
        return every;
    }
    let (w, h) = (camera.width as f32, camera.height as f32);
    if hi.x < 0.0 || hi.y < 0.0 || lo.x >= w || lo.y >= h {
        return None;
    }
    let pixel = |v: f32, size: f32| v.clamp(0.0, size - 1.0) as u32;
    Some([pixel(lo.x, w), pixel(lo.y, h), pixel(hi.x, w), pixel(hi.y, h)])
}

/// Most loop iterations one fragment of the raster operations can cost at S samples (its
/// iteration of the list, the coverage loop, Enderton's writes or stratified's insertion sort
/// and tests), bounding the fragments a chunk may hold.
fn iterations_per_fragment(samples: u32) -> u32 {
    2 + samples + samples * (samples - 1) / 2 + 2 * samples
}

/// Most loop iterations one transparent triangle can cost: a fragment's, and the ray cast of
/// each sample.
fn triangle_iterations(samples: u32) -> u32 {
    iterations_per_fragment(samples) + samples
}

impl RopPass {
    /// Allocate the shuffled order, the pair lists (as many pairs as the depth order makes) and
    /// the groups binding them, `targets.color_view` as the frame's target; with `keep_state`
    /// every pixel's final state too (the hybrid's first hit reads it).
    pub(super) fn new(r: &GpuRasterizer, targets: &RasterTargets, keep_state: bool) -> Result<Self, GpuError> {
        let (ctx, pipes, n) = (r.ctx, r.pipes, r.scene.count);
        let pair_count = r.pair_count()?;
        let triangles = TriangleLists::new(r)?;
        let (chunk_len, splat_chunks) = r.raster_operation_chunks()?;
        let (triangle_len, triangle_chunks) = r.chunks(triangles.longest, triangle_iterations(r.raster.samples));
        let chunk_count = triangle_chunks + splat_chunks;
        let table: Vec<[u32; 4]> = (0..chunk_count)
            .map(|c| [c, if c < triangle_chunks { triangle_len } else { chunk_len }, chunk_count, triangle_chunks])
            .collect();
        let chunks = ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rop chunks"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::COPY_SRC,
        });
        let chunk = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rop chunk"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pixels = u64::from(r.camera.width * r.camera.height);
        let words = if chunk_count > 1 || keep_state { pixels * u64::from(2 * r.raster.samples + 2) } else { 1 };
        let state = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rop state"),
            size: words * 4,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let shuffle = pipes.sort.buffers(ctx, n + 1)?;
        let lists = TileLists::new(r, &shuffle, pair_count)?;
        let frame = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rop frame"),
            size: size_of::<FrameParams>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let split = &lists.k.split;
        let shuffled = [split.bind(&DEPTH_KEYS, &shuffle.keys), split.bind(&ORDER, &shuffle.vals)].concat();
        let own = [(0, &r.params_buffer), (19, &frame)];
        let keys_group = bind(ctx, &r.k.shuffle_keys, &own, &[shuffled, r.split_parts(false, false)].concat());
        let rop = r.rop_pipeline(&lists.k);
        let parts =
            [r.split_parts(false, true), split.bind(&ORDER, &shuffle.vals), split.bind(&PAIR_RANKS, &lists.pairs.vals)]
                .concat();
        let rop_group = BindGroups::auto(
            &ctx.device,
            Some("tile rop"),
            rop,
            &[
                wgpu::BindGroupEntry { binding: 0, resource: r.params_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 10, resource: lists.ranges.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 13, resource: r.scene.materials.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 14, resource: r.scene.lights.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 17, resource: r.behind.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 19, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 20, resource: r.sample_offsets.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 21, resource: wgpu::BindingResource::TextureView(&targets.color_view) },
                wgpu::BindGroupEntry { binding: 22, resource: state.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 23, resource: chunk.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 26, resource: r.scene.ordered_triangles.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 27, resource: r.scene.mesh_materials.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 28, resource: triangles.buffer.as_entire_binding() },
            ],
            &parts,
        );
        Ok(Self { shuffle, lists, frame, keys_group, rop_group, chunk, chunks, chunk_count, state })
    }

    /// Encode frame `slot` of `slots`: its parameters into place, the shuffled order, the tile
    /// lists in that order, and the raster operations of every pixel.
    pub(super) fn encode(
        &self,
        r: &GpuRasterizer,
        encoder: &mut wgpu::CommandEncoder,
        slots: &FrameSlots,
        slot: u32,
    ) -> Result<(), GpuError> {
        let (ctx, pipes, n) = (r.ctx, r.pipes, r.scene.count);
        let frame_bytes = size_of::<FrameParams>() as u64;
        encoder.copy_buffer_to_buffer(&slots.buffer, u64::from(slots.offset(slot)), &self.frame, 0, frame_bytes);
        let (gx, gy) = groups(n.div_ceil(256));
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("shuffle"), timestamp_writes: None });
            pass.set_pipeline(&r.k.shuffle_keys);
            self.keys_group.set_compute(&mut pass, &[]);
            ctx.dispatch(&mut pass, gx, gy, 1);
        }
        let pairs = Culled { buffers: &self.shuffle, n, kept: &r.draw_args };
        pipes.sort.encode_culled(ctx, encoder, pairs, None)?;
        self.lists.encode_count(r, encoder, &self.shuffle);
        self.lists.encode_lists(r, encoder)?;
        let [tiles_x, tiles_y] = r.params.tiles;
        for c in 0..self.chunk_count {
            encoder.copy_buffer_to_buffer(&self.chunks, u64::from(c) * 16, &self.chunk, 0, 16);
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile rop"), timestamp_writes: None });
            pass.set_pipeline(r.rop_pipeline(&self.lists.k));
            self.rop_group.set_compute(&mut pass, &[]);
            ctx.dispatch(&mut pass, tiles_x, tiles_y, 1);
        }
        Ok(())
    }
}

impl GpuRasterizer<'_> {
    /// The hybrid's first hit of every sample from Enderton's or stratified raster operations,
    /// in the frame of key `frame_key` (decisions shifted by `u_shift`): one ROP frame that keeps
    /// its state, then `rop_first_hit` (rop.wgsl) turns each written sample into the tile pass's
    /// first-hit buffers.
    pub(super) fn rop_first_hits(
        &self,
        method: &RasterMethod,
        frame_key: u32,
        u_shift: f32,
    ) -> Result<Vec<crate::layout::GpuFirstHit>, GpuError> {
        let draw = self.check_scene(method)?;
        let params = RasterParams { mode: draw.mode(), first_hit: crate::layout::FIRST_HIT_ACCEPTED, ..self.params };
        self.ctx.queue.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        let (ctx, (w, h)) = (self.ctx, (self.camera.width, self.camera.height));
        let targets = RasterTargets::new(ctx, self.pipes, w, h, draw, 1);
        let rop = RopPass::new(self, &targets, true)?;
        let slots = FrameSlots::new(ctx);
        slots.write(ctx, &[frame_key], 0, &Frames { u_shift, ..Frames::default() });
        let out = super::depth_pick::HitBuffers::new(ctx, (w * h * self.raster.samples) as usize);
        let own = [
            (0, &self.params_buffer),
            (11, &out.color),
            (12, &out.pick),
            (16, &out.normal),
            (20, &self.sample_offsets),
            (22, &rop.state),
        ];
        let group = bind(ctx, &self.k.rop_first_hit, &own, &self.split_parts(false, true));
        let mut encoder = self.encoder("rop first hits");
        rop.encode(self, &mut encoder, &slots, 0)?;
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("rop first hit"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.k.rop_first_hit);
            group.set_compute(&mut pass, &[]);
            ctx.dispatch(&mut pass, w.div_ceil(8), h.div_ceil(8), 1);
        }
        self.submit(encoder)?;
        Ok(out.read(ctx)?.first_hits(&self.offsets()))
    }

    /// The most splats any tile's list holds (the same in every draw order), counted from the
    /// projected rects.
    fn longest_tile_list(&self) -> Result<u32, GpuError> {
        let [tiles_x, tiles_y] = self.params.tiles;
        let mut lengths = vec![0u32; (tiles_x * tiles_y) as usize];
        for s in self.splats()? {
            let [x0, y0, x1, y1] = s.rect;
            if x0 >= x1 || y0 >= y1 {
                continue;
            }
            for ty in y0 / TILE..=(y1 - 1) / TILE {
                for tx in x0 / TILE..=(x1 - 1) / TILE {
                    lengths[(ty * tiles_x + tx) as usize] += 1;
                }
            }
        }
        Ok(lengths.into_iter().max().unwrap_or(0))
    }

    /// How Enderton and stratified walk each tile's list: (splats per chunk, chunks), one chunk
    /// on a hardware adapter, chunks within lavapipe's loop budget on a CPU adapter.
    pub fn raster_operation_chunks(&self) -> Result<(u32, u32), GpuError> {
        let longest = self.longest_tile_list()?.max(1);
        Ok(self.chunks(longest, iterations_per_fragment(self.raster.samples)))
    }

    /// How Enderton and stratified walk each tile's transparent triangles: (triangles per
    /// chunk, chunks), as [`GpuRasterizer::raster_operation_chunks`] walks the splats; (0, 0)
    /// without transparent triangles.
    pub fn triangle_operation_chunks(&self) -> (u32, u32) {
        let longest = TriangleLists::bin(self).iter().map(Vec::len).max().unwrap_or(0) as u32;
        self.chunks(longest, triangle_iterations(self.raster.samples))
    }

    /// (entries per chunk, chunks) of lists of at most `longest` entries that cost at most
    /// `per_entry` loop iterations each: one chunk on a hardware adapter (none for empty lists),
    /// chunks within lavapipe's loop budget on a CPU adapter.
    fn chunks(&self, longest: u32, per_entry: u32) -> (u32, u32) {
        if longest == 0 {
            return (0, 0);
        }
        let chunk_len = if self.ctx.info.device_type == wgpu::DeviceType::Cpu {
            // A margin of 5,000 iterations for the loops outside the list (setup, resolve).
            ((crate::LOOP_BUDGET - 5_000) / per_entry).min(longest)
        } else {
            longest
        };
        (chunk_len, longest.div_ceil(chunk_len))
    }

    /// The raster-operations kernel of this rasterizer's fragment depth.
    fn rop_pipeline<'k>(&self, k: &'k SplatKernels) -> &'k wgpu::ComputePipeline {
        &k.tile_rop[usize::from(self.raster.fragment_depth == FragmentDepth::MaxDensityPlane)]
    }
}
