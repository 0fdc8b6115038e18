// Compute stages of the splatting path, each the twin of a function of
// crates/splat-core/src/raster: EWA projection and culling (project.rs), and the tile
// rasterizer that composites every pixel's sorted fragments front to back to pick the
// iso-opacity depth and splat (mod.rs, Rasterizer::sorted with Blend::Under).

// One particle in scene order (48 bytes), mirrored by splat_gpu::RasterParticle.
struct RasterParticle {
    mean: vec3<f32>,
    opacity: f32,
    // Covariance Σ = R S² Rᵀ: (xx, xy, xz) and (yy, yz, zz).
    cov_a: vec3<f32>,
    pad0: f32,
    cov_b: vec3<f32>,
    pad1: f32,
}

@group(0) @binding(0) var<uniform> params: RasterParams;
@group(0) @binding(1) var<storage, read> particles: array<RasterParticle>;
@group(0) @binding(2) var<storage, read> sh: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> splats: array<Splat>;
// Depth sort: keys (depth bits, NONE when culled) and values (particle ids); after the sort,
// `order[r]` is the particle of rank r.
@group(0) @binding(4) var<storage, read_write> depth_keys: array<u32>;
@group(0) @binding(5) var<storage, read_write> order: array<u32>;
// Indirect draw arguments (vertex count, instance count = visible splats, 0, 0).
@group(0) @binding(6) var<storage, read_write> draw_args: array<atomic<u32>, 4>;

const NEAR: f32 = 0.2;
const DILATION: f32 = 0.3;
const TILE: u32 = 16u;

fn flat_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * 256u + gid.x;
}

fn cull(i: u32) {
    splats[i].rect = vec4<u32>(0u);
    depth_keys[i] = NONE;
    order[i] = i;
}

// project.rs `project`: Σ′ = J W Σ Wᵀ Jᵀ + 0.3 I, the rect of the extent, the SH colour from the camera
// centre, and the sort key; culled particles get the key NONE and sort behind all others.
@compute @workgroup_size(256, 1, 1)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if (i >= params.count) {
        return;
    }
    cull(i);
    let p = particles[i];
    if (p.opacity < params.alpha_cull) {
        return;
    }
    let r0 = params.cam_row0.xyz;
    let r1 = params.cam_row1.xyz;
    let r2 = params.cam_row2.xyz;
    let t = vec3<f32>(dot(r0, p.mean), dot(r1, p.mean), dot(r2, p.mean)) + params.cam_translation.xyz;
    if (!(t.z > NEAR)) {
        return;
    }
    let fx = params.intrinsics.x;
    let fy = params.intrinsics.y;
    let tx = clamp(t.x / t.z, -params.guard.x, params.guard.x) * t.z;
    let ty = clamp(t.y / t.z, -params.guard.y, params.guard.y) * t.z;
    // Rows of J W (2 × 3).
    let jw0 = (fx / t.z) * r0 - (fx * tx / (t.z * t.z)) * r2;
    let jw1 = (fy / t.z) * r1 - (fy * ty / (t.z * t.z)) * r2;
    let sigma = mat3x3<f32>(
        vec3<f32>(p.cov_a.x, p.cov_a.y, p.cov_a.z),
        vec3<f32>(p.cov_a.y, p.cov_b.x, p.cov_b.y),
        vec3<f32>(p.cov_a.z, p.cov_b.y, p.cov_b.z),
    );
    let s0 = sigma * jw0;
    let s1 = sigma * jw1;
    let a = dot(jw0, s0) + DILATION;
    let b = dot(jw0, s1);
    let c = dot(jw1, s1) + DILATION;
    let det = a * c - b * b;
    if (!(det > 0.0) || det > 3.0e38) {
        return;
    }
    let mean = vec2<f32>(fx * t.x / t.z + params.intrinsics.z, fy * t.y / t.z + params.intrinsics.w);
    let mid = 0.5 * (a + c);
    let lambda_max = mid + sqrt(max(mid * mid - det, EIGEN_FLOOR));
    let radius = ceil(BOX_SIGMAS * sqrt(lambda_max));
    var rx = radius;
    var ry = radius;
    if (params.extent == EXTENT_SQRT8) {
        rx = sqrt(EXTENT_SQ * a);
        ry = sqrt(EXTENT_SQ * c);
    }
    let size = vec2<f32>(params.size);
    let lo = max(floor(mean - vec2<f32>(rx, ry)), vec2<f32>(0.0));
    let hi = min(ceil(mean + vec2<f32>(rx, ry)), size);
    if (!(lo.x < hi.x && lo.y < hi.y)) {
        return;
    }
    // R t is the world-to-camera rotation of the mean, so the camera centre is −Rᵀ t_cam.
    let tr = params.cam_translation.xyz;
    let center = -(tr.x * r0 + tr.y * r1 + tr.z * r2);
    let v = p.mean - center;
    var dir = vec3<f32>(0.0);
    if (dot(v, v) > 0.0) {
        dir = normalize(v);
    }
    var s: Splat;
    s.mean = mean;
    s.depth = t.z;
    s.opacity = p.opacity;
    s.conic = vec3<f32>(c / det, -b / det, a / det);
    s.id = i;
    s.color = sh_eval(i, params.sh_degree, dir);
    s.radius = radius;
    s.rect = vec4<u32>(vec2<u32>(lo), vec2<u32>(hi));
    splats[i] = s;
    depth_keys[i] = bitcast<u32>(t.z);
    atomicAdd(&draw_args[1], 1u);
}

