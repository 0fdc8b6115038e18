//! Tile lists of the compute tile passes (the depth pick's `tile_blend`, the raster operations'
//! `tile_rop`): the splats of an order (rank → particle) binned into 16 × 16 tiles as (tile,
//! rank) pairs, sorted by tile with the stable radix sort, so that each tile's list keeps the
//! order, and each tile's range of pairs.

use super::*;

/// The bind groups and buffers of one binning: splats in `order`, per-rank pair counts and
/// their scan in `offsets.hist`, the pairs, and each tile's range.
pub(super) struct TileLists {
    /// (tile, rank) pairs; after the sort, `pairs.vals` is every tile's list of ranks.
    pub(super) pairs: SortBuffers,
    pub(super) pair_count: u32,
    /// Per tile, the range [x, y) of its pairs.
    pub(super) ranges: wgpu::Buffer,
    /// The kernels of the scene's split with the pairs' ([`RasterSplit::with_pairs`]): those
    /// that read the pairs (emit, ranges, and the tile passes after them).
    pub(super) k: std::sync::Arc<SplatKernels>,
    count_group: BindGroups,
    emit_group: BindGroups,
    ranges_group: BindGroups,
}

impl TileLists {
    /// Bind the binning of the splats in `order` (the values of `offsets`), counting into
    /// `offsets.hist` (room for count + 1 entries), with room for `pair_count` pairs
    /// ([`GpuRasterizer::pair_count`]: the same in every order).
    pub(super) fn new(r: &GpuRasterizer, offsets: &SortBuffers, pair_count: u32) -> Result<Self, GpuError> {
        let (ctx, pipes) = (r.ctx, r.pipes);
        let pairs = pipes.sort.buffers(ctx, pair_count.max(1))?;
        let split = r.scene.split.with_pairs(ctx, &pairs)?;
        let k = pipes.kernels(ctx, split)?;
        let [tiles_x, tiles_y] = r.params.tiles;
        let ranges = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tile ranges"),
            size: u64::from(tiles_x * tiles_y) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let (params, draw_args) = (&r.params_buffer, &r.draw_args);
        let count_group = r.count_group(offsets);
        let parts = [
            split.bind(&ORDER, &offsets.vals),
            split.bind(&OFFSETS, &offsets.hist),
            split.bind(&PAIR_TILES, &pairs.keys),
            split.bind(&PAIR_RANKS, &pairs.vals),
            r.split_parts(false, false),
        ]
        .concat();
        let emit_group = bind(ctx, &k.tile_emit, &[(0, params), (6, draw_args)], &parts);
        let parts = [split.bind(&OFFSETS, &offsets.hist), split.bind(&PAIR_TILES, &pairs.keys)].concat();
        let ranges_group = bind(ctx, &k.tile_ranges, &[(0, params), (10, &ranges)], &parts);
        Ok(Self { pairs, pair_count, ranges, k, count_group, emit_group, ranges_group })
    }

    /// Count each rank's pairs and scan them into `offsets.hist` (the buffers [`TileLists::new`]
    /// bound): needed again whenever the order changes.
    pub(super) fn encode_count(&self, r: &GpuRasterizer, encoder: &mut wgpu::CommandEncoder, offsets: &SortBuffers) {
        r.encode_count(encoder, &self.count_group, offsets);
    }

    /// Emit the pairs at the counted offsets, sort them by tile and find each tile's range.
    pub(super) fn encode_lists(&self, r: &GpuRasterizer, encoder: &mut wgpu::CommandEncoder) -> Result<(), GpuError> {
        let (ctx, pipes, k, n) = (r.ctx, r.pipes, &self.k, r.scene.count);
        encoder.clear_buffer(&self.ranges, 0, None);
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile emit"), timestamp_writes: None });
            pass.set_pipeline(&k.tile_emit);
            self.emit_group.set_compute(&mut pass, &[]);
            let (gx, gy) = groups(n.div_ceil(256));
            ctx.dispatch(&mut pass, gx, gy, 1);
        }
        let [tiles_x, tiles_y] = r.params.tiles;
        let tile_bits = u32::BITS - (tiles_x * tiles_y - 1).leading_zeros();
        pipes.sort.encode(ctx, encoder, &self.pairs, self.pair_count, tile_bits, None)?;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile ranges"), timestamp_writes: None });
        pass.set_pipeline(&k.tile_ranges);
        self.ranges_group.set_compute(&mut pass, &[]);
        let (gx, gy) = groups(self.pair_count.div_ceil(256));
        ctx.dispatch(&mut pass, gx, gy, 1);
        Ok(())
    }
}

impl GpuRasterizer<'_> {
    /// The group of `tile_count` over the splats in the order `offsets.vals`, counting into
    /// `offsets.hist`.
    fn count_group(&self, offsets: &SortBuffers) -> BindGroups {
        let split = &self.scene.split;
        let own = [(0, &self.params_buffer), (6, &self.draw_args)];
        let parts =
            [split.bind(&ORDER, &offsets.vals), split.bind(&OFFSETS, &offsets.hist), self.split_parts(false, false)];
        bind(self.ctx, &self.k.tile_count, &own, &parts.concat())
    }

    /// Per rank the tiles its rect touches (`tile_count`), and their exclusive scan in
    /// `offsets.hist` (its entry `count` is the total).
    fn encode_count(&self, encoder: &mut wgpu::CommandEncoder, group: &BindGroups, offsets: &SortBuffers) {
        let n = self.scene.count;
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile count"), timestamp_writes: None });
            pass.set_pipeline(&self.k.tile_count);
            group.set_compute(&mut pass, &[]);
            let (gx, gy) = groups((n + 1).div_ceil(256));
            self.ctx.dispatch(&mut pass, gx, gy, 1);
        }
        self.pipes.sort.encode_scan(self.ctx, encoder, offsets, n + 1);
    }

    /// How many (tile, splat) pairs the visible splats make: counted and scanned in depth order
    /// into the depth sort's histogram (which then holds each rank's offset in that order); the
    /// total is the same in any draw order.
    pub(super) fn pair_count(&self) -> Result<u32, GpuError> {
        let mut encoder = self.encoder("tile count");
        self.encode_count(&mut encoder, &self.count_group(&self.depth), &self.depth);
        self.submit(encoder)?;
        let total = u64::from(self.scene.count);
        Ok(self.depth.read(self.ctx, &self.depth.hist, total..total + 1)?[0])
    }
}
