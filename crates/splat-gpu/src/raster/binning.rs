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
    count_group: wgpu::BindGroup,
    emit_group: wgpu::BindGroup,
    ranges_group: wgpu::BindGroup,
}

impl TileLists {
    /// Bind the binning of the splats in `order`, counting into `offsets.hist` (room for
    /// count + 1 entries), with room for `pair_count` pairs ([`GpuRasterizer::pair_count`]: the
    /// same in every order).
    pub(super) fn new(
        r: &GpuRasterizer,
        order: &wgpu::Buffer,
        offsets: &SortBuffers,
        pair_count: u32,
    ) -> Result<Self, GpuError> {
        let (ctx, pipes, k) = (r.ctx, r.pipes, &r.k);
        let pairs = pipes.sort.buffers(ctx, pair_count.max(1))?;
        let [tiles_x, tiles_y] = r.params.tiles;
        let ranges = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("tile ranges"),
            size: u64::from(tiles_x * tiles_y) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let (params, draw_args) = (&r.params_buffer, &r.draw_args);
        let count_group = r.count_group(order, offsets);
        let own = [(0, params), (5, order), (6, draw_args), (7, &offsets.hist), (8, &pairs.keys), (9, &pairs.vals)];
        let emit_group = bind(ctx, &k.tile_emit, &[&own[..], &r.split_parts(false, false)].concat());
        let ranges_group =
            bind(ctx, &k.tile_ranges, &[(0, params), (7, &offsets.hist), (8, &pairs.keys), (10, &ranges)]);
        Ok(Self { pairs, pair_count, ranges, count_group, emit_group, ranges_group })
    }

    /// Count each rank's pairs and scan them into `offsets.hist` (the buffers [`TileLists::new`]
    /// bound): needed again whenever the order changes.
    pub(super) fn encode_count(&self, r: &GpuRasterizer, encoder: &mut wgpu::CommandEncoder, offsets: &SortBuffers) {
        r.encode_count(encoder, &self.count_group, offsets);
    }

    /// Emit the pairs at the counted offsets, sort them by tile and find each tile's range.
    pub(super) fn encode_lists(&self, r: &GpuRasterizer, encoder: &mut wgpu::CommandEncoder) -> Result<(), GpuError> {
        let (ctx, pipes, k, n) = (r.ctx, r.pipes, &r.k, r.scene.count);
        encoder.clear_buffer(&self.ranges, 0, None);
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile emit"), timestamp_writes: None });
            pass.set_pipeline(&k.tile_emit);
            pass.set_bind_group(0, &self.emit_group, &[]);
            let (gx, gy) = groups(n.div_ceil(256));
            ctx.dispatch(&mut pass, gx, gy, 1);
        }
        let [tiles_x, tiles_y] = r.params.tiles;
        let tile_bits = u32::BITS - (tiles_x * tiles_y - 1).leading_zeros();
        pipes.sort.encode(ctx, encoder, &self.pairs, self.pair_count, tile_bits, None)?;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile ranges"), timestamp_writes: None });
        pass.set_pipeline(&k.tile_ranges);
        pass.set_bind_group(0, &self.ranges_group, &[]);
        let (gx, gy) = groups(self.pair_count.div_ceil(256));
        ctx.dispatch(&mut pass, gx, gy, 1);
        Ok(())
    }
}

impl GpuRasterizer<'_> {
    /// The group of `tile_count` over the splats in `order`, counting into `offsets.hist`.
    fn count_group(&self, order: &wgpu::Buffer, offsets: &SortBuffers) -> wgpu::BindGroup {
        let own = [(0, &self.params_buffer), (5, order), (6, &self.draw_args), (7, &offsets.hist)];
        bind(self.ctx, &self.k.tile_count, &[&own[..], &self.split_parts(false, false)].concat())
    }

    /// Per rank the tiles its rect touches (`tile_count`), and their exclusive scan in
    /// `offsets.hist` (its entry `count` is the total).
    fn encode_count(&self, encoder: &mut wgpu::CommandEncoder, group: &wgpu::BindGroup, offsets: &SortBuffers) {
        let n = self.scene.count;
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile count"), timestamp_writes: None });
            pass.set_pipeline(&self.k.tile_count);
            pass.set_bind_group(0, group, &[]);
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
        self.encode_count(&mut encoder, &self.count_group(&self.depth.vals, &self.depth), &self.depth);
        self.submit(encoder)?;
        Ok(self.ctx.read_u32_at(&self.depth.hist, self.scene.count as usize, 1)?[0])
    }
}