// ---- tile binning: (tile, rank) pairs, sorted by tile, rank order kept within a tile --------

// Pairs per rank, then their exclusive scan: where rank r's pairs start.
@group(0) @binding(7) var<storage, read_write> offsets: array<u32>;
@group(0) @binding(8) var<storage, read_write> pair_tiles: array<u32>;
@group(0) @binding(9) var<storage, read_write> pair_ranks: array<u32>;
// Per tile, the range [x, y) of its pairs.
@group(0) @binding(10) var<storage, read_write> ranges: array<vec2<u32>>;
// Per pixel: colour + coverage of front-to-back compositing, and (depth bits, picked id).
@group(0) @binding(11) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read_write> out_pick: array<vec2<u32>>;
// Per pixel: the integrated unit normal (zero where no fragment, w unused).
@group(0) @binding(16) var<storage, read_write> out_normal: array<vec4<f32>>;
// The mesh pre-pass (mesh_prepass.wgsl): colour and distance, and the mesh's normal, per pixel;
// read where params.meshes is 1.
@group(0) @binding(17) var<storage, read> behind: array<vec4<f32>>;
@group(0) @binding(18) var<storage, read> behind_normal: array<vec4<f32>>;

// Ranks to bin: the visible splats in depth order, or every particle in a shuffled draw order
// (the raster operations of tile_rop; the culled ones touch no tile).
fn drawn() -> u32 {
    if (params.mode >= MODE_ENDERTON) {
        return params.count;
    }
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
        let s = splats[order[r]];
        let t = tile_rect(s);
        n = select(0u, (t.z - t.x + 1u) * (t.w - t.y + 1u), visible(s));
    }
    offsets[r] = n; // offsets[count] stays 0: after the scan it holds the total
}

@compute @workgroup_size(256, 1, 1)
fn tile_emit(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let r = flat_index(gid, groups);
    if (r >= drawn() || !visible(splats[order[r]])) {
        return;
    }
    let t = tile_rect(splats[order[r]]);
    var at = offsets[r];
    for (var ty = t.y; ty <= t.w; ty++) {
        for (var tx = t.x; tx <= t.z; tx++) {
            pair_tiles[at] = ty * params.tiles.x + tx;
            pair_ranks[at] = r;
            at++;
        }
    }
}

