//! GPU LSD radix sort of (key, value) u32 pairs, written in WGSL (`shaders/sort.wgsl`), and the
//! exclusive scan it is built from.
//!
//! No maintained sort crate targets wgpu 30 (`wgpu_sort` stops at wgpu 0.19 and assumes a
//! subgroup size), so the sort is our own: [`RADIX_BITS`] = 8 bits per pass (four passes for a
//! 32-bit key), each pass a histogram, a scan and a scatter over blocks of [`BLOCK`] keys,
//! stable, and free of subgroup operations, so it is correct for any subgroup size by
//! construction (lavapipe runs 8 lanes, GPUs 32 or 64). A test checks the shader never calls a
//! subgroup builtin. The scatter sorts its block on the digit in workgroup memory first, by
//! stable splits on two bits at a time (the local sort of Satish et al. 2009, "Designing
//! efficient sorting algorithms for manycore GPUs"), so that each key's place among its
//! digit's keys is its place in the sorted block, and the block's keys of a digit are written
//! together.
//!
//! The scan is reduce-then-scan over tiles of [`SCAN_TILE`] entries ([`scan_levels`]): one
//! workgroup a tile, coalesced loads, and no invocation reading more than four entries of a
//! level, where a single workgroup used to sum a 6 M-key sort's 375,000 histogram entries in
//! runs of 1,465 serial loads an invocation.
//!
//! The depth sort and the draw-order shuffle sort the visible splats alone
//! ([`RadixSort::encode_culled`]): the first pass drops the culled ones (value [`CULLED`]) as it
//! sorts the first digit, and the passes after it run on the count the projection left on the
//! device, their uniforms and workgroup counts written
//! there by `sort_setup` (`shaders/sort_setup.wgsl`), so a view that culls most of a scene
//! sorts little more than what it draws, without a read-back.
//!
//! [`cpu_radix_sort`] is the CPU mirror of the same passes; [`depth_key`] maps a view depth to
//! its sortable key, and filters what cannot be sorted (NaN, negative, infinite).

use crate::split::{BindGroups, PartBindings, Split, SplitArray, SplitLayout};
use crate::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// WGSL of the sort kernels before the declarations of their arrays ([`sort_wgsl`]).
const SORT_SOURCE: &str = include_str!("../shaders/sort.wgsl");
/// WGSL of the setup of a culling sort's later passes ([`setup_wgsl`]).
const SETUP_SOURCE: &str = include_str!("../shaders/sort_setup.wgsl");
/// The value of a pair a culling sort drops (a culled splat's): no particle's id.
pub const CULLED: u32 = u32::MAX;
/// Invocations of a sort workgroup.
pub const WORKGROUP: u32 = 256;
/// Keys an invocation of the histogram and the scatter takes.
pub const ITEMS: u32 = 4;
/// Keys per workgroup block: its histogram is [`RADIX`] counts, so the scan is of a quarter
/// as many entries as there are keys.
pub const BLOCK: u32 = WORKGROUP * ITEMS;
/// Bits sorted per pass: each of the scatter's splits takes two.
pub const RADIX_BITS: u32 = 8;
/// Digits of a pass, one counter an invocation of the histogram.
pub const RADIX: u32 = 1 << RADIX_BITS;
/// Rows of the shader's raking scan: that many invocations each add up a row of that many.
const RAKE: u32 = 16;
const _: () = assert!(RADIX == WORKGROUP && RADIX_BITS.is_multiple_of(2) && RAKE * RAKE == WORKGROUP);
/// Entries of a scan tile: a workgroup of [`WORKGROUP`] invocations, four entries each.
pub const SCAN_TILE: u32 = 1024;
/// Most levels of a scan: four cover 2³² entries (2³² → 2²² → 2¹² → 4 tiles' sums).
pub const MAX_LEVELS: usize = 4;
/// `SortParams::scan_in` of the bottom level: the histogram itself.
const FROM_HIST: u32 = u32::MAX;
/// `SortParams::scan_out` of the top level: no level above.
const TOP: u32 = u32::MAX;
/// Uniform slots (and dispatch arguments) of the passes, at most eight of [`RADIX_BITS`];
const PASS_SLOTS: u64 = 8;
/// then of the first pass's scan levels;
const FIRST_LEVELS: u64 = PASS_SLOTS;
/// of the later passes' (shorter after a culling first pass);
const LATER_LEVELS: u64 = FIRST_LEVELS + MAX_LEVELS as u64;
/// and of [`RadixSort::encode_scan`]'s.
const SCAN_LEVELS: u64 = LATER_LEVELS + MAX_LEVELS as u64;
const SLOTS: u64 = SCAN_LEVELS + MAX_LEVELS as u64;
/// Bytes of a slot's dispatch arguments: workgroups in x, y and z.
const ARGS: u64 = 12;
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
    /// Entries of the scan level a dispatch covers.
    pub scan_len: u32,
    /// Where that level lives: `u32::MAX` for the histogram, else its first entry in the
    /// partial sums.
    pub scan_in: u32,
    /// The first entry in the partial sums of the level above, `u32::MAX` at the top.
    pub scan_out: u32,
    /// 1: the pass drops the pairs of value [`CULLED`] (the first of [`RadixSort::encode_culled`]'s).
    pub cull: u32,
    /// Padding to 32 bytes.
    pub pad: u32,
}

