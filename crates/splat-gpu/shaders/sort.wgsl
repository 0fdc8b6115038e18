// LSD radix sort of (key, value) pairs of u32, RADIX_BITS bits per pass, stable; and the
// exclusive scan it is built from. Mirrored by splat_gpu::sort::cpu_radix_sort.
//
// No subgroup operation is used anywhere: every cooperation between invocations goes through
// workgroup memory and workgroupBarrier, so the result cannot depend on the subgroup size
// (lavapipe runs 8 lanes, GPUs 32 or 64). A pass is:
//   histogram: per block of BLOCK keys (ITEMS an invocation), the count of each digit
//              -> hist[digit * blocks + block];
//   scan:      exclusive prefix sum of hist in that (digit-major) order: the first output
//              position of each (digit, block);
//   scatter:   the block sorted on its digit in workgroup memory (a stable split on two bits
//              at a time, Satish et al. 2009's local sort), then each key written to
//              hist[digit, block] + its place among the block's keys of that digit. Stable
//              because blocks, and keys within a block, keep input order.
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
//
// Declared before this by splat_gpu::sort: WG (invocations a workgroup), ITEMS (keys an
// invocation), BLOCK (WG × ITEMS), RADIX_BITS, RADIX (= WG), RAKE (the raking scan's rows,
// RAKE² = WG), SCAN_TILE, MAX_GROUPS_X, CULLED.
struct SortParams {
    // Keys to sort (or entries to scan).
    count: u32,
    // Bit offset of this pass's digit.
    shift: u32,
    // Blocks of BLOCK keys.
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

// Entries a scan invocation loads from a level, and a scan tile's (WG × SCAN_ITEMS).
const SCAN_ITEMS: u32 = 4u;
// `scan_in` of the bottom level, `hist`; `scan_out` of the top level, which has no level above.
const FROM_HIST: u32 = 0xffffffffu;
const TOP: u32 = 0xffffffffu;

var<workgroup> counts: array<atomic<u32>, RADIX>;
var<workgroup> tile: array<u32, SCAN_TILE>;
// The scatter's block, in input order and after each split; each digit's first place in it,
// and where the digit's keys of this block start in the output.
var<workgroup> block_keys: array<u32, BLOCK>;
var<workgroup> block_vals: array<u32, BLOCK>;
var<workgroup> digit_first: array<u32, RADIX>;
var<workgroup> digit_out: array<u32, RADIX>;
// The raking scan's entries, its rows' prefixes and its total.
var<workgroup> rake: array<vec2<u32>, WG>;
var<workgroup> rake_rows: array<vec2<u32>, RAKE>;
var<workgroup> rake_total: vec2<u32>;

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

@compute @workgroup_size(WG, 1, 1)
fn histogram(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let block = block_of(wg);
    if (block >= sp.blocks) {
        return;
    }
    // One counter an invocation: RADIX = WG.
    atomicStore(&counts[l], 0u);
    workgroupBarrier();
    for (var k = 0u; k < ITEMS; k++) {
        let i = block * BLOCK + k * WG + l;
        if (kept(i)) {
            atomicAdd(&counts[digit(key_in_at(i))], 1u);
        }
    }
    workgroupBarrier();
    hist_set(l * sp.blocks + block, atomicLoad(&counts[l]));
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
@compute @workgroup_size(WG, 1, 1)
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
    rake_exclusive_scan(l, vec2<u32>(sum, 0u));
    if (l == 0u) {
        partials[sp.scan_out + t] = rake_total.x;
    }
}

// Each tile of the level rewritten as its exclusive prefix sum, plus the prefix of the tiles
// before it (entry `tile` of the level above, already scanned; 0 at the top): the tile is
// staged in workgroup memory with coalesced loads, each invocation scans SCAN_ITEMS
// consecutive entries of it, and the runs' sums are scanned across the workgroup.
@compute @workgroup_size(WG, 1, 1)
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
    var running = rake_exclusive_scan(l, vec2<u32>(run, 0u)).x;
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

// Exclusive prefix sum of `v` over the workgroup, by raking: RAKE invocations scan a row of
// RAKE entries each, one scans the rows' sums. The total is left in `rake_total`. The scan
// kernels use the first word; the scatter's splits pack two 16-bit counts in each, which a
// block's BLOCK keys cannot overflow. Three barriers; call from uniform control flow.
fn rake_exclusive_scan(l: u32, v: vec2<u32>) -> vec2<u32> {
    rake[l] = v;
    workgroupBarrier();
    if (l < RAKE) {
        var run = vec2<u32>(0u);
        for (var j = 0u; j < RAKE; j++) {
            let x = rake[l * RAKE + j];
            rake[l * RAKE + j] = run;
            run += x;
        }
        rake_rows[l] = run;
    }
    workgroupBarrier();
    if (l == 0u) {
        var run = vec2<u32>(0u);
        for (var r = 0u; r < RAKE; r++) {
            let x = rake_rows[r];
            rake_rows[r] = run;
            run += x;
        }
        rake_total = run;
    }
    workgroupBarrier();
    return rake[l] + rake_rows[l / RAKE];
}

// The four 16-bit counts of a raking scan's two words.
fn unpack_counts(w: vec2<u32>) -> vec4<u32> {
    return vec4<u32>(w.x & 0xffffu, w.x >> 16u, w.y & 0xffffu, w.y >> 16u);
}

// The block's pairs, ITEMS consecutive ones an invocation (invocation l holds places
// l * ITEMS + j), so that a split's ranks keep their order.
struct Held {
    keys: array<u32, ITEMS>,
    vals: array<u32, ITEMS>,
}

fn hold(l: u32) -> Held {
    var held: Held;
    for (var j = 0u; j < ITEMS; j++) {
        held.keys[j] = block_keys[l * ITEMS + j];
        held.vals[j] = block_vals[l * ITEMS + j];
    }
    return held;
}

// A stable split of the block's first `n` pairs into four buckets: each held pair moves to
// its bucket's start + the bucket's pairs held by invocations before l + those held before
// it by l. The pairs at places n and beyond go to the last bucket, behind the others, so
// they stay at the end. Rewrites the block in workgroup memory and returns the pairs l holds
// in the new order.
fn split(l: u32, held: Held, n: u32, shift: u32) -> Held {
    var bucket: array<u32, ITEMS>;
    var before: array<u32, ITEMS>;
    var own = vec4<u32>(0u);
    for (var j = 0u; j < ITEMS; j++) {
        let c = select(3u, (held.keys[j] >> shift) & 3u, l * ITEMS + j < n);
        bucket[j] = c;
        before[j] = own[c];
        own[c] += 1u;
    }
    let prefix = unpack_counts(rake_exclusive_scan(l, vec2<u32>(own.x | (own.y << 16u), own.z | (own.w << 16u))));
    let totals = unpack_counts(rake_total);
    var start = prefix + vec4<u32>(0u, totals.x, totals.x + totals.y, totals.x + totals.y + totals.z);
    // Every read of the block happened before the scan's first barrier.
    for (var j = 0u; j < ITEMS; j++) {
        let at = start[bucket[j]] + before[j];
        block_keys[at] = held.keys[j];
        block_vals[at] = held.vals[j];
    }
    workgroupBarrier();
    return hold(l);
}

// The block's kept pairs moved to its first places, in order (a culling pass, or the last
// block, whose places past the pass's pairs hold nothing); their count.
fn compact(l: u32, held: Held, n: u32) -> u32 {
    var keep: array<bool, ITEMS>;
    var own = 0u;
    for (var j = 0u; j < ITEMS; j++) {
        keep[j] = l * ITEMS + j < n && (sp.cull == 0u || held.vals[j] != CULLED);
        own += u32(keep[j]);
    }
    var at = rake_exclusive_scan(l, vec2<u32>(own, 0u)).x;
    let total = rake_total.x;
    for (var j = 0u; j < ITEMS; j++) {
        if (keep[j]) {
            block_keys[at] = held.keys[j];
            block_vals[at] = held.vals[j];
            at += 1u;
        }
    }
    workgroupBarrier();
    return total;
}

// The block sorted on the pass's digit in workgroup memory (RADIX_BITS / 2 stable splits, after
// the kept pairs are moved to the front), then each pair written to its digit's start in the
// output (hist, scanned) + its place among the block's pairs of that digit. Blocks and the
// pairs within a block keep their input order within a digit, so the sort is stable.
@compute @workgroup_size(WG, 1, 1)
fn scatter(
    @builtin(local_invocation_index) l: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let block = block_of(wg);
    if (block >= sp.blocks) {
        return;
    }
    let first = block * BLOCK;
    for (var k = 0u; k < ITEMS; k++) {
        let i = first + k * WG + l;
        if (i < sp.count) {
            block_keys[k * WG + l] = key_in_at(i);
            block_vals[k * WG + l] = val_in_at(i);
        }
    }
    // RADIX = WG: one digit an invocation.
    digit_out[l] = hist_at(l * sp.blocks + block);
    workgroupBarrier();
    var held = hold(l);
    var n = min(sp.count - first, BLOCK);
    if (sp.cull != 0u || n < BLOCK) {
        n = compact(l, held, n);
        held = hold(l);
    }
    for (var b = 0u; b < RADIX_BITS; b += 2u) {
        held = split(l, held, n, sp.shift + b);
    }
    for (var j = 0u; j < ITEMS; j++) {
        let at = l * ITEMS + j;
        let d = digit(held.keys[j]);
        if (at < n && (at == 0u || digit(block_keys[at - 1u]) != d)) {
            digit_first[d] = at;
        }
    }
    workgroupBarrier();
    for (var k = 0u; k < ITEMS; k++) {
        let at = k * WG + l;
        if (at < n) {
            let key = block_keys[at];
            let d = digit(key);
            let out = digit_out[d] + at - digit_first[d];
            key_out_set(out, key);
            val_out_set(out, block_vals[at]);
        }
    }
}
