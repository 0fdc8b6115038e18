// LSD radix sort of (key, value) pairs of u32, 4 bits per pass, stable; and the exclusive scan
// it is built from. Mirrored by splat_gpu::sort::cpu_radix_sort.
//
// No subgroup operation is used anywhere: every cooperation between invocations goes through
// workgroup memory and workgroupBarrier, so the result cannot depend on the subgroup size
// (lavapipe runs 8 lanes, GPUs 32 or 64). A pass is:
//   histogram: per block of WG keys, the count of each digit  -> hist[digit * blocks + block];
//   scan:      exclusive prefix sum of hist in that (digit-major) order: the first output
//              position of each (digit, block);
//   scatter:   each key goes to hist[digit, block] + its rank among the block's keys of that
//              digit. Stable because blocks, and keys within a block, keep input order.
//
// The scan is reduce-then-scan over tiles of SCAN_TILE entries, one workgroup a tile, every
// access coalesced (entry k * WG + l of a tile is invocation l's k-th load): `scan_reduce`
// writes each tile's sum to the next level (in `partials`), the levels are reduced until one
// tile holds them, and `scan_down` scans each tile from the top level down, starting it at its
// own sum's prefix from the level above. No invocation reads more than SCAN_ITEMS entries of a
// level, however long the scan.
//
// The host dispatches what it can size; the passes after a culling one run on a count only the
// device knows and are dispatched indirectly, their uniforms and workgroups written by
// `sort_setup` (sort_setup.wgsl). A pass that culls (`cull`, the first pass of
// the depth sort and of the draw-order shuffle) drops the pairs whose value is CULLED, so the
// passes after it sort the visible splats alone.
struct SortParams {
    // Keys to sort (or entries to scan).
    count: u32,
    // Bit offset of this pass's digit.
    shift: u32,
    // Blocks of WG keys.
    blocks: u32,
    // Entries of the scan level a dispatch covers.
    scan_len: u32,
    // Where that level lives: FROM_HIST for `hist` itself, else its first entry in `partials`.
    scan_in: u32,
    // The first entry in `partials` of the level above (its tiles' sums), or TOP for the top.
    scan_out: u32,
    // 1: the pass drops the pairs whose value is CULLED (neither counted nor written).
    cull: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> sp: SortParams;
// The pass's input keys and values (`key_in_at(i)`, `val_in_at(i)`, bindings 1 and 2), its
// output (`key_out_set(i, k)`, `val_out_set(i, v)`, 3 and 4) and the histogram (`hist_at(i)`,
// `hist_set(i, h)`, 5): declared with their accessors by splat_gpu::sort::sort_wgsl, each split
// over more bindings where it is larger than one (splat_gpu::split).

// The scan's upper levels: the tiles' sums of each level below, level after level.
@group(0) @binding(6) var<storage, read_write> partials: array<u32>;

const WG: u32 = 256u;
const RADIX: u32 = 16u;

// Keys per segment of a block in the scatter's ranking (WG = SEGMENT²).
const SEGMENT: u32 = 16u;

// Entries a scan invocation loads from a level, and a scan tile's (WG × SCAN_ITEMS).
// SCAN_TILE, MAX_GROUPS_X and CULLED are declared by splat_gpu::sort::constants_wgsl.
const SCAN_ITEMS: u32 = 4u;
// `scan_in` of the bottom level, `hist`; `scan_out` of the top level, which has no level above.
const FROM_HIST: u32 = 0xffffffffu;
const TOP: u32 = 0xffffffffu;

var<workgroup> counts: array<atomic<u32>, 16>;
var<workgroup> partial: array<u32, 256>;
var<workgroup> digits: array<u32, 256>;
var<workgroup> offsets: array<u32, 256>;
var<workgroup> tile: array<u32, 1024>;

fn digit(key: u32) -> u32 {
    return (key >> sp.shift) & (RADIX - 1u);
}

// Blocks beyond MAX_GROUPS_X workgroups are dispatched in rows of a 2D grid, every row but
// the last full (so the row width is a constant, not `num_workgroups`, which an indirect
// dispatch need not provide on every backend).
fn block_of(wg: vec3<u32>) -> u32 {
    return wg.y * MAX_GROUPS_X + wg.x;
}

// Whether input pair i is sorted: one of the pass's pairs, and not dropped by a culling pass.
fn kept(i: u32) -> bool {
    return i < sp.count && (sp.cull == 0u || val_in_at(i) != CULLED);
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
) {
    let block = block_of(wg);
    if (block >= sp.blocks) {
        return;
    }
    if (l < RADIX) {
        atomicStore(&counts[l], 0u);
    }
    workgroupBarrier();
    let i = block * WG + l;
    if (kept(i)) {
        atomicAdd(&counts[digit(key_in_at(i))], 1u);
    }
    workgroupBarrier();
    if (l < RADIX) {
        hist_set(l * sp.blocks + block, atomicLoad(&counts[l]));
    }
}

// Entry i of the level being scanned.
fn level_at(i: u32) -> u32 {
    if (sp.scan_in == FROM_HIST) {
        return hist_at(i);
    }
    return partials[sp.scan_in + i];
}

fn level_set(i: u32, v: u32) {
    if (sp.scan_in == FROM_HIST) {
        hist_set(i, v);
    } else {
        partials[sp.scan_in + i] = v;
    }
}

// The sum of each tile of the level, to entry `tile` of the level above.
@compute @workgroup_size(256, 1, 1)
fn scan_reduce(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let t = block_of(wg);
    if (t * SCAN_TILE >= sp.scan_len) {
        return;
    }
    var sum = 0u;
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        let i = t * SCAN_TILE + k * WG + l;
        if (i < sp.scan_len) {
            sum += level_at(i);
        }
    }
    workgroup_exclusive_scan(l, sum);
    if (l == 0u) {
        partials[sp.scan_out + t] = partial[WG - 1u];
    }
}