@compute @workgroup_size(256, 1, 1)
fn tile_ranges(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    let total = offsets[params.count];
    if (i >= total) {
        return;
    }
    let tile = pair_tiles[i];
    if (i == 0u || pair_tiles[i - 1u] != tile) {
        ranges[tile].x = i;
    }
    if (i + 1u == total || pair_tiles[i + 1u] != tile) {
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
        batch[l] = splats[order[pair_ranks[start + l]]];
    }
    workgroupBarrier();
}

// One workgroup per 16 × 16 tile, one invocation per pixel, walking the tile's splats in depth
// order in batches loaded cooperatively into workgroup memory (the 3DGS rasterizer's loop).
//
// Why a compute pass and not the raster pipeline: front-to-back blending gives the colour, but
// the iso-opacity depth needs the transmittance *before and after* each fragment, in order,
// which a fixed-function blend cannot return and a fragment shader can only read back through
// a storage image under fragment-shader interlock (what vk_gaussian_splatting does). wgpu has
// no interlock, and without it the read-modify-write of overlapping fragments races. Here one
// invocation owns its pixel and walks the fragments sequentially in the global depth order, so
// the depth and picked splat are exact, the same (depth, id) order as the CPU reference.
@compute @workgroup_size(16, 16, 1)
fn tile_blend(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) l: u32,
) {
    let tile = wg.y * params.tiles.x + wg.x;
    let px = wg.xy * TILE + lid.xy;
    let inside = px.x < params.size.x && px.y < params.size.y;
    let centre = vec2<f32>(px) + vec2<f32>(0.5);
    let range = tile_pairs(tile, l);
    var transmittance = 1.0;
    var color = vec3<f32>(0.0);
    var depth = 0.0;
    var picked = NONE;
    // The pixel-centre ray, and the integrated normal Σ nᵢ αᵢ Tᵢ.
    let origin = camera_origin();
    let dir = pixel_dir(centre);
    let to_t = stretch(centre);
    var normal = vec3<f32>(0.0);
    // What lies behind (raster/mod.rs `Rasterizer::behind`): the background, or the pixel's
    // mesh, which hides the fragments at or behind it (the depth test of the splat pass).
    var back = vec4<f32>(params.background.xyz, FAR_DEPTH);
    if (inside && params.meshes == 1u) {
        back = behind[px.y * params.size.x + px.x];
    }
    let mesh = back.w < FAR_DEPTH;
    for (var start = range.x; start < range.y; start += BATCH) {
        load_batch(start, range.y, l);
        let n = min(BATCH, range.y - start);
        for (var j = 0u; j < n; j++) {
            let s = batch[j];
            let in_rect = all(px >= s.rect.xy) && all(px < s.rect.zw);
            if (inside && in_rect && s.depth * to_t < back.w) {
                let alpha = splat_alpha(s, centre, params);
                if (alpha > 0.0) {
                    var c = s.color;
                    let n = splat_normal(s.id, origin, dir);
                    if (params.lit == 1u && params.look == LOOK_VOLUMETRIC) {
                        c = shade_unshadowed(s.color, s.id, origin, dir, s.depth * to_t, n);
                    }
                    normal += transmittance * alpha * n;
                    color += transmittance * alpha * c;
                    transmittance *= 1.0 - alpha;
                    if (picked == NONE && transmittance < params.iso_threshold) {
                        picked = s.id;
                        depth = s.depth;
                    }
                }
            }
        }
        workgroupBarrier();
    }
    if (inside) {
        let index = px.y * params.size.x + px.x;
        let covered = select(0.0, 1.0, mesh);
        var out = vec4<f32>(color + transmittance * back.xyz, 1.0 - transmittance + transmittance * covered);
        // raster/mod.rs `sorted`: the integrated normal normalised, −dir when degenerate; the
        // depth as a distance along the pixel-centre ray, t = z |d_cam|, where T fell below the
        // threshold, else the mesh's (depth consolidation, vk_gaussian_splatting Lighting §1.5.3).
        var n = normal;
        if (any(n != vec3<f32>(0.0))) {
            let rcp = 1.0 / length(n);
            n = select(-dir, n * rcp, rcp > 0.0 && rcp < 3.0e38);
        }
        var t = -1.0;
        if (params.first_hit == 1u) {
            // The hybrid pipeline lights and continues from this in the ray tracer.
            out_color[index] = vec4<f32>(color, transmittance);
            out_normal[index] = vec4<f32>(n, 0.0);
            out_pick[index] = vec2<u32>(bitcast<u32>(select(-1.0, depth * to_t, picked != NONE)), picked);
            return;
        }
        if (picked != NONE) {
            t = depth * to_t;
        } else if (mesh) {
            t = back.w;
            n = behind_normal[index].xyz;
        }
        if (params.lit == 1u && params.look == LOOK_SURFACE) {
            // raster/mod.rs `light_surface`: L lit once at the picked depth with the integrated
            // normal and the picked splat's material; what lies behind (the mesh's normal and
            // depth, or the background and no normal) where T stayed above the threshold.
            if (picked == NONE) {
                out = vec4<f32>(back.xyz, covered);
                n = select(vec3<f32>(0.0), n, mesh);
            } else {
                let lit = shade_unshadowed(color, picked, origin, dir, depth * to_t, n);
                out = vec4<f32>(lit + transmittance * back.xyz, out.w);
            }
        }
        out_color[index] = out;
        out_normal[index] = vec4<f32>(n, 0.0);
        out_pick[index] = vec2<u32>(bitcast<u32>(t), picked);
    }
}

