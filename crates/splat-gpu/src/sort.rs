//! GPU LSD radix sort of (key, value) u32 pairs, written in WGSL (`shaders/sort.wgsl`), and the
//! exclusive scan it is built from.
//!
//! No maintained sort crate targets wgpu 30 (`wgpu_sort` stops at wgpu 0.19 and assumes a
//! subgroup size), so the sort is our own: 4 bits per pass, three dispatches per pass
//! (histogram, scan, scatter), stable, and free of subgroup operations, so it is correct for
//! any subgroup size by construction (lavapipe runs 8 lanes, GPUs 32 or 64). A test checks the
//! shader never calls a subgroup builtin.
//!
//! [`cpu_radix_sort`] is the CPU mirror of the same passes; [`depth_key`] maps a view depth to
//! its sortable key, and filters what cannot be sorted (NaN, negative, infinite).

use crate::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// WGSL of the sort kernels.
pub const SORT_WGSL: &str = include_str!("../shaders/sort.wgsl");
/// Keys per workgroup block.
pub const BLOCK: u32 = 256;
/// Bits sorted per pass.
pub const RADIX_BITS: u32 = 4;
/// Most workgroups along one dispatch dimension (WebGPU's default limit); more blocks are
/// dispatched as rows of a 2D grid.
const MAX_GROUPS_X: u32 = 65_535;

/// The uniforms of one pass (WGSL `SortParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SortParams {
    /// Keys to sort (or entries to scan).
    pub count: u32,
    /// Bit offset of the pass's digit.
    pub shift: u32,
    /// Blocks of [`BLOCK`] keys.
    pub blocks: u32,
    /// Entries of the histogram the scan covers.
    pub scan_len: u32,
}

/// The sortable key of a view depth: its IEEE bits, which order positive floats like the
/// floats themselves. `None` for what a sort cannot order (NaN, ±∞, negative, −0): such
/// splats are culled before sorting.
pub fn depth_key(z: f32) -> Option<u32> {
    (z.is_finite() && z.is_sign_positive()).then_some(z.to_bits())
}

/// CPU mirror of the GPU passes: a stable LSD radix sort of `keys` (with `vals`) on the low
/// `bits` bits, [`RADIX_BITS`] at a time, via per-digit counts and their exclusive scan.
pub fn cpu_radix_sort(keys: &mut Vec<u32>, vals: &mut Vec<u32>, bits: u32) {
    let radix = 1usize << RADIX_BITS;
    for shift in (0..pass_count(bits)).map(|p| p * RADIX_BITS) {
        let digit = |k: u32| ((k >> shift) as usize) & (radix - 1);
        let mut start = vec![0usize; radix];
        for &k in keys.iter() {
            start[digit(k)] += 1;
        }
        let mut sum = 0;
        for s in &mut start {
            (*s, sum) = (sum, sum + *s);
        }
        let (mut k2, mut v2) = (vec![0; keys.len()], vec![0; vals.len()]);
        for (&k, &v) in keys.iter().zip(vals.iter()) {
            let at = &mut start[digit(k)];
            (k2[*at], v2[*at]) = (k, v);
            *at += 1;
        }
        (*keys, *vals) = (k2, v2);
    }
}

/// Passes for `bits` key bits: rounded up to an even count so that the result lands back in
/// the input buffers after the ping-pong.
pub fn pass_count(bits: u32) -> u32 {
    bits.clamp(1, 32).div_ceil(RADIX_BITS).next_multiple_of(2)
}

/// The sort's pipelines.
pub struct RadixSort {
    layout: wgpu::BindGroupLayout,
    histogram: wgpu::ComputePipeline,
    scan: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
    stride: u64,
}

/// Buffers of one sort of up to `capacity` pairs: keys and values in place (`keys`, `vals`)
/// with ping-pong scratch, per-block histogram and per-pass uniforms.
pub struct SortBuffers {
    /// Keys: the input, and the sorted output after [`RadixSort::encode`].
    pub keys: wgpu::Buffer,
    /// Values, permuted with their keys.
    pub vals: wgpu::Buffer,
    /// Histogram (and scan) scratch, `16 × blocks` entries, at least `capacity`.
    pub hist: wgpu::Buffer,
    capacity: u32,
    params: wgpu::Buffer,
    bind_groups: [wgpu::BindGroup; 2],
}