// Each tile of the level rewritten as its exclusive prefix sum, plus the prefix of the tiles
// before it (entry `tile` of the level above, already scanned; 0 at the top): the tile is
// staged in workgroup memory with coalesced loads, each invocation scans SCAN_ITEMS
// consecutive entries of it, and the runs' sums are scanned across the workgroup.
@compute @workgroup_size(256, 1, 1)
fn scan_down(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let t = block_of(wg);
    let first = t * SCAN_TILE;
    if (first >= sp.scan_len) {
        return;
    }
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        let i = first + k * WG + l;
        var v = 0u;
        if (i < sp.scan_len) {
            v = level_at(i);
        }
        tile[k * WG + l] = v;
    }
    workgroupBarrier();
    var run = 0u;
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        run += tile[l * SCAN_ITEMS + k];
    }
    var running = workgroup_exclusive_scan(l, run);
    if (sp.scan_out != TOP) {
        running += partials[sp.scan_out + t];
    }
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        let v = tile[l * SCAN_ITEMS + k];
        tile[l * SCAN_ITEMS + k] = running;
        running += v;
    }
    workgroupBarrier();
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        let i = first + k * WG + l;
        if (i < sp.scan_len) {
            level_set(i, tile[k * WG + l]);
        }
    }
}

// Each key's rank among the block's keys of its digit, from counts over 16 segments of 16
// keys: invocation (d, g) counts digit d in segment g, 16 invocations turn each digit's counts
// into exclusive offsets, and each key adds the keys of its digit before it in its segment.
// Three barriers per block; keys keep their input order within a digit, so the sort is stable.
@compute @workgroup_size(256, 1, 1)
fn scatter(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let block = block_of(wg);
    if (block >= sp.blocks) {
        return;
    }
    let i = block * WG + l;
    let valid = kept(i);
    var key = 0u;
    var val = 0u;
    if (valid) {
        key = key_in_at(i);
        val = val_in_at(i);
    }
    let d = digit(key);
    // Past the end or culled: digit RADIX, which no invocation counts.
    digits[l] = select(RADIX, d, valid);
    workgroupBarrier();
    let counted = l / SEGMENT;
    let segment = l % SEGMENT;
    var c = 0u;
    for (var j = 0u; j < SEGMENT; j++) {
        c += u32(digits[segment * SEGMENT + j] == counted);
    }
    offsets[counted * SEGMENT + segment] = c;
    workgroupBarrier();
    if (l < RADIX) {
        var running = 0u;
        for (var g = 0u; g < SEGMENT; g++) {
            let n = offsets[l * SEGMENT + g];
            offsets[l * SEGMENT + g] = running;
            running += n;
        }
    }
    workgroupBarrier();
    if (valid) {
        let own = l / SEGMENT;
        var rank = offsets[d * SEGMENT + own];
        for (var s = own * SEGMENT; s < l; s++) {
            rank += u32(digits[s] == d);
        }
        let at = hist_at(d * sp.blocks + block) + rank;
        key_out_set(at, key);
        val_out_set(at, val);
    }
}