/// The sortable key of a view depth: its IEEE bits, which order positive floats like the
/// floats themselves. `None` for what a sort cannot order (NaN, ±∞, negative, −0): such
/// splats are culled before sorting.
pub fn depth_key(z: f32) -> Option<u32> {
    (z.is_finite() && z.is_sign_positive()).then_some(z.to_bits())
}

/// CPU mirror of the GPU passes: a stable LSD radix sort of `keys` (with `vals`) on the low
/// `bits` bits, [`RADIX_BITS`] at a time, via per-digit counts and their exclusive scan. (A
/// culling sort is this sort of the pairs whose value is not [`CULLED`].)
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

/// The levels of an exclusive scan of `n` entries, bottom (the histogram) to top, as the
/// uniforms of their dispatches: level i + 1 holds the sums of level i's tiles of
/// [`SCAN_TILE`] entries, packed one level after another in the partial sums; the top level is
/// one tile.
pub fn scan_levels(n: u32) -> Vec<SortParams> {
    let mut levels = vec![SortParams { scan_len: n, scan_in: FROM_HIST, scan_out: TOP, ..SortParams::default() }];
    let mut next = 0;
    while let Some(below) = levels.last_mut().filter(|l| l.scan_len > SCAN_TILE) {
        below.scan_out = next;
        let len = below.scan_len.div_ceil(SCAN_TILE);
        levels.push(SortParams { scan_len: len, scan_in: next, scan_out: TOP, ..SortParams::default() });
        next += len;
    }
    debug_assert!(levels.len() <= MAX_LEVELS);
    levels
}

/// Entries of the partial sums a scan of `n` entries needs (its levels above the bottom).
fn partials_len(n: u32) -> u64 {
    scan_levels(n)[1..].iter().map(|l| u64::from(l.scan_len)).sum()
}

/// Passes for `bits` key bits: rounded up to an even count so that the result lands back in
/// the input buffers after the ping-pong.
pub fn pass_count(bits: u32) -> u32 {
    bits.clamp(1, 32).div_ceil(RADIX_BITS).next_multiple_of(2)
}

/// The arrays of the sort's kernels: a pass's input keys and values, its output, and the
/// histogram, each of `array_len(capacity)` u32 split alike ([`split_of`]).
const KEYS_IN: SplitArray = SplitArray::of::<u32>("sort key", "keys_in", "key_in_at", "u32", 1);
const VALS_IN: SplitArray = SplitArray::of::<u32>("sort value", "vals_in", "val_in_at", "u32", 2);
const KEYS_OUT: SplitArray =
    SplitArray::of::<u32>("sort key", "keys_out", "key_out_at", "u32", 3).writable("key_out_set");
const VALS_OUT: SplitArray =
    SplitArray::of::<u32>("sort value", "vals_out", "val_out_at", "u32", 4).writable("val_out_set");
const HIST: SplitArray = SplitArray::of::<u32>("sort histogram", "hist", "hist_at", "u32", 5).writable("hist_set");
/// The storage buffers a sort kernel binds when its arrays are whole (the uniforms, the five
/// arrays and the scan's partial sums).
const OWN_BINDINGS: u32 = 7;

/// Elements of each of the sort's arrays for `capacity` pairs: the pairs, and at least the
/// histogram's [`RADIX`] counts a block of [`BLOCK`] keys.
pub fn array_len(capacity: u32) -> u64 {
    let capacity = u64::from(capacity.max(1));
    (u64::from(RADIX) * capacity.div_ceil(u64::from(BLOCK))).max(capacity)
}

/// How the sort's arrays for `capacity` pairs are cut in bindings of `max_binding` bytes; the
/// splatting kernels that read and write them are compiled for the same cut.
pub fn split_of(capacity: u32, max_binding: u64) -> Split {
    Split::of(array_len(capacity), 4, max_binding)
}

/// The sort kernels' arrays as `split` cuts them, extra parts bound as `parts` from binding 7 on.
fn split_layout(split: Split, parts: PartBindings) -> SplitLayout {
    let arrays = [KEYS_IN, VALS_IN, KEYS_OUT, VALS_OUT, HIST].map(|a| (a, split)).to_vec();
    SplitLayout { arrays, first_extra: 7, parts }
}

/// The constants the sort's shaders share with this file, declared here once.
fn constants_wgsl() -> String {
    format!(
        "const WG: u32 = {WORKGROUP}u;\nconst ITEMS: u32 = {ITEMS}u;\nconst BLOCK: u32 = {BLOCK}u;\n\
         const RADIX_BITS: u32 = {RADIX_BITS}u;\nconst RADIX: u32 = {RADIX}u;\nconst RAKE: u32 = {RAKE}u;\n\
         const SCAN_TILE: u32 = {SCAN_TILE}u;\n\
         const MAX_GROUPS_X: u32 = {MAX_GROUPS_X}u;\nconst CULLED: u32 = {CULLED}u;\n"
    )
}

