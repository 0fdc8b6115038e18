// LSD radix sort of (key, value) pairs of u32, 4 bits per pass, stable; and the exclusive scan
// it is built from. Mirrored by splat_gpu::sort::cpu_radix_sort.
//
// No subgroup operation is used anywhere: every cooperation between invocations goes through
// workgroup memory and workgroupBarrier, so the result cannot depend on the subgroup size
// (lavapipe runs 8 lanes, GPUs 32 or 64). A pass is three dispatches:
//   histogram: per block of WG keys, the count of each digit  -> hist[digit * blocks + block];
//   scan:      exclusive prefix sum of hist in that (digit-major) order: the first output
//              position of each (digit, block);
//   scatter:   each block sorts its keys by the digit locally with four stable 1-bit splits,
//              then writes key i to hist[digit, block] + (its rank among the block's keys of
//              that digit). Stable because blocks, and keys within a block, keep input order.

struct SortParams {
    // Keys to sort (or entries to scan).
    count: u32,
    // Bit offset of this pass's digit.
    shift: u32,
    // Blocks of WG keys.
    blocks: u32,
    // Entries of `hist` the scan covers.
    scan_len: u32,
}

@group(0) @binding(0) var<uniform> sp: SortParams;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> vals_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> hist: array<u32>;

const WG: u32 = 256u;
const RADIX: u32 = 16u;

var<workgroup> counts: array<atomic<u32>, 16>;
var<workgroup> first: array<u32, 16>;
var<workgroup> partial: array<u32, 256>;
var<workgroup> local_keys: array<u32, 256>;
var<workgroup> local_vals: array<u32, 256>;

fn digit(key: u32) -> u32 {
    return (key >> sp.shift) & (RADIX - 1u);
}

// Blocks beyond 65535 workgroups are dispatched in rows of a 2D grid.
fn block_of(wg: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wg.y * groups.x + wg.x;
}

// Exclusive prefix sum of `v` over the workgroup (Hillis–Steele in workgroup memory); the
// workgroup's total is left in partial[WG - 1]. Call from uniform control flow.
fn workgroup_exclusive_scan(l: u32, v: u32) -> u32 {
    partial[l] = v;
    workgroupBarrier();
    for (var d = 1u; d < WG; d = d << 1u) {
        var x = 0u;
        if (l >= d) {
            x = partial[l - d];
        }
        workgroupBarrier();
        partial[l] += x;
        workgroupBarrier();
    }
    return partial[l] - v;
}

@compute @workgroup_size(256, 1, 1)
fn histogram(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = block_of(wg, groups);
    if (block >= sp.blocks) {
        return;
    }
    if (l < RADIX) {
        atomicStore(&counts[l], 0u);
    }
    workgroupBarrier();
    let i = block * WG + l;
    if (i < sp.count) {
        atomicAdd(&counts[digit(keys_in[i])], 1u);
    }
    workgroupBarrier();
    if (l < RADIX) {
        hist[l * sp.blocks + block] = atomicLoad(&counts[l]);
    }
}

// One workgroup: each invocation sums a contiguous run of hist, the runs' totals are scanned
// in workgroup memory, and each run is rewritten as its exclusive prefix.
@compute @workgroup_size(256, 1, 1)
fn scan(@builtin(local_invocation_index) l: u32) {
    let n = sp.scan_len;
    let per = (n + WG - 1u) / WG;
    let start = min(l * per, n);
    let end = min(start + per, n);
    var sum = 0u;
    for (var i = start; i < end; i++) {
        sum += hist[i];
    }
    var running = workgroup_exclusive_scan(l, sum);
    for (var i = start; i < end; i++) {
        let h = hist[i];
        hist[i] = running;
        running += h;
    }
}

@compute @workgroup_size(256, 1, 1)
fn scatter(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let block = block_of(wg, groups);
    if (block >= sp.blocks) {
        return;
    }
    let i = block * WG + l;
    // Past the end: the largest key, so these stay behind every real key of the block.
    var key = 0xffffffffu;
    var val = 0u;
    if (i < sp.count) {
        key = keys_in[i];
        val = vals_in[i];
    }
    let valid = min(WG, sp.count - block * WG);
    // Four stable 1-bit splits sort the block by the digit.
    for (var b = 0u; b < 4u; b++) {
        let bit = (digit(key) >> b) & 1u;
        let zeros_before = workgroup_exclusive_scan(l, 1u - bit);
        let zeros = partial[WG - 1u];
        var at = zeros_before;
        if (bit == 1u) {
            at = zeros + l - zeros_before;
        }
        workgroupBarrier();
        local_keys[at] = key;
        local_vals[at] = val;
        workgroupBarrier();
        key = local_keys[l];
        val = local_vals[l];
        workgroupBarrier();
    }
    // The first local position of each digit.
    let d = digit(key);
    if (l == 0u || digit(local_keys[l - 1u]) != d) {
        first[d] = l;
    }
    workgroupBarrier();
    if (l < valid) {
        let at = hist[d * sp.blocks + block] + (l - first[d]);
        keys_out[at] = key;
        vals_out[at] = val;
    }
}
