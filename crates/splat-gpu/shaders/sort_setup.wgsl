// The uniforms and workgroup counts of the radix sort's passes after the first, from a count
// the device holds (the visible splats the projection counted): the twin of
// splat_gpu::sort::RadixSort::write_pass_slots for those passes. One invocation.
//
// The host has written every slot for all `n` pairs (the first pass culls: it writes the
// visible pairs alone, packed, sorted on the first digit). This rewrites what the visible count changes:
// the later passes' count and blocks, the scan levels of their histogram, and each slot's
// workgroups (`args`, three words a slot, read by dispatch_workgroups_indirect). The levels'
// places in `partials` stay those of the n keys' levels, which hold the shorter ones.
//
// Declared before this by splat_gpu::sort: SLOT_WORDS (words a uniform slot), the word of
// each SortParams field (COUNT, BLOCKS, SCAN_LEN), LATER_LEVELS (the first slot of the later
// passes' levels), BLOCK, SCAN_TILE, RADIX, MAX_GROUPS_X.

struct Setup {
    // The visible keys, copied from where the device counted them.
    count: u32,
    // Passes of the sort.
    passes: u32,
    // Scan levels of each pass (those of the n keys' histogram).
    levels: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> setup: Setup;
@group(0) @binding(1) var<storage, read_write> slots: array<u32>;
@group(0) @binding(2) var<storage, read_write> args: array<u32>;

// Workgroups for `n` blocks or tiles in slot s: a row, or full rows of MAX_GROUPS_X.
fn set_groups(s: u32, n: u32) {
    args[3u * s] = min(n, MAX_GROUPS_X);
    args[3u * s + 1u] = select(1u, (n + MAX_GROUPS_X - 1u) / MAX_GROUPS_X, n > MAX_GROUPS_X);
    args[3u * s + 2u] = 1u;
}

@compute @workgroup_size(1, 1, 1)
fn sort_setup() {
    let count = setup.count;
    let blocks = (count + BLOCK - 1u) / BLOCK;
    for (var p = 1u; p < setup.passes; p++) {
        slots[p * SLOT_WORDS + COUNT] = count;
        slots[p * SLOT_WORDS + BLOCKS] = blocks;
        set_groups(p, blocks);
    }
    var len = RADIX * blocks;
    for (var i = 0u; i < setup.levels; i++) {
        let s = LATER_LEVELS + i;
        let tiles = (len + SCAN_TILE - 1u) / SCAN_TILE;
        slots[s * SLOT_WORDS + SCAN_LEN] = len;
        set_groups(s, tiles);
        len = tiles;
    }
}