/// The WGSL of the sort kernels over arrays cut as `split`, their parts bound as `parts`.
pub(crate) fn sort_wgsl(split: Split, parts: PartBindings) -> String {
    let layout = split_layout(split, parts);
    format!("{}{}{SORT_SOURCE}{}", layout.directives(), constants_wgsl(), layout.wgsl())
}

/// The WGSL of `sort_setup` for uniform slots `stride` bytes apart: the words of the
/// [`SortParams`] fields it writes are those of the struct here.
pub fn setup_wgsl(stride: u64) -> String {
    let word = |offset: usize| offset / 4;
    format!(
        "{}const SLOT_WORDS: u32 = {}u;\nconst COUNT: u32 = {}u;\nconst BLOCKS: u32 = {}u;\nconst SCAN_LEN: u32 = {}u;\n\
         const LATER_LEVELS: u32 = {LATER_LEVELS}u;\n{SETUP_SOURCE}",
        constants_wgsl(),
        stride / 4,
        word(std::mem::offset_of!(SortParams, count)),
        word(std::mem::offset_of!(SortParams, blocks)),
        word(std::mem::offset_of!(SortParams, scan_len)),
    )
}

/// The sort's pipelines, compiled for each [`Split`] of its arrays on first use (the whole one
/// at once).
pub struct RadixSort {
    kernels: crate::split::PerSplit<Split, SortKernels>,
    /// `sort_setup` and its layout (the same for every split).
    setup: (wgpu::BindGroupLayout, wgpu::ComputePipeline),
    stride: u64,
}

/// The sort's kernels for arrays cut as `split`.
struct SortKernels {
    layout: wgpu::BindGroupLayout,
    /// The layout of the binding arrays' group, where the split has any.
    arrays_layout: Option<wgpu::BindGroupLayout>,
    histogram: wgpu::ComputePipeline,
    scan_reduce: wgpu::ComputePipeline,
    scan_down: wgpu::ComputePipeline,
    scatter: wgpu::ComputePipeline,
}

/// Buffers of one sort of up to `capacity` pairs: keys and values in place with ping-pong
/// scratch, the per-block histogram, and the uniforms and workgroup counts of each dispatch,
/// each array in the parts of `split`.
pub struct SortBuffers {
    /// Keys: the input, and the sorted output after [`RadixSort::encode`].
    pub(crate) keys: Vec<wgpu::Buffer>,
    /// Values, permuted with their keys.
    pub(crate) vals: Vec<wgpu::Buffer>,
    /// Histogram (and scan) scratch, [`RADIX`] entries a block, at least `capacity`.
    pub(crate) hist: Vec<wgpu::Buffer>,
    /// The scan's levels above the histogram ([`scan_levels`]).
    partials: wgpu::Buffer,
    /// The ping-pong halves of keys and values.
    scratch: [Vec<wgpu::Buffer>; 2],
    /// How every array is cut over bindings.
    pub(crate) split: Split,
    capacity: u32,
    slots: Slots,
    bind_groups: [BindGroups; 2],
    kernels: std::sync::Arc<SortKernels>,
}

/// The pairs of a culling sort ([`RadixSort::encode_culled`], [`RadixSort::encode_compaction`]):
/// the first `n` of `buffers`, of which those not of value [`CULLED`] are as many as word 1 of
/// `kept` says (an indirect draw's instance count: the visible splats the projection counted).
#[derive(Clone, Copy)]
pub struct Culled<'b> {
    /// The sort's buffers, holding the pairs.
    pub buffers: &'b SortBuffers,
    /// The pairs the first pass reads.
    pub n: u32,
    /// The device's count of the pairs kept, in its word 1.
    pub kept: &'b wgpu::Buffer,
}

/// The uniforms and workgroups of a sort's dispatches, and what sizes them on the device.
struct Slots {
    /// The uniform slots, one a stride ([`PASS_SLOTS`] and the levels after them).
    params: wgpu::Buffer,
    /// The workgroups of each slot `sort_setup` sizes, [`ARGS`] bytes a slot (those the host
    /// sizes are dispatched directly: wgpu validates every indirect dispatch with one of its
    /// own by default).
    args: wgpu::Buffer,
    /// `sort_setup`'s input: the device's count, the passes and the levels.
    setup: wgpu::Buffer,
    setup_group: wgpu::BindGroup,
}

impl SortBuffers {
    /// Pairs the buffers hold.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Bytes of the buffers on the device.
    pub fn bytes(&self) -> u64 {
        let arrays = [&self.keys, &self.vals, &self.hist, &self.scratch[0], &self.scratch[1]];
        arrays.iter().flat_map(|parts| parts.iter()).map(wgpu::Buffer::size).sum::<u64>() + self.partials.size()
    }

    /// Elements `range` of `parts`, one of this sort's arrays.
    pub(crate) fn read(
        &self,
        ctx: &GpuContext,
        parts: &[wgpu::Buffer],
        range: std::ops::Range<u64>,
    ) -> Result<Vec<u32>, GpuError> {
        crate::split::read_u32(ctx, parts, self.split, range)
    }
}

