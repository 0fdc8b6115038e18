// Tile lists of the compute tile passes, the twin of splat_gpu raster/binning.rs: (tile, rank)
// pairs sorted by tile with rank order kept within a tile, each tile's range of pairs, and the
// batched walk of a tile's list that depth_pick.wgsl and rop.wgsl share. Part of the raster
// kernels (splat_gpu::RASTER_WGSL).

// Pairs per rank, then their exclusive scan: where rank r's pairs start (`offset_at(r)`,
// `offset_set`, binding 7); the pairs' tiles and ranks (`pair_tile_at`, `pair_rank_at` and
// their setters, bindings 8 and 9): split over more bindings by splat_gpu::RasterSplit, as the
// sort cuts them.
// Per tile, the range [x, y) of its pairs.
@group(0) @binding(10) var<storage, read_write> ranges: array<vec2<u32>>;

// Ranks to bin: the visible splats (the draw arguments' instance count), in depth order or in
// the shuffled draw order of the raster operations of tile_rop, each sort dropping the culled
// ones.
fn drawn() -> u32 {
    return atomicLoad(&draw_args[1]);
}

// Whether a splat survived culling (a culled one has an empty rect).
fn visible(s: Splat) -> bool {
    return s.rect.x < s.rect.z && s.rect.y < s.rect.w;
}

fn tile_rect(s: Splat) -> vec4<u32> {
    return vec4<u32>(s.rect.x / TILE, s.rect.y / TILE, (s.rect.z - 1u) / TILE, (s.rect.w - 1u) / TILE);
}

@compute @workgroup_size(256, 1, 1)
fn tile_count(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let r = flat_index(gid, groups);
    if (r > params.count) {
        return;
    }
    var n = 0u;
    if (r < drawn()) {
        let s = splat_at(order_at(r));
        let t = tile_rect(s);
        n = select(0u, (t.z - t.x + 1u) * (t.w - t.y + 1u), visible(s));
    }
    offset_set(r, n); // offset count stays 0: after the scan it holds the total
}

@compute @workgroup_size(256, 1, 1)
fn tile_emit(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let r = flat_index(gid, groups);
    if (r >= drawn() || !visible(splat_at(order_at(r)))) {
        return;
    }
    let t = tile_rect(splat_at(order_at(r)));
    var at = offset_at(r);
    for (var ty = t.y; ty <= t.w; ty++) {
        for (var tx = t.x; tx <= t.z; tx++) {
            pair_tile_set(at, ty * params.tiles.x + tx);
            pair_rank_set(at, r);
            at++;
        }
    }
}

@compute @workgroup_size(256, 1, 1)
fn tile_ranges(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    let total = offset_at(params.count);
    if (i >= total) {
        return;
    }
    let tile = pair_tile_at(i);
    if (i == 0u || pair_tile_at(i - 1u) != tile) {
        ranges[tile].x = i;
    }
    if (i + 1u == total || pair_tile_at(i + 1u) != tile) {
        ranges[tile].y = i + 1u;
    }
}

// The mesh pre-pass's distance where a pixel has no mesh (bvh.wgsl `FAR`).
const FAR_DEPTH: f32 = 3.0e38;
const BATCH: u32 = 128u;
var<workgroup> batch: array<Splat, 128>;
var<workgroup> tile_range: vec2<u32>;

// The range of pairs of the workgroup's tile, the same for every invocation (a storage load is
// not uniform to WGSL; the tile loops' barriers need a uniform bound).
fn tile_pairs(tile: u32, l: u32) -> vec2<u32> {
    if (l == 0u) {
        tile_range = ranges[tile];
    }
    return workgroupUniformLoad(&tile_range);
}

// Pairs [start, min(start + BATCH, end)) of the tile's list into `batch`, one per invocation.
fn load_batch(start: u32, end: u32, l: u32) {
    if (l < BATCH && start + l < end) {
        batch[l] = splat_at(order_at(pair_rank_at(start + l)));
    }
    workgroupBarrier();
}
