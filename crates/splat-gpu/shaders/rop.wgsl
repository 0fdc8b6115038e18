// Enderton and Laine–Karras on the GPU, the twin of splat_gpu raster/rop.rs: the raster
// operations of one pixel, in draw order. Part of the raster kernels (splat_gpu::RASTER_WGSL).
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
// This dispatch's chunk of every tile's lists: (index, length, count, triangle chunks). The
// transparent triangles' lists come first (chunks 0 .. w), then the splats' (chunks w .. z).
// lavapipe stops a shader invocation's loops after 65,535 iterations in all, so the host cuts
// the lists into chunks that stay below it (one chunk of each on other adapters).
@group(0) @binding(23) var<storage, read> rop_chunk: vec4<u32>;
// Every triangle of the meshes in the meshes' order (entry o: the triangle of place o), and
// their materials: a transparent triangle is a fragment of the raster operations (raster/mod.rs
// `triangle_fragments`), drawn before the splats in that order.
@group(0) @binding(26) var<storage, read> rop_triangles: array<Triangle>;
@group(0) @binding(27) var<storage, read> rop_materials: array<MeshMaterial>;
// Each tile's transparent triangles (splat_gpu raster/rop.rs `TriangleLists`): words 2 t and
// 2 t + 1 bound tile t's entries, which follow the header, three words each: a place in the
// meshes' order (ascending) and the pixel rect the triangle may reach, x0 | x1 << 16 and
// y0 | y1 << 16, inclusive.
@group(0) @binding(28) var<storage, read> rop_triangle_lists: array<u32>;