/// Workgroups (x, y) covering `blocks` blocks.
pub(crate) fn groups(blocks: u32) -> (u32, u32) {
    if blocks <= MAX_GROUPS_X { (blocks.max(1), 1) } else { (MAX_GROUPS_X, blocks.div_ceil(MAX_GROUPS_X)) }
}

impl RadixSort {
    /// Compile the kernels of whole arrays; a typed error when the device rejects them.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let stride = (size_of::<SortParams>() as u64).next_multiple_of(ctx.storage_alignment);
        let sort = Self { kernels: crate::split::PerSplit::new(), setup: setup_kernel(ctx, stride)?, stride };
        sort.kernels(ctx, Split::WHOLE)?;
        Ok(sort)
    }

    /// The kernels of arrays cut as `split`, compiled on first use.
    fn kernels(&self, ctx: &GpuContext, split: Split) -> Result<std::sync::Arc<SortKernels>, GpuError> {
        self.kernels.get(split, || SortKernels::new(ctx, split))
    }

    /// Buffers for up to `capacity` pairs, split over as many bindings as they need; refused
    /// when that is more than the adapter binds in a stage.
    pub fn buffers(&self, ctx: &GpuContext, capacity: u32) -> Result<SortBuffers, GpuError> {
        let capacity = capacity.max(1);
        let len = array_len(capacity);
        let split = split_of(capacity, ctx.max_index_binding);
        let over = |split| split_layout(split, ctx.part_bindings()).over(ctx, OWN_BINDINGS);
        if let Some((needed, available)) = over(split) {
            let fits = |m: u64| over(split_of(m as u32, ctx.max_index_binding)).is_none();
            return Err(GpuError::SceneOverBindings {
                arrays: "sort keys, values and histogram",
                kernel: "the radix sort",
                needed,
                available,
                limit: ctx.max_index_binding,
                bytes: 5 * 4 * len,
                fits: crate::split::most_that_fit(u64::from(capacity), fits),
                fits_what: "pairs",
            });
        }
        let kernels = self.kernels(ctx, split)?;
        let array = |what| crate::split::alloc(ctx, what, 4, split, len);
        let (keys, vals) = (array("sort keys")?, array("sort values")?);
        let scratch = [array("sort keys scratch")?, array("sort values scratch")?];
        let hist = array("sort histogram")?;
        let partials = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("sort scan partial sums"),
            size: 4 * partials_len(len.min(u64::from(u32::MAX)) as u32).max(1),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let slots = self.slots(ctx);
        let layout = split_layout(split, ctx.part_bindings());
        let bind = |ki: &[wgpu::Buffer], vi: &[wgpu::Buffer], ko: &[wgpu::Buffer], vo: &[wgpu::Buffer]| {
            let params = wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &slots.params,
                    offset: 0,
                    size: wgpu::BufferSize::new(size_of::<SortParams>() as u64),
                }),
            };
            let arrays = [(KEYS_IN, ki), (VALS_IN, vi), (KEYS_OUT, ko), (VALS_OUT, vo), (HIST, &hist[..])];
            let parts: Vec<_> = arrays.iter().flat_map(|(array, buffers)| layout.bind(array, buffers)).collect();
            let partials = wgpu::BindGroupEntry { binding: 6, resource: partials.as_entire_binding() };
            let layouts = (&kernels.layout, kernels.arrays_layout.as_ref());
            BindGroups::new(&ctx.device, Some("sort"), layouts.0, layouts.1, &[params, partials], &parts)
        };
        let bind_groups = [bind(&keys, &vals, &scratch[0], &scratch[1]), bind(&scratch[0], &scratch[1], &keys, &vals)];
        Ok(SortBuffers { keys, vals, hist, partials, scratch, split, capacity, slots, bind_groups, kernels })
    }

    /// A sort's uniform slots and dispatch arguments, and `sort_setup`'s input and bindings.
    fn slots(&self, ctx: &GpuContext) -> Slots {
        let small = |label, size, usage| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | usage,
                mapped_at_creation: false,
            })
        };
        let params = small("sort params", self.stride * SLOTS, wgpu::BufferUsages::empty());
        let args =
            small("sort dispatch args", ARGS * SLOTS, wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_SRC);
        let setup = small("sort setup", 16, wgpu::BufferUsages::empty());
        let setup_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sort setup"),
            layout: &self.setup.0,
            entries: &[&setup, &params, &args]
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
                .collect::<Vec<_>>(),
        });
        Slots { params, args, setup, setup_group }
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
        let (passes, levels) = self.write_pass_slots(ctx, buf, count, bits, false)?;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("radix sort"),
            timestamp_writes: timestamps,
        });
        self.encode_passes(ctx, &mut pass, buf, &passes, &levels, false);
        Ok(())
    }

    /// Encode the sort of `pairs` on their whole keys without the pairs of value [`CULLED`], in
    /// one compute pass: the others end up sorted in the first pairs of the buffers' `keys` and
    /// `vals`. The first pass reads all `n` and drops the culled pairs; `sort_setup` then sizes
    /// the passes after it on the device's count, which the host never reads, and they are
    /// dispatched indirectly.
    pub fn encode_culled(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        pairs: Culled,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Result<(), GpuError> {
        self.encode_culled_on(ctx, encoder, pairs, u32::BITS, timestamps)
    }

    /// Encode the stream compaction of `pairs`, whose keys are zero: the pairs of value other
    /// than [`CULLED`] in their input order, in the first pairs of the buffers' `vals`. It is
    /// [`RadixSort::encode_culled`] on one key bit (two passes, the least that lands back in
    /// the input buffers): the sort is stable and every digit is zero, so the first pass drops
    /// the culled pairs and keeps the order of the others, and the second moves them back.
    pub fn encode_compaction(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        pairs: Culled,
    ) -> Result<(), GpuError> {
        self.encode_culled_on(ctx, encoder, pairs, 1, None)
    }

    /// A culling sort of `pairs` on their low `bits` key bits ([`RadixSort::encode_culled`]).
    fn encode_culled_on(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        Culled { buffers, n, kept }: Culled,
        bits: u32,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Result<(), GpuError> {
        let (passes, levels) = self.write_pass_slots(ctx, buffers, n, bits, true)?;
        let mut pass = self.encode_setup(ctx, encoder, &buffers.slots, (&passes, &levels), kept, timestamps);
        self.encode_passes(ctx, &mut pass, buffers, &passes, &levels, true);
        Ok(())
    }

    /// Begin the compute pass of a culling sort with `sort_setup`: the later `passes` and
    /// `levels` of `slots` sized on word 1 of `instances`.
    fn encode_setup<'e>(
        &self,
        ctx: &GpuContext,
        encoder: &'e mut wgpu::CommandEncoder,
        slots: &Slots,
        (passes, levels): (&[SortParams], &[SortParams]),
        instances: &wgpu::Buffer,
        timestamps: Option<wgpu::ComputePassTimestampWrites<'e>>,
    ) -> wgpu::ComputePass<'e> {
        let setup = [0, passes.len() as u32, levels.len() as u32, 0];
        ctx.queue.write_buffer(&slots.setup, 0, bytemuck::cast_slice(&setup));
        encoder.copy_buffer_to_buffer(instances, 4, &slots.setup, 0, 4);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("radix sort"),
            timestamp_writes: timestamps,
        });
        pass.set_pipeline(&self.setup.1);
        pass.set_bind_group(0, &slots.setup_group, &[]);
        ctx.dispatch(&mut pass, 1, 1, 1);
        pass
    }

    /// Write the slots of a sort of `count` pairs on `bits` bits (the first pass culling with
    /// `cull`): each pass's uniforms, and the scan levels of its histogram, the same for the
    /// first pass and the later ones. Those passes and levels.
    fn write_pass_slots(
        &self,
        ctx: &GpuContext,
        buf: &SortBuffers,
        count: u32,
        bits: u32,
        cull: bool,
    ) -> Result<(Vec<SortParams>, Vec<SortParams>), GpuError> {
        if count > buf.capacity {
            return Err(GpuError::Unsupported(format!("{count} keys exceed the sort's capacity of {}", buf.capacity)));
        }
        Ok(self.write_sort(ctx, &buf.slots, count, bits, cull))
    }

    /// [`Self::write_pass_slots`] into `slots`, whatever the arrays.
    fn write_sort(
        &self,
        ctx: &GpuContext,
        slots: &Slots,
        count: u32,
        bits: u32,
        cull: bool,
    ) -> (Vec<SortParams>, Vec<SortParams>) {
        let blocks = count.div_ceil(BLOCK).max(1);
        let passes: Vec<SortParams> = (0..pass_count(bits))
            .map(|p| SortParams {
                count,
                shift: p * RADIX_BITS,
                blocks,
                cull: u32::from(cull && p == 0),
                ..SortParams::default()
            })
            .collect();
        self.write_slots(ctx, slots, 0, &passes);
        let levels = scan_levels(RADIX * blocks);
        self.write_slots(ctx, slots, FIRST_LEVELS, &levels);
        self.write_slots(ctx, slots, LATER_LEVELS, &levels);
        (passes, levels)
    }

    /// Write `params` to the uniform slots of `slots` from slot `first` on, one a stride.
    fn write_slots(&self, ctx: &GpuContext, slots: &Slots, first: u64, params: &[SortParams]) {
        let mut uniforms = vec![0u8; (self.stride * params.len() as u64) as usize];
        for (i, p) in params.iter().enumerate() {
            let at = (self.stride * i as u64) as usize;
            uniforms[at..at + size_of::<SortParams>()].copy_from_slice(bytemuck::bytes_of(p));
        }
        ctx.queue.write_buffer(&slots.params, self.stride * first, &uniforms);
    }

    /// Encode the sort `passes`, each a histogram, the scan of its histogram's `levels` and a
    /// scatter, ping-ponging between the buffers' halves; with `device_sized`, the passes after
    /// the first are dispatched as `sort_setup` sized them.
    fn encode_passes(
        &self,
        ctx: &GpuContext,
        pass: &mut wgpu::ComputePass<'_>,
        buf: &SortBuffers,
        passes: &[SortParams],
        levels: &[SortParams],
        device_sized: bool,
    ) {
        let mut encoding = Encoding { stride: self.stride, ctx, pass, buf };
        for (p, params) in (0u64..).zip(passes) {
            let group = &buf.bind_groups[(p % 2) as usize];
            let on_device = device_sized && p > 0;
            let blocks = (!on_device).then(|| groups(params.blocks));
            encoding.dispatch(group, p, &buf.kernels.histogram, blocks);
            let first = if p == 0 { FIRST_LEVELS } else { LATER_LEVELS };
            encoding.levels(group, first, levels, on_device);
            encoding.dispatch(group, p, &buf.kernels.scatter, blocks);
        }
    }

    /// Encode an exclusive prefix sum of the first `count` entries of `buf.hist`, in place
    /// (its own uniform slots of the buffers).
    pub fn encode_scan(&self, ctx: &GpuContext, encoder: &mut wgpu::CommandEncoder, buf: &SortBuffers, count: u32) {
        let levels = scan_levels(count);
        self.write_slots(ctx, &buf.slots, SCAN_LEVELS, &levels);
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("scan"), timestamp_writes: None });
        let mut encoding = Encoding { stride: self.stride, ctx, pass: &mut pass, buf };
        encoding.levels(&buf.bind_groups[0], SCAN_LEVELS, &levels, false);
    }
}