impl SortBuffers {
    /// Pairs the buffers hold.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

/// Workgroups (x, y) covering `blocks` blocks.
pub(crate) fn groups(blocks: u32) -> (u32, u32) {
    if blocks <= MAX_GROUPS_X { (blocks.max(1), 1) } else { (MAX_GROUPS_X, blocks.div_ceil(MAX_GROUPS_X)) }
}

impl RadixSort {
    /// Compile the kernels; a typed error when the device rejects them.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("sort.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SORT_WGSL.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sort"),
            entries: &layout_entries(),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sort"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry| crate::context::compute_pipeline(device, &module, Some(&pipeline_layout), entry);
        let sort = Self {
            histogram: pipeline("histogram"),
            scan: pipeline("scan"),
            scatter: pipeline("scatter"),
            layout,
            stride: (size_of::<SortParams>() as u64).next_multiple_of(ctx.storage_alignment),
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Shader(e.to_string()));
        }
        Ok(sort)
    }

    /// Buffers for up to `capacity` pairs; refuses sizes above the adapter's binding limit.
    pub fn buffers(&self, ctx: &GpuContext, capacity: u32) -> Result<SortBuffers, GpuError> {
        let capacity = capacity.max(1);
        let blocks = capacity.div_ceil(BLOCK);
        let hist_len = (16 * blocks).max(capacity);
        ctx.check_binding("sort", 4 * u64::from(hist_len), capacity as usize)?;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let buffer = |label, words: u32| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 4 * u64::from(words),
                usage,
                mapped_at_creation: false,
            })
        };
        let (keys, vals) = (buffer("sort keys", capacity), buffer("sort values", capacity));
        let (keys_tmp, vals_tmp) = (buffer("sort keys scratch", capacity), buffer("sort values scratch", capacity));
        let hist = buffer("sort histogram", hist_len);
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sort params"),
            size: self.stride * 9,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = |ki: &wgpu::Buffer, vi: &wgpu::Buffer, ko: &wgpu::Buffer, vo: &wgpu::Buffer| {
            ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("sort"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &params,
                            offset: 0,
                            size: wgpu::BufferSize::new(size_of::<SortParams>() as u64),
                        }),
                    },
                    wgpu::BindGroupEntry { binding: 1, resource: ki.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: vi.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: ko.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 4, resource: vo.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 5, resource: hist.as_entire_binding() },
                ],
            })
        };
        let bind_groups = [bind(&keys, &vals, &keys_tmp, &vals_tmp), bind(&keys_tmp, &vals_tmp, &keys, &vals)];
        Ok(SortBuffers { keys, vals, hist, capacity, params, bind_groups })
    }

    /// Encode the sort of the first `count` pairs of `buf` on their low `bits` key bits, in
    /// one compute pass. The sorted pairs end up in `buf.keys` and `buf.vals`.
    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        buf: &SortBuffers,
        count: u32,
        bits: u32,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Result<(), GpuError> {
        if count > buf.capacity {
            return Err(GpuError::Unsupported(format!("{count} keys exceed the sort's capacity of {}", buf.capacity)));
        }
        let blocks = count.div_ceil(BLOCK).max(1);
        let passes = pass_count(bits);
        let mut uniforms = vec![0u8; (self.stride * u64::from(passes)) as usize];
        for p in 0..passes {
            let params = SortParams { count, shift: p * RADIX_BITS, blocks, scan_len: 16 * blocks };
            let at = (self.stride * u64::from(p)) as usize;
            uniforms[at..at + size_of::<SortParams>()].copy_from_slice(bytemuck::bytes_of(&params));
        }
        ctx.queue.write_buffer(&buf.params, 0, &uniforms);
        let (gx, gy) = groups(blocks);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("radix sort"),
            timestamp_writes: timestamps,
        });
        for p in 0..passes {
            let offset = (self.stride * u64::from(p)) as u32;
            pass.set_bind_group(0, &buf.bind_groups[(p % 2) as usize], &[offset]);
            pass.set_pipeline(&self.histogram);
            ctx.dispatch(&mut pass, gx, gy, 1);
            pass.set_pipeline(&self.scan);
            ctx.dispatch(&mut pass, 1, 1, 1);
            pass.set_pipeline(&self.scatter);
            ctx.dispatch(&mut pass, gx, gy, 1);
        }
        Ok(())
    }

    /// Encode an exclusive prefix sum of the first `count` entries of `buf.hist`, in place
    /// (one workgroup; uniform slot 8 of the buffers).
    pub fn encode_scan(&self, ctx: &GpuContext, encoder: &mut wgpu::CommandEncoder, buf: &SortBuffers, count: u32) {
        let params = SortParams { count, shift: 0, blocks: 0, scan_len: count };
        ctx.queue.write_buffer(&buf.params, self.stride * 8, bytemuck::bytes_of(&params));
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("scan"), timestamp_writes: None });
        pass.set_bind_group(0, &buf.bind_groups[0], &[(self.stride * 8) as u32]);
        pass.set_pipeline(&self.scan);
        ctx.dispatch(&mut pass, 1, 1, 1);
    }
}