// ---- Enderton and Laine–Karras: the raster operations of one pixel, in draw order -----------
//
// Both methods decide a fragment's samples from the pixel's state before it: Enderton et al.
// from the m covered samples that pass the depth test, Laine & Karras (Figure 7) also from the
// stored depth of each sample (line 9) and the surface's coverage bits (lines 4–8, 18). That is
// work for the raster-operations stage (Laine & Karras §5: "primarily targeted at hardware
// implementation ... best suited in ROP"); a fragment shader cannot read the depth attachment,
// and a storage image read-modify-write races between overlapping fragments without
// fragment-shader interlock, which wgpu lacks (the reason tile_blend exists). So here one
// invocation owns a pixel and plays its ROP: it walks the pixel's fragments in the frame's draw
// order (the shuffled tile lists), computes each fragment's sample mask exactly as
// raster/mod.rs `enderton` / `stratified` do, and applies it to the pixel's S samples.

// The frame's FrameParams (copied from its slot before the frame's dispatches).
@group(0) @binding(19) var<storage, read> rop_frame: FrameParams;
// Sub-pixel position of sample i in [0, 1)² (params.samples of them).
@group(0) @binding(20) var<storage, read> rop_offsets: array<vec2<f32>>;
// The frame's resolved colour and coverage, folded by fold.wgsl.
@group(0) @binding(21) var rop_target: texture_storage_2d<rgba32float, write>;
// Each pixel's raster-operation state between the chunks of its tile list: depth bits and id
// of every sample, the surface's coverage and id (2 S + 2 words).
@group(0) @binding(22) var<storage, read_write> rop_state: array<u32>;
// This dispatch's chunk of every tile's list: (index, length, count). lavapipe stops a shader
// invocation's loops after 65,535 iterations in all, so the host cuts the lists into chunks
// that stay below it (one chunk on other adapters).
@group(0) @binding(23) var<uniform> rop_chunk: vec4<u32>;