/// The dispatches of one sort (or scan) being encoded into a compute pass.
struct Encoding<'e, 'p> {
    stride: u64,
    ctx: &'e GpuContext,
    pass: &'e mut wgpu::ComputePass<'p>,
    buf: &'e SortBuffers,
}

impl Encoding<'_, '_> {
    /// Dispatch `pipeline` with the uniforms of `slot`: `workgroups` where the host knows them,
    /// else those `sort_setup` wrote for the slot.
    fn dispatch(
        &mut self,
        group: &BindGroups,
        slot: u64,
        pipeline: &wgpu::ComputePipeline,
        workgroups: Option<(u32, u32)>,
    ) {
        group.set_compute(self.pass, &[(self.stride * slot) as u32]);
        self.pass.set_pipeline(pipeline);
        match workgroups {
            Some((x, y)) => self.ctx.dispatch(self.pass, x, y, 1),
            None => self.ctx.dispatch_indirect(self.pass, &self.buf.slots.args, ARGS * slot),
        }
    }

    /// The scan of `levels`, whose slots start at `first`: each level below the top reduced to
    /// the next, then each level scanned from the top down (`on_device`: sized by `sort_setup`).
    fn levels(&mut self, group: &BindGroups, first: u64, levels: &[SortParams], on_device: bool) {
        let kernels = &self.buf.kernels;
        let tiles = |i: usize| (!on_device).then(|| groups(levels[i].scan_len.div_ceil(SCAN_TILE)));
        for i in 0..levels.len() - 1 {
            self.dispatch(group, first + i as u64, &kernels.scan_reduce, tiles(i));
        }
        for i in (0..levels.len()).rev() {
            self.dispatch(group, first + i as u64, &kernels.scan_down, tiles(i));
        }
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
    sort_uploaded(ctx, sort, keys, vals, bits, false)
}

/// Sort `keys` with `vals` on the GPU on their low `bits` bits without the pairs of value
/// [`CULLED`], as the depth sort ([`RadixSort::encode_culled`], 32 bits) and the compaction
/// ([`RadixSort::encode_compaction`], 1 bit of zero keys) do, the count of the others uploaded
/// to the device for `sort_setup`: the entry point of the tests.
pub fn sort_culled_pairs(
    ctx: &GpuContext,
    sort: &RadixSort,
    keys: &[u32],
    vals: &[u32],
    bits: u32,
) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
    sort_uploaded(ctx, sort, keys, vals, bits, true)
}