// Reserved ids of the hashes (raster/mod.rs ORDER_ID, SURFACE_ID) and Enderton's ξ slot.
const ORDER_ID: u32 = 4294967293u;
const SURFACE_ID: u32 = 4294967292u;
const ENDERTON_XI_SLOT: u32 = 64u;
// What a sample holds where a mesh was drawn (raster/mod.rs MESH).
const MESH: u32 = 4294967294u;
// The bit of a transparent triangle's id, its place in the meshes' order below it (raster/mod.rs
// TRIANGLE).
const TRIANGLE: u32 = 2147483648u;
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
// xxhash32(id, seed) (ties by id: the sort is stable and the values start in id order); the
// culled ones get the value NONE, which the sort drops (they touch no tile, so the visible ones
// keep the CPU's order).
@compute @workgroup_size(256, 1, 1)
fn shuffle_keys(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if (i >= params.count) {
        return;
    }
    let seed = xxhash32(vec3<u32>(rop_frame.key, ORDER_ID, 0u));
    depth_key_set(i, xxhash32(vec3<u32>(i, seed, 0u)));
    order_set(i, select(NONE, i, visible(splat_at(i))));
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

// raster/mod.rs `resolve`: the mean of the samples (colour, written share) of the pixel at
// `corner`, entry `pixel` of the image. A written sample shows its splat's colour, lit where the
// scene is (`lit_color` without a hybrid: at the sample's depth along the sample's own ray, with
// the splat's normal along sample 0's ray, no shadows); a sample holding its mesh shows the
// pre-pass's colour and counts as written; an empty one shows the background.
fn resolve_rop(rop: ptr<function, Rop>, spp: u32, corner: vec2<f32>, pixel: u32) -> vec4<f32> {
    let origin = camera_origin();
    let ray0 = pixel_dir(corner + rop_offsets[0]);
    var color = vec3<f32>(0.0);
    var written = 0u;
    for (var i = 0u; i < spp; i++) {
        let id = (*rop).id[i];
        if (id == NONE) {
            color += params.background.xyz;
        } else if (id == MESH) {
            color += behind[pixel * spp + i].xyz;
            written++;
        } else if ((id & TRIANGLE) != 0u) {
            color += triangle_color(id & ~TRIANGLE, sample_ray(corner, i));
            written++;
        } else {
            var c = splat_at(id).color;
            if (params.lit == 1u) {
                let n = splat_normal(id, origin, ray0);
                c = shade_unshadowed(c, id, origin, pixel_dir(corner + rop_offsets[i]), (*rop).t[i], n);
            }
            color += c;
            written++;
        }
    }
    return vec4<f32>(color, f32(written)) / f32(spp);
}

// The ray through sample i of the pixel at `corner` (the mesh pre-pass's, raster/mod.rs
// `Rasterizer::pixel`).
fn sample_ray(corner: vec2<f32>, i: u32) -> Ray {
    return Ray(camera_origin(), pixel_dir(corner + rop_offsets[i]), params.cam_row2.xyz, params.t_min, params.t_max);
}

// raster/mod.rs `surface_color` of the triangle of place `o` on `ray` (forward-shaded: lit
// without shadows, its mirror and glass shares seeing the background); black where the ray
// misses it.
fn triangle_color(o: u32, ray: Ray) -> vec3<f32> {
    let tri = rop_triangles[o];
    let h = triangle_intersect(tri, ray);
    if (h.x < 0.0 || !(h.x < ray.t_max)) {
        return vec3<f32>(0.0);
    }
    let m = rop_materials[tri.mesh];
    let n = facing_normal(tri, h.y, h.z, ray.dir);
    let lit = shade_material_unshadowed(m.shading, m.color, ray.origin, ray.dir, h.x, n);
    return local_share(m) * lit + background_share(m, clamp(-dot(ray.dir, n), 0.0, 1.0)) * params.background.xyz;
}

// raster/mod.rs `triangle_fragments` and `surviving` for the transparent triangle of place `o`:
// the samples of the pixel at `corner` whose rays cross it (each shared edge once) in front of
// what they hold, with their depths, into rop.alive[..m]; returns (m, their mask, its alpha at
// the ray through the pixel's centre, as bits; 0 where it draws nothing).
fn triangle_surviving(rop: ptr<function, Rop>, o: u32, corner: vec2<f32>, spp: u32) -> vec3<u32> {
    let tri = rop_triangles[o];
    let id = TRIANGLE | o;
    var m = 0u;
    var mask = 0u;
    var crossed = false;
    for (var i = 0u; i < spp; i++) {
        let h = triangle_crosses(tri, sample_ray(corner, i));
        if (h.x < 0.0) {
            continue;
        }
        crossed = true;
        if (depth_before(h.x, id, (*rop).t[i], (*rop).id[i])) {
            (*rop).alive[m] = i;
            (*rop).alive_t[m] = h.x;
            m++;
            mask |= 1u << i;
        }
    }
    var alpha = 0.0;
    if (crossed) {
        let centre = Ray(camera_origin(), pixel_dir(corner + vec2<f32>(0.5)), params.cam_row2.xyz, params.t_min, params.t_max);
        let b = plane_barycentrics(tri, centre);
        alpha = select(tri.alpha0, alpha_at(tri, b.x, b.y), b.z > 0.0);
    }
    return vec3<u32>(m, mask, bitcast<u32>(alpha));
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
fn rop_u(pixel_key: u32, id: u32, slot: u32) -> f32 {
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, id, slot)))) - rop_frame.u_shift;
}