// Reserved ids of the hashes (raster/mod.rs ORDER_ID, SURFACE_ID) and Enderton's ξ slot.
const ORDER_ID: u32 = 4294967293u;
const SURFACE_ID: u32 = 4294967292u;
const ENDERTON_XI_SLOT: u32 = 64u;
const MODE_ENDERTON: u32 = 3u;
const MODE_STRATIFIED: u32 = 4u;
const MODE_STRATIFIED_PLAIN: u32 = 5u;
// Most samples the ROP kernel holds per pixel (the standard pattern's largest).
const ROP_SAMPLES: u32 = 16u;
const EMPTY_DEPTH: f32 = 3.4028235e38;
// 1: fragments lie at the max-density point along each sample's ray (FragmentDepth::
// MaxDensityPlane), 0: on the billboard through the centre.
override PLANE_DEPTH: u32 = 0u;

// raster/mod.rs `Rasterizer::depth`: distance along the ray through pixel position p.
fn fragment_depth(s: Splat, p: vec2<f32>) -> f32 {
    if (PLANE_DEPTH == 1u) {
        return plane_depth(s.id, camera_origin(), pixel_dir(p));
    }
    return s.depth * stretch(p);
}

// raster/mod.rs `Rasterizer::shuffle`: the frame's draw order, every particle keyed by
// xxhash32(id, seed) (ties by id: the sort is stable and the values start in id order); culled
// particles are drawn too (their rect is empty, they touch no tile).
@compute @workgroup_size(256, 1, 1)
fn shuffle_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if (i >= params.count) {
        return;
    }
    let seed = xxhash32(vec3<u32>(rop_frame.key, ORDER_ID, 0u));
    depth_keys[i] = xxhash32(vec3<u32>(i, seed, 0u));
    order[i] = i;
}

// rng.rs `hilbert_index`: cell (x, y)'s index along the Hilbert curve of order `order`.
fn hilbert_index(order_bits: u32, x0: u32, y0: u32) -> u32 {
    let n = 1u << order_bits;
    var x = x0;
    var y = y0;
    var d = 0u;
    for (var s = n >> 1u; s > 0u; s >>= 1u) {
        let rx = select(0u, 1u, (x & s) != 0u);
        let ry = select(0u, 1u, (y & s) != 0u);
        d += s * s * ((3u * rx) ^ ry);
        if (ry == 0u) {
            if (rx == 1u) {
                x = n - 1u - x;
                y = n - 1u - y;
            }
            let swap = x;
            x = y;
            y = swap;
        }
    }
    return d;
}

// rng.rs `calc_alpha_ref` (Laine & Karras 2011, Figure 4).
fn calc_alpha_ref(sample_id: u32, pixel_id: u32, surface_id: u32, spp: u32, scramble: bool) -> f32 {
    var x = reverseBits(sample_id + pixel_id * spp) + surface_id;
    if (scramble) {
        x ^= x * 0x6C50B47Cu;
        x ^= x * 0xB82F1E52u;
        x ^= x * 0xC7AFE638u;
        x ^= x * 0x8D22F6E6u;
    }
    return unit_f32(x);
}

// The state of one pixel (raster/mod.rs `SampleBuffer` and the locals of `stratified`): depth and
// id (= scene index) of the nearest written fragment of each sample, the surviving samples of
// the fragment being drawn with their depths, and the current surface's coverage bits and id.
struct Rop {
    t: array<f32, 16>,
    id: array<u32, 16>,
    alive: array<u32, 16>,
    alive_t: array<f32, 16>,
    covered: u32,
    surface: u32,
}

// Words of rop_state per pixel: depth bits and id of each sample, coverage and surface id.
fn rop_words(spp: u32) -> u32 {
    return 2u * spp + 2u;
}

// The pixel's state at the start of this chunk: empty samples and the frame's first surface id
// for the first chunk, else what the previous chunk stored at `at`.
fn load_rop(at: u32, spp: u32, resume: bool) -> Rop {
    var rop: Rop;
    rop.surface = xxhash32(vec3<u32>(rop_frame.key, SURFACE_ID, 0u));
    for (var i = 0u; i < spp; i++) {
        rop.t[i] = EMPTY_DEPTH;
        rop.id[i] = NONE;
        if (resume) {
            rop.t[i] = bitcast<f32>(rop_state[at + i]);
            rop.id[i] = rop_state[at + spp + i];
        }
    }
    if (resume) {
        rop.covered = rop_state[at + 2u * spp];
        rop.surface = rop_state[at + 2u * spp + 1u];
    }
    return rop;
}