/// Upload the pairs, sort them on `bits` ([`RadixSort::encode_culled`] with `cull`, else
/// [`RadixSort::encode`]) and read back the sorted ones.
fn sort_uploaded(
    ctx: &GpuContext,
    sort: &RadixSort,
    keys: &[u32],
    vals: &[u32],
    bits: u32,
    cull: bool,
) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
    if keys.len() != vals.len() {
        return Err(GpuError::Unsupported(format!("{} keys but {} values", keys.len(), vals.len())));
    }
    let n = u32::try_from(keys.len()).map_err(|_| GpuError::Unsupported("more than 2³² keys".into()))?;
    let kept = if cull { vals.iter().filter(|&&v| v != CULLED).count() as u32 } else { n };
    let buf = sort.buffers(ctx, n)?;
    if n == 0 {
        return Ok((Vec::new(), Vec::new()));
    }
    crate::split::write_u32(ctx, &buf.keys, buf.split, keys);
    crate::split::write_u32(ctx, &buf.vals, buf.split, vals);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("sort") });
    if cull {
        let kept = instances(ctx, kept);
        sort.encode_culled_on(ctx, &mut encoder, Culled { buffers: &buf, n, kept: &kept }, bits, None)?;
    } else {
        sort.encode(ctx, &mut encoder, &buf, n, bits, None)?;
    }
    ctx.submit(encoder.finish());
    let keys = buf.read(ctx, &buf.keys, 0..u64::from(kept))?;
    let vals = buf.read(ctx, &buf.vals, 0..u64::from(kept))?;
    Ok((keys, vals))
}