// raster/mod.rs `enderton`: R = ⌊α m + ξ⌋ of the m survivors, by a partial Fisher–Yates.
fn enderton(rop: ptr<function, Rop>, m: u32, alpha: f32, id: u32, pixel_key: u32) {
    let xi = rop_u(pixel_key, id, ENDERTON_XI_SLOT);
    let r = min(u32(floor(alpha * f32(m) + xi)), m);
    for (var j = 0u; j < r; j++) {
        let u = rop_u(pixel_key, id, ENDERTON_XI_SLOT + 1u + j);
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

// The raster operations of one fragment of id `id` whose m surviving samples (bits `mask`) are
// in rop.alive: Enderton's or stratified's.
fn draw_fragment(rop: ptr<function, Rop>, m: u32, mask: u32, alpha: f32, id: u32, pixel_key: u32, pixel_id: u32) {
    if (params.mode == MODE_ENDERTON) {
        enderton(rop, m, alpha, id, pixel_key);
    } else {
        stratified(rop, m, mask, alpha, id, pixel_id);
    }
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
    // This chunk of the tile's triangle list or of its splat list (an empty range for the other).
    let triangle_chunk = rop_chunk.x < rop_chunk.w;
    var triangles = vec2<u32>(0u);
    var range = vec2<u32>(0u);
    if (triangle_chunk) {
        let list = vec2<u32>(rop_triangle_lists[2u * tile], rop_triangle_lists[2u * tile + 1u]);
        let first = min(list.x + rop_chunk.x * rop_chunk.y, list.y);
        triangles = vec2<u32>(first, min(list.y, first + rop_chunk.y));
    } else {
        let tile_list = tile_pairs(tile, l);
        let first = min(tile_list.x + (rop_chunk.x - rop_chunk.w) * rop_chunk.y, tile_list.y);
        range = vec2<u32>(first, min(tile_list.y, first + rop_chunk.y));
    }
    let spp = params.samples;
    let pixel = px.y * params.size.x + px.x;
    let at = pixel * rop_words(spp);
    var rop = load_rop(at, spp, inside && rop_chunk.x > 0u);
    if (inside && params.meshes == 1u && rop_chunk.x == 0u) {
        // raster/mod.rs `sample_buffer`: each sample starts with its mesh's depth, so fragments
        // behind it fail the depth test.
        for (var i = 0u; i < spp; i++) {
            let t_mesh = behind[pixel * spp + i].w;
            if (t_mesh < FAR_DEPTH) {
                rop.t[i] = t_mesh;
                rop.id[i] = MESH;
            }
        }
    }
    let pixel_key = xxhash32(vec3<u32>(px.x, px.y, rop_frame.key));
    let pixel_id = hilbert_index(params.hilbert_order, px.x, px.y);
    // The transparent triangles first, in the meshes' order (raster/mod.rs `shuffle`).
    let entries = 2u * params.tiles.x * params.tiles.y;
    for (var k = triangles.x; k < triangles.y && inside; k++) {
        let at = entries + 3u * k;
        let xs = rop_triangle_lists[at + 1u];
        let ys = rop_triangle_lists[at + 2u];
        if (px.x < (xs & 0xffffu) || px.x > (xs >> 16u) || px.y < (ys & 0xffffu) || px.y > (ys >> 16u)) {
            continue;
        }
        let o = rop_triangle_lists[at];
        let alive = triangle_surviving(&rop, o, corner, spp);
        let alpha = bitcast<f32>(alive.z);
        if (alive.x == 0u || !(alpha > 0.0)) {
            continue;
        }
        draw_fragment(&rop, alive.x, alive.y, alpha, TRIANGLE | o, pixel_key, pixel_id);
    }
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
            draw_fragment(&rop, m, alive.y, alpha, s.id, pixel_key, pixel_id);
        }
        workgroupBarrier();
    }
    // The state goes on to the next chunk, or, for the hybrid's first hit, to `rop_first_hit`.
    if (inside && (rop_chunk.x + 1u < rop_chunk.z || params.first_hit != 0u)) {
        store_rop(&rop, at, spp);
    } else if (inside) {
        textureStore(rop_target, vec2<i32>(px), resolve_rop(&rop, spp, corner, pixel));
    }
}

// The hybrid pipeline's first hits from the raster operations' samples (raster/mod.rs
// `resolve` of Enderton or stratified in `Rasterizer::hybrid`): each written splat, opaque, with
// its unlit colour, T = 0, its normal along sample 0's ray, its depth along the sample's ray and
// its id; T = 1 where a mesh or nothing holds the sample (the ray tracer continues to the mesh or
// the background). Sample i of pixel p goes to entry p S + i of the tile pass's first-hit
// buffers (depth_pick.wgsl), filled as FIRST_HIT_ACCEPTED fills them.
@compute @workgroup_size(8, 8, 1)
fn rop_first_hit(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let pixel = gid.y * params.size.x + gid.x;
    let spp = params.samples;
    let at = pixel * rop_words(spp);
    let dir = pixel_dir(vec2<f32>(gid.xy) + rop_offsets[0]);
    for (var i = 0u; i < spp; i++) {
        let index = pixel * spp + i;
        let t = bitcast<f32>(rop_state[at + i]);
        let id = rop_state[at + spp + i];
        if (id == NONE || id == MESH) {
            write_first_hit(index, vec3<f32>(0.0), 1.0, vec3<f32>(0.0), -1.0, NONE);
        } else {
            write_first_hit(index, splat_at(id).color, 0.0, splat_normal(id, camera_origin(), dir), t, id);
        }
    }
}