// Keep the pixel's state for the next chunk.
fn store_rop(rop: ptr<function, Rop>, at: u32, spp: u32) {
    for (var i = 0u; i < spp; i++) {
        rop_state[at + i] = bitcast<u32>((*rop).t[i]);
        rop_state[at + spp + i] = (*rop).id[i];
    }
    rop_state[at + 2u * spp] = (*rop).covered;
    rop_state[at + 2u * spp + 1u] = (*rop).surface;
}

// raster/mod.rs `resolve`: the mean of the samples (colour, written share), the background
// where none was written.
fn resolve_rop(rop: ptr<function, Rop>, spp: u32) -> vec4<f32> {
    var color = vec3<f32>(0.0);
    var written = 0u;
    for (var i = 0u; i < spp; i++) {
        if ((*rop).id[i] == NONE) {
            color += params.background.xyz;
        } else {
            color += splats[(*rop).id[i]].color;
            written++;
        }
    }
    return vec4<f32>(color, f32(written)) / f32(spp);
}

// Lines 1–3 of Figure 7 (and Enderton's depth test): the samples of the pixel at `corner` that
// splat s covers and whose stored fragment lies behind it, with their depths, into
// rop.alive[..m]; returns (m, their mask).
fn surviving(rop: ptr<function, Rop>, s: Splat, corner: vec2<f32>, spp: u32) -> vec2<u32> {
    var m = 0u;
    var mask = 0u;
    for (var i = 0u; i < spp; i++) {
        let p = corner + rop_offsets[i];
        let t = fragment_depth(s, p);
        if (covers(s, p, params) && depth_before(t, s.id, (*rop).t[i], (*rop).id[i])) {
            (*rop).alive[m] = i;
            (*rop).alive_t[m] = t;
            m++;
            mask |= 1u << i;
        }
    }
    return vec2<u32>(m, mask);
}

// frame.rs `depth_before`: (t, id) strictly in front of (other_t, other_id).
fn depth_before(t: f32, id: u32, other_t: f32, other_id: u32) -> bool {
    return t < other_t || (t == other_t && id < other_id);
}

// u ∈ [0, 1) of splat `id` in slot `slot` (rng.rs `RayRng::particle`, hash scheme).
fn rop_u(pixel_seed: u32, id: u32, slot: u32) -> f32 {
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, id, slot)))) - rop_frame.u_shift;
}

// raster/mod.rs `enderton`: R = ⌊α m + ξ⌋ of the m survivors, by a partial Fisher–Yates.
fn enderton(rop: ptr<function, Rop>, m: u32, alpha: f32, id: u32, pixel_seed: u32) {
    let xi = rop_u(pixel_seed, id, ENDERTON_XI_SLOT);
    let r = min(u32(floor(alpha * f32(m) + xi)), m);
    for (var j = 0u; j < r; j++) {
        let u = rop_u(pixel_seed, id, ENDERTON_XI_SLOT + 1u + j);
        let pick = j + min(u32(u * f32(m - j)), m - j - 1u);
        let s = (*rop).alive[pick];
        let t = (*rop).alive_t[pick];
        (*rop).alive[pick] = (*rop).alive[j];
        (*rop).alive_t[pick] = (*rop).alive_t[j];
        (*rop).alive[j] = s;
        (*rop).alive_t[j] = t;
        (*rop).t[s] = t;
        (*rop).id[s] = id;
    }
}

// Whether sample a's stored (depth, id, index) orders before sample b's (SampleBuffer::cmp_stored).
fn stored_before(rop: ptr<function, Rop>, a: u32, b: u32) -> bool {
    let ta = (*rop).t[a];
    let tb = (*rop).t[b];
    if (ta != tb) {
        return ta < tb;
    }
    if ((*rop).id[a] != (*rop).id[b]) {
        return (*rop).id[a] < (*rop).id[b];
    }
    return a < b;
}