/// Draw arguments of `count` instances (word 1), as the projection leaves them for a culling
/// sort to read: the test entries' stand-in for the device's count.
fn instances(ctx: &GpuContext, count: u32) -> wgpu::Buffer {
    use wgpu::util::DeviceExt as _;
    ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("instances"),
        contents: bytemuck::cast_slice(&[0u32, count]),
        usage: wgpu::BufferUsages::COPY_SRC,
    })
}

/// The workgroups of a dispatch in x, y and z.
pub type Workgroups = [u32; 3];

/// The workgroups `sort_setup` gives a culling sort of `n` pairs of which `visible` are kept:
/// those of each later pass, then those of each scan level of the later passes (x, y, z). No
/// array is allocated, so that the test of counts past a row of the dispatch grid (more than
/// 65,535 blocks, 16.8 M pairs) runs where such a sort could not.
pub fn culled_workgroups(
    ctx: &GpuContext,
    sort: &RadixSort,
    n: u32,
    visible: u32,
) -> Result<(Vec<Workgroups>, Vec<Workgroups>), GpuError> {
    let slots = sort.slots(ctx);
    let (passes, levels) = sort.write_sort(ctx, &slots, n, u32::BITS, true);
    let visible = instances(ctx, visible);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("setup") });
    drop(sort.encode_setup(ctx, &mut encoder, &slots, (&passes, &levels), &visible, None));
    ctx.submit(encoder.finish());
    let args = ctx.read_u32(&slots.args, (ARGS / 4 * SLOTS) as usize)?;
    let slot = |s: u64| -> Workgroups { std::array::from_fn(|k| args[(3 * s) as usize + k]) };
    let pass_groups = (1..passes.len() as u64).map(slot).collect();
    let level_groups = (0..levels.len() as u64).map(|i| slot(LATER_LEVELS + i)).collect();
    Ok((pass_groups, level_groups))
}

/// The exclusive prefix sum of `values` on the GPU (uploading and reading back), by the sort's
/// scan: the entry point of the tests.
pub fn exclusive_scan(ctx: &GpuContext, sort: &RadixSort, values: &[u32]) -> Result<Vec<u32>, GpuError> {
    let count = u32::try_from(values.len()).map_err(|_| GpuError::Unsupported("more than 2³² entries".into()))?;
    let buf = sort.buffers(ctx, count)?;
    if count == 0 {
        return Ok(Vec::new());
    }
    crate::split::write_u32(ctx, &buf.hist, buf.split, values);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("scan") });
    sort.encode_scan(ctx, &mut encoder, &buf, count);
    ctx.submit(encoder.finish());
    buf.read(ctx, &buf.hist, 0..u64::from(count))
}

/// The sort's bindings for arrays cut as `split`, their parts bound as `parts` (checked against
/// `sort_wgsl`'s by a test).
fn layout_entries(split: Split, parts: PartBindings) -> Vec<wgpu::BindGroupLayoutEntry> {
    let params = crate::context::params_entry(0, wgpu::ShaderStages::COMPUTE, true, size_of::<SortParams>());
    let storage = |b, read_only| crate::context::storage_entry(b, wgpu::ShaderStages::COMPUTE, read_only);
    let mut entries = vec![
        params,
        storage(1, true),
        storage(2, true),
        storage(3, false),
        storage(4, false),
        storage(5, false),
        storage(6, false),
    ];
    entries.extend(split_layout(split, parts).extra_entries(0, |_| wgpu::ShaderStages::COMPUTE));
    entries
}

/// The sort's bindings in its binding arrays' group for arrays cut as `split`, their parts bound
/// as `parts` (none, no such group).
fn array_entries(split: Split, parts: PartBindings) -> Vec<wgpu::BindGroupLayoutEntry> {
    split_layout(split, parts).extra_entries(crate::split::ARRAY_GROUP, |_| wgpu::ShaderStages::COMPUTE)
}

/// `sort_setup`'s bindings: its input, the uniform slots and the dispatch arguments.
fn setup_entries() -> Vec<wgpu::BindGroupLayoutEntry> {
    let storage = |b, read_only| crate::context::storage_entry(b, wgpu::ShaderStages::COMPUTE, read_only);
    vec![storage(0, true), storage(1, false), storage(2, false)]
}

