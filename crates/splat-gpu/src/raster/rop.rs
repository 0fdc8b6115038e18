//! Enderton and Laine–Karras on the GPU: the compute tile pass plays each pixel's raster
//! operations in the frame's draw order (`shaders/raster.wgsl` `tile_rop`, whose comment says
//! why not a fragment shader).
//!
//! Per frame: the draw order of the CPU reference's [`splat_core::raster::Rasterizer::shuffle`]
//! (every particle keyed by a hash of its id and the frame, radix sorted), the tile lists
//! binned in that order (the depth pick's binning with the shuffled order), and `tile_rop`,
//! which writes the frame's resolved colour to the target the fold reads.

use super::*;

/// The buffers and bind groups of the raster-operations frames of one render.
pub(super) struct RopPass {
    shuffle: SortBuffers,
    pairs: SortBuffers,
    pair_count: u32,
    ranges: wgpu::Buffer,
    frame: wgpu::Buffer,
    keys_group: wgpu::BindGroup,
    count_group: wgpu::BindGroup,
    emit_group: wgpu::BindGroup,
    ranges_group: wgpu::BindGroup,
    rop_group: wgpu::BindGroup,
}

impl RopPass {
    /// Allocate the shuffled order, the pair lists (as many pairs as the depth order makes) and
    /// the groups binding them, `targets.color_view` as the frame's target.
    pub(super) fn new(r: &GpuRasterizer, targets: &Targets) -> Result<Self, GpuError> {
        let (ctx, pipes, n) = (r.ctx, r.pipes, r.scene.count);
        let pair_count = r.pair_count()?;
        let shuffle = pipes.sort.buffers(ctx, n + 1)?;
        let pairs = pipes.sort.buffers(ctx, pair_count.max(1))?;
        let [tiles_x, tiles_y] = r.params.tiles;
        let ranges = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rop tile ranges"),
            size: u64::from(tiles_x * tiles_y) * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("rop frame"),
            size: size_of::<FrameParams>() as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let keys_group = bind(
            ctx,
            &pipes.shuffle_keys,
            &[(0, &r.params_buffer), (4, &shuffle.keys), (5, &shuffle.vals), (19, &frame)],
        );
        let count_group = bind(
            ctx,
            &pipes.tile_count,
            &[(0, &r.params_buffer), (3, &r.splats), (5, &shuffle.vals), (6, &r.draw_args), (7, &shuffle.hist)],
        );
        let emit_group = bind(
            ctx,
            &pipes.tile_emit,
            &[
                (0, &r.params_buffer),
                (3, &r.splats),
                (5, &shuffle.vals),
                (6, &r.draw_args),
                (7, &shuffle.hist),
                (8, &pairs.keys),
                (9, &pairs.vals),
            ],
        );
        let ranges_group = bind(
            ctx,
            &pipes.tile_ranges,
            &[(0, &r.params_buffer), (7, &shuffle.hist), (8, &pairs.keys), (10, &ranges)],
        );
        let rop = r.rop_pipeline();
        let rop_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("tile rop"),
            layout: &rop.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: r.params_buffer.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: r.splats.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: shuffle.vals.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 9, resource: pairs.vals.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 10, resource: ranges.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 15, resource: r.scene.canonical.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 19, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 20, resource: r.sample_offsets.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 21, resource: wgpu::BindingResource::TextureView(&targets.color_view) },
            ],
        });
        Ok(Self {
            shuffle,
            pairs,
            pair_count,
            ranges,
            frame,
            keys_group,
            count_group,
            emit_group,
            ranges_group,
            rop_group,
        })
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
            pass.set_pipeline(&pipes.shuffle_keys);
            pass.set_bind_group(0, &self.keys_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        pipes.sort.encode(ctx, encoder, &self.shuffle, n, 32, None)?;
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("rop count"), timestamp_writes: None });
            pass.set_pipeline(&pipes.tile_count);
            pass.set_bind_group(0, &self.count_group, &[]);
            let (cx, cy) = groups((n + 1).div_ceil(256));
            pass.dispatch_workgroups(cx, cy, 1);
        }
        pipes.sort.encode_scan(ctx, encoder, &self.shuffle, n + 1);
        encoder.clear_buffer(&self.ranges, 0, None);
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("rop emit"), timestamp_writes: None });
            pass.set_pipeline(&pipes.tile_emit);
            pass.set_bind_group(0, &self.emit_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        let [tiles_x, tiles_y] = r.params.tiles;
        let tile_bits = u32::BITS - (tiles_x * tiles_y - 1).leading_zeros();
        pipes.sort.encode(ctx, encoder, &self.pairs, self.pair_count, tile_bits, None)?;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("tile rop"), timestamp_writes: None });
        pass.set_pipeline(&pipes.tile_ranges);
        pass.set_bind_group(0, &self.ranges_group, &[]);
        let (px, py) = groups(self.pair_count.div_ceil(256));
        pass.dispatch_workgroups(px, py, 1);
        pass.set_pipeline(r.rop_pipeline());
        pass.set_bind_group(0, &self.rop_group, &[]);
        pass.dispatch_workgroups(tiles_x, tiles_y, 1);
        Ok(())
    }
}

impl GpuRasterizer<'_> {
    /// The raster-operations kernel of this rasterizer's fragment depth.
    fn rop_pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipes.tile_rop[usize::from(self.raster.fragment_depth == FragmentDepth::MaxDensityPlane)]
    }
}