// raster/mod.rs `stratified`, lines 4–18 of Figure 7 for the m survivors (their bits `mask`):
// a conflict with the surface's coverage starts a new surface; the survivors sorted by their
// stored depth are tested against the surface's reference values, the sequence continuing
// where the surface left it.
fn stratified(rop: ptr<function, Rop>, m: u32, mask: u32, alpha: f32, id: u32, pixel_id: u32) {
    // Lines 4–7.
    if ((mask & (*rop).covered) != 0u) {
        (*rop).surface += 1u;
        (*rop).covered = 0u;
    }
    // Line 9.
    for (var a = 1u; a < m; a++) {
        let s = (*rop).alive[a];
        let t = (*rop).alive_t[a];
        var b = a;
        for (; b > 0u && stored_before(rop, s, (*rop).alive[b - 1u]); b--) {
            (*rop).alive[b] = (*rop).alive[b - 1u];
            (*rop).alive_t[b] = (*rop).alive_t[b - 1u];
        }
        (*rop).alive[b] = s;
        (*rop).alive_t[b] = t;
    }
    // Lines 8, 10–17.
    let scramble = params.mode == MODE_STRATIFIED;
    let first = countOneBits((*rop).covered);
    for (var j = 0u; j < m; j++) {
        let reference = calc_alpha_ref(first + j, pixel_id, (*rop).surface, params.samples, scramble);
        if (alpha > reference - rop_frame.u_shift) {
            let s = (*rop).alive[j];
            (*rop).t[s] = (*rop).alive_t[j];
            (*rop).id[s] = id;
        }
    }
    // Line 18.
    (*rop).covered |= mask;
}

@compute @workgroup_size(16, 16, 1)
fn tile_rop(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) l: u32,
) {
    let tile = wg.y * params.tiles.x + wg.x;
    let px = wg.xy * TILE + lid.xy;
    let inside = px.x < params.size.x && px.y < params.size.y;
    let corner = vec2<f32>(px);
    let centre = corner + vec2<f32>(0.5);
    let tile_list = tile_pairs(tile, l);
    // This chunk of the tile's list.
    let first = min(tile_list.x + rop_chunk.x * rop_chunk.y, tile_list.y);
    let range = vec2<u32>(first, min(tile_list.y, first + rop_chunk.y));
    let spp = params.samples;
    let at = (px.y * params.size.x + px.x) * rop_words(spp);
    var rop = load_rop(at, spp, inside && rop_chunk.x > 0u);
    let pixel_seed = xxhash32(vec3<u32>(px.x, px.y, rop_frame.key));
    let pixel_id = hilbert_index(params.hilbert_order, px.x, px.y);
    for (var start = range.x; start < range.y; start += BATCH) {
        load_batch(start, range.y, l);
        let n = min(BATCH, range.y - start);
        for (var j = 0u; j < n; j++) {
            let s = batch[j];
            if (!inside || !all(px >= s.rect.xy) || !all(px < s.rect.zw)) {
                continue;
            }
            let alpha = fragment_alpha(s, centre, params);
            if (alpha <= 0.0) {
                continue;
            }
            let alive = surviving(&rop, s, corner, spp);
            let m = alive.x;
            if (m == 0u) {
                continue;
            }
            if (params.mode == MODE_ENDERTON) {
                enderton(&rop, m, alpha, s.id, pixel_seed);
            } else {
                stratified(&rop, m, alive.y, alpha, s.id, pixel_id);
            }
        }
        workgroupBarrier();
    }
    if (inside && rop_chunk.x + 1u < rop_chunk.z) {
        store_rop(&rop, at, spp);
    } else if (inside) {
        textureStore(rop_target, vec2<i32>(px), resolve_rop(&rop, spp));
    }
}