/// Compile `sort_setup` for uniform slots `stride` bytes apart.
fn setup_kernel(ctx: &GpuContext, stride: u64) -> Result<(wgpu::BindGroupLayout, wgpu::ComputePipeline), GpuError> {
    let device = &ctx.device;
    crate::context::validated(device, || {
        let module = crate::context::shader_module(device, "sort_setup.wgsl", &setup_wgsl(stride));
        let (layout, pipeline_layout) = crate::context::layouts(device, "sort setup", &setup_entries());
        (layout, crate::context::compute_pipeline(device, &module, Some(&pipeline_layout), "sort_setup"))
    })
}

impl SortKernels {
    /// Compile the kernels of arrays cut as `split`; a typed error when the device rejects them.
    fn new(ctx: &GpuContext, split: Split) -> Result<Self, GpuError> {
        let device = &ctx.device;
        crate::context::validated(device, || {
            let parts = ctx.part_bindings();
            let module = crate::context::shader_module(device, "sort.wgsl", &sort_wgsl(split, parts));
            let (entries, arrays) = (layout_entries(split, parts), array_entries(split, parts));
            let (layout, arrays_layout, pipeline_layout) = crate::split::layouts(device, "sort", &entries, &arrays);
            let pipeline = |entry| crate::context::compute_pipeline(device, &module, Some(&pipeline_layout), entry);
            Self {
                histogram: pipeline("histogram"),
                scan_reduce: pipeline("scan_reduce"),
                scan_down: pipeline("scan_down"),
                scatter: pipeline("scatter"),
                layout,
                arrays_layout,
            }
        })
    }
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

    /// Each level holds its tiles' sums, packed one after another, up to a single tile.
    #[test]
    fn scan_levels_reduce_to_one_tile() {
        let lens = |n| scan_levels(n).iter().map(|l| (l.scan_len, l.scan_in, l.scan_out)).collect::<Vec<_>>();
        assert_eq!(lens(0), [(0, FROM_HIST, TOP)]);
        assert_eq!(lens(SCAN_TILE), [(SCAN_TILE, FROM_HIST, TOP)]);
        assert_eq!(lens(SCAN_TILE + 1), [(SCAN_TILE + 1, FROM_HIST, 0), (2, 0, TOP)]);
        let n = SCAN_TILE * SCAN_TILE + 1;
        assert_eq!(lens(n), [(n, FROM_HIST, 0), (SCAN_TILE + 1, 0, SCAN_TILE + 1), (2, SCAN_TILE + 1, TOP)]);
        assert_eq!(partials_len(n), u64::from(SCAN_TILE) + 3);
        assert_eq!(scan_levels(u32::MAX).len(), MAX_LEVELS);
        // A 6.1 M-key sort's histogram: 5,958 blocks' 256 counts, 1,525,248 entries in 1,490
        // tiles, whose sums are two tiles.
        let n = RADIX * 6_100_000u32.div_ceil(BLOCK);
        assert_eq!(lens(n), [(1_525_248, FROM_HIST, 0), (1490, 0, 1490), (2, 1490, TOP)]);
    }

    #[test]
    fn depth_keys_order_like_depths_and_filter_the_unsortable() {
        let depths = [0.2f32, 0.21, 1.0, 1.0 + f32::EPSILON, 3.5e3, 1e30];
        let keys: Vec<u32> = depths.iter().map(|&z| depth_key(z).unwrap()).collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]));
        for bad in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, -0.0] {
            assert_eq!(depth_key(bad), None, "{bad}");
        }
        assert_eq!(pass_count(32), 4);
        assert_eq!(pass_count(12), 2);
        assert_eq!(pass_count(1), 2);
    }

    /// The kernels validate and use no subgroup operation (correct for any subgroup size).
    #[test]
    fn sort_wgsl_validates_without_subgroup_operations() {
        // Capabilities::empty() lacks SUBGROUP, so a subgroup builtin fails validation.
        crate::layout::wgsl_check::validate("sort", &sort_wgsl(Split::WHOLE, PartBindings::Each));
        crate::layout::wgsl_check::validate(
            "sort (split)",
            &sort_wgsl(Split { parts: 3, shift: 8 }, PartBindings::Each),
        );
        crate::layout::wgsl_check::validate("sort setup", &setup_wgsl(256));
    }

    #[test]
    fn sort_layout_matches_the_shader() {
        let none = naga::valid::Capabilities::empty();
        for split in [Split::WHOLE, Split { parts: 3, shift: 8 }] {
            let wgsl = sort_wgsl(split, PartBindings::Each);
            crate::layout::wgsl_check::check_layout(
                "sort",
                &wgsl,
                none,
                &super::layout_entries(split, PartBindings::Each),
            );
            let wgsl = sort_wgsl(split, PartBindings::Array);
            let entries = super::layout_entries(split, PartBindings::Array);
            let arrays = super::array_entries(split, PartBindings::Array);
            let groups: [&[_]; 2] = [&entries, &arrays];
            crate::layout::wgsl_check::check_layouts("sort", &wgsl, crate::layout::wgsl_check::BINDING_ARRAYS, &groups);
        }
        crate::layout::wgsl_check::check_layout("sort setup", &setup_wgsl(32), none, &super::setup_entries());
    }
}