/// Sort `keys` with `vals` on the GPU on their low `bits` bits (uploading and reading back):
/// the entry point of the tests and the benchmark.
pub fn sort_pairs(
    ctx: &GpuContext,
    sort: &RadixSort,
    keys: &[u32],
    vals: &[u32],
    bits: u32,
) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
    if keys.len() != vals.len() {
        return Err(GpuError::Unsupported(format!("{} keys but {} values", keys.len(), vals.len())));
    }
    let count = u32::try_from(keys.len()).map_err(|_| GpuError::Unsupported("more than 2³² keys".into()))?;
    let buf = sort.buffers(ctx, count)?;
    if count == 0 {
        return Ok((Vec::new(), Vec::new()));
    }
    ctx.queue.write_buffer(&buf.keys, 0, bytemuck::cast_slice(keys));
    ctx.queue.write_buffer(&buf.vals, 0, bytemuck::cast_slice(vals));
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("sort") });
    sort.encode(ctx, &mut encoder, &buf, count, bits, None)?;
    ctx.submit(encoder.finish());
    let keys = ctx.read_u32(&buf.keys, count as usize)?;
    let vals = ctx.read_u32(&buf.vals, count as usize)?;
    Ok((keys, vals))
}

/// The sort's bindings (checked against `sort.wgsl`'s by a test).
fn layout_entries() -> [wgpu::BindGroupLayoutEntry; 6] {
    let params = crate::context::params_entry(0, wgpu::ShaderStages::COMPUTE, true, size_of::<SortParams>());
    let storage = |b, read_only| crate::context::storage_entry(b, wgpu::ShaderStages::COMPUTE, read_only);
    [params, storage(1, true), storage(2, true), storage(3, false), storage(4, false), storage(5, false)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_mirror_is_a_stable_sort() {
        let mut rng = splat_core::rng::SplitMix64::new(3);
        let keys: Vec<u32> = (0..5000).map(|_| (rng.next_u64() % 97) as u32 * 0x0101_0101).collect();
        let vals: Vec<u32> = (0..5000).collect();
        let (mut k, mut v) = (keys.clone(), vals.clone());
        cpu_radix_sort(&mut k, &mut v, 32);
        let mut expected: Vec<(u32, u32)> = keys.into_iter().zip(vals).collect();
        expected.sort_by_key(|&(key, _)| key); // stable
        assert_eq!(k, expected.iter().map(|e| e.0).collect::<Vec<_>>());
        assert_eq!(v, expected.iter().map(|e| e.1).collect::<Vec<_>>());
    }

    #[test]
    fn depth_keys_order_like_depths_and_filter_the_unsortable() {
        let depths = [0.2f32, 0.21, 1.0, 1.0 + f32::EPSILON, 3.5e3, 1e30];
        let keys: Vec<u32> = depths.iter().map(|&z| depth_key(z).unwrap()).collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]));
        for bad in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, -0.0] {
            assert_eq!(depth_key(bad), None, "{bad}");
        }
        assert_eq!(pass_count(32), 8);
        assert_eq!(pass_count(12), 4);
        assert_eq!(pass_count(1), 2);
    }

    /// The kernels validate and use no subgroup operation (correct for any subgroup size).
    #[test]
    fn sort_wgsl_validates_without_subgroup_operations() {
        // Capabilities::empty() lacks SUBGROUP, so a subgroup builtin fails validation.
        crate::layout::wgsl_check::validate("sort", SORT_WGSL);
    }

    #[test]
    fn sort_layout_matches_the_shader() {
        let none = naga::valid::Capabilities::empty();
        crate::layout::wgsl_check::check_layout("sort", SORT_WGSL, none, &super::layout_entries());
    }
}
