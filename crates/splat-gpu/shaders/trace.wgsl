// Ray tracing of transparent 3D Gaussians through a BVH (bvh.wgsl), every method of
// splat_core::trace, with stochastic.wgsl, kbuffer.wgsl and shadow.wgsl (the twins of
// trace/{stochastic,kbuffer,shadow}.rs). Each function mirrors its CPU twin in
// crates/splat-core/src/{hit,rng,trace/mod,frame}.rs; the decisions use the same counter-based
// hashes, so a GPU frame makes the CPU frame's choices.

// One particle in BVH leaf order (64 bytes), mirrored by splat_gpu::GpuParticle.
struct Particle {
    mean: vec3<f32>,
    opacity: f32,
    // Rows of the canonical transform M = S⁻¹ Rᵀ.
    row0: vec3<f32>,
    id: u32,
    row1: vec3<f32>,
    // Visible extent (kernel.rs `visible_extent`): the icosahedron proxy's inradius.
    extent: f32,
    row2: vec3<f32>,
    pad2: f32,
}

// Everything a dispatch needs (240 bytes), mirrored by splat_gpu::Params.
struct Params {
    cam_row0: vec4<f32>,
    cam_row1: vec4<f32>,
    cam_row2: vec4<f32>,
    cam_center: vec4<f32>,
    intrinsics: vec4<f32>, // fx, fy, cx, cy
    background: vec4<f32>,
    size: vec2<u32>,
    sh_degree: u32,
    method: u32,
    k: u32,
    max_passes: u32,
    n: u32,
    m: u32,
    seed: u32,
    frames: u32,
    rng_scheme: u32,
    hit_distance: u32,
    kernel_degree: u32,
    cutoff: f32,
    alpha_clamp: f32,
    alpha_cull: f32,
    t_min: f32,
    t_max: f32,
    min_transmittance: f32,
    first_frame: u32,
    // 0: whole frames per invocation; 1: one pass of frame first_frame (pass-per-dispatch).
    mode: u32,
    pass_index: u32,
    // splat_core::Frames::u_shift, a test hook: every u is drawn as u − u_shift (0 in renders).
    u_shift: f32,
    // Lighting (lighting.rs): 1 when a set reflects light (`Lighting::is_on`).
    lit: u32,
    // LOOK_SURFACE or LOOK_VOLUMETRIC.
    look: u32,
    // SHADOWS_*.
    shadows: u32,
    shadow_k: u32,
    shadow_threshold: f32,
    shadow_colored: f32,
    shadow_offset: f32,
    light_count: u32,
    set_count: u32,
    iso_threshold: f32,
    // Node index of the mesh BVH's root (after the splats' nodes), NONE without meshes.
    mesh_root: u32,
    // settings.rs `max_bounces`: mirror and glass bounces after the camera ray.
    max_bounces: u32,
    // The camera's lens (LENS_*) and its distortion (lens.wgsl).
    lens: u32,
    distortion: array<vec4<f32>, 3>,
    // camera_sampling.rs: FILTER_CENTER or FILTER_BOX, and the thin lens (aperture 0: none).
    pixel_filter: u32,
    aperture: f32,
    focus_distance: f32,
    // frame.rs AccumulationFormat (ACCUMULATION_*): how the running mean is stored.
    accumulation: u32,
    // normal.rs NormalMode (NORMAL_*).
    normal_mode: u32,
    // In MODE_HYBRID, the first hit the tile rasterizer wrote: FIRST_HIT_ACCEPTED for
    // StochasticSplats' closest accepted fragment, else sorted splatting's.
    first_hit: u32,
    // In MODE_HYBRID, the rasterizer's samples per pixel S: S first hits a pixel.
    raster_samples: u32,
    // splat_core::Frames::first: frame f of this render is frame run_first + f of the run,
    // whose key and camera sample it draws (a share of a longer run; 0 otherwise).
    run_first: u32,
}

// The state of one ray between passes (pass-per-dispatch mode), mirrored by splat_gpu::PassState:
// Eq. 3 so far, where the next pass starts, and for the surface look the integrated normal and
// the iso-opacity depth with its particle (trace/mod.rs `Integrator`).
struct PassState {
    radiance: vec3<f32>,
    transmittance: f32,
    after_t: f32,
    after_id: u32,
    flags: u32,
    picked: u32,
    normal: vec3<f32>,
    depth: f32,
}

// params.mode (splat_gpu::layout::MODE_*): whole frames per invocation, or one pass of one frame.
const MODE_FRAMES: u32 = 0u;
const MODE_PASS: u32 = 1u;
// Whole frames whose camera segment is the rasterized first hit in hybrid_in (the hybrid
// pipeline, vk_gaussian_splatting Lighting §5).
const MODE_HYBRID: u32 = 2u;
// params.first_hit (splat_gpu::layout::FIRST_HIT_*).
const FIRST_HIT_ACCEPTED: u32 = 2u;
const FIRST_HIT_FRAGMENTS: u32 = 4u;
const DONE: u32 = 1u;
const ACCEPTED: u32 = 2u;
// The ray met at least one hit (the integrated normal is defined).
const HIT: u32 = 4u;
// A hybrid sample of a pixel whose surface-look pick lies in sample 0: it adds only its
// transmittance times what lies behind it.
const BEHIND_ONLY: u32 = 8u;
// The method codes of splat_core's catalogue (MethodId::code; a test finds one for every
// method of the catalogue with a GPU kernel, named MethodId::wgsl_constant, and no other).
const METHOD_EXACT: u32 = 0u;
const METHOD_KBUFFER: u32 = 1u;
const METHOD_STOCHASTIC: u32 = 2u;
const METHOD_STOCHASTIC_N: u32 = 3u;
const METHOD_STOCHASTIC_PASS: u32 = 4u;
const METHOD_DEPTH_SAMPLING_K: u32 = 5u;
const MAX_HITS: u32 = 64u;
// params.rng_scheme (splat_gpu::layout::RNG_*) and params.hit_distance (HIT_*).
const RNG_HASH: u32 = 0u;
const RNG_TRIG: u32 = 1u;
const HIT_MEAN: u32 = 0u;
const HIT_CENTER: u32 = 1u;
const HIT_ICOSAHEDRON: u32 = 2u;
// hit.rs CENTER_VIEW_COS_MIN: the centre convention takes rays within 60° of the view axis.
const CENTER_VIEW_COS_MIN: f32 = 0.5;
// params.pixel_filter (splat_gpu::layout::FILTER_*) and camera_sampling.rs's FRAME_SOBOL_SALT.
const FILTER_CENTER: u32 = 0u;
const FILTER_BOX: u32 = 1u;
const FRAME_SOBOL_SALT: u32 = 0xca3e5a3fu;
const PASS_ID: u32 = 0xffffffffu;
const OFFSET_ID: u32 = 0xfffffffeu;
const LIGHT_ID: u32 = 0xfffffffbu;
// lighting.rs `Look` and `Shadows`.
const LOOK_SURFACE: u32 = 0u;
const LOOK_VOLUMETRIC: u32 = 1u;
const SHADOWS_NONE: u32 = 0u;
const SHADOWS_SORTED: u32 = 1u;
const SHADOWS_STOCHASTIC: u32 = 2u;
const SHADOWS_EXACT: u32 = 3u;
// trace/mod.rs `SURFACE_OFFSET`, `BOUNCE_SHIFT`, `SHADOW_BOUNCE_SHIFT`, `LAYER_PASS_SHIFT` and
// settings.rs `MAX_BOUNCES`.
const SURFACE_OFFSET: f32 = 1e-4;
const BOUNCE_SHIFT: u32 = 20u;
const SHADOW_BOUNCE_SHIFT: u32 = 26u;
const LAYER_PASS_SHIFT: u32 = 24u;
const MAX_BOUNCES: u32 = 15u;
// lavapipe (Mesa's CPU Vulkan driver) stops a loop after 65535 iterations of its SIMD loop per
// invocation (gallivm's loop limiter), silently: a ray that needs more would be cut short.
// Every loop body below starts with `iterations += 1u`; a loop statement cannot iterate more
// often than lanes × the busiest lane's total, which the host checks against the budget.
const LOOP_BUDGET: u32 = 65535u;

@group(0) @binding(0) var<storage, read> params: Params;
// Bindings 1–3, the particles, BVH nodes and SH coefficients, are declared by the host
// (splat_gpu::split) with their accessors particle_at, node_at and sh_at, over as many
// bindings as the scene needs (18 and up for the parts after the first).
@group(0) @binding(4) var<storage, read_write> out_mean: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_var: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> pass_state: array<PassState>;
@group(0) @binding(7) var<storage, read> materials: array<Material>;
@group(0) @binding(8) var<storage, read> lights: array<Light>;
@group(0) @binding(9) var<storage, read_write> out_pick: array<Pick>;
@group(0) @binding(10) var<storage, read> triangles: array<Triangle>;
@group(0) @binding(11) var<storage, read> mesh_materials: array<MeshMaterial>;
@group(0) @binding(12) var<storage, read> hybrid_in: array<FirstHit>;
// The fragments of the volumetric look's first hits (FIRST_HIT_FRAGMENTS).
@group(0) @binding(17) var<storage, read> hybrid_fragments: array<Fragment>;

// The hybrid pipeline's first hit of one sample of a pixel (sample i of pixel p at p S + i),
// from the rasterizer (64 bytes), mirrored by splat_gpu::GpuFirstHit: the splats' radiance L and
// transmittance T in front of the meshes (lit per fragment in the volumetric look, raw in the
// surface look), the integrated unit normal (zero where no fragment), the iso-opacity depth
// and splat (picked NONE: none), and the sample's position in the pixel.
struct FirstHit {
    radiance: vec3<f32>,
    transmittance: f32,
    normal: vec3<f32>,
    depth: f32,
    picked: u32,
    pad0: u32,
    offset: vec2<f32>,
    // With FIRST_HIT_FRAGMENTS, the sample's fragments in hybrid_fragments: first, count.
    fragments: vec2<u32>,
    pad1: vec2<u32>,
}

// The pick of the sample the last call of `sample` (or the pass method's last state) made.
var<private> sample_pick: Pick;

fn no_pick() -> Pick {
    return Pick(vec3<f32>(0.0), -1.0, NONE, 0u, 0u, 0u);
}

// ---- rng.rs ---------------------------------------------------------------------------------

fn fract_(x: f32) -> f32 {
    return x - floor(x);
}

fn trig_hash(p: vec3<f32>) -> f32 {
    let r = fract_(47453.547 * sin(91.3458 * p.z));
    return fract_(43758.547 * sin(12.9898 * (p.x + r) + 78.233 * (p.y + r)));
}

// The bounce number of the segment being traced (trace/mod.rs `Bounce`): slot s of bounce d is
// s + d·2²⁰, shadow slot s + d·2²⁶, pass p + d·2²⁰, so that every bounce decides anew.
var<private> bounce: u32;
// How many transparent surfaces the segment's ray has passed (trace/mod.rs `Bounce::past_layer`):
// the stochastic pass, whose decisions are keyed by pass alone, draws layer l's at pass + l·2²⁴.
var<private> layer: u32;

fn bounce_slot(slot: u32) -> u32 {
    return slot + (bounce << select(BOUNCE_SHIFT, SHADOW_BOUNCE_SHIFT, slot >= 0x80000000u));
}

// rng.rs `RayRng::particle` through trace/mod.rs `Bounce`: u of particle `id` in sample `slot` of
// the current bounce, lowered by the test hook.
// In the path tracer (path.wgsl) the path's own decisions, slot being its decision number.
fn particle_u(pixel_key: u32, id: u32, slot: u32, hit: vec3<f32>) -> f32 {
    if (PATH_MODE) {
        return path_particle(id, slot) - params.u_shift;
    }
    return unshifted_particle_u(pixel_key, id, bounce_slot(slot), hit) - params.u_shift;
}

fn unshifted_particle_u(pixel_key: u32, id: u32, slot: u32, hit: vec3<f32>) -> f32 {
    if (params.rng_scheme == RNG_HASH) {
        return unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, id, slot))));
    }
    let o = vec3<f32>(
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, OFFSET_ID, 3u * slot)))),
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, OFFSET_ID, 3u * slot + 1u)))),
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, OFFSET_ID, 3u * slot + 2u)))),
    );
    return trig_hash(hit + o);
}

fn pass_u(pixel_key: u32, pass_index: u32) -> f32 {
    let slot = bounce_slot(pass_index) + (layer << LAYER_PASS_SHIFT);
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, PASS_ID, slot)))) - params.u_shift;
}

// ---- kernel.rs, hit.rs ----------------------------------------------------------------------

fn response(d2: f32) -> f32 {
    return kernel_response(d2, params.kernel_degree);
}

struct Hit {
    t: f32,
    alpha: f32,
    ok: bool,
}

// Algorithm 1 without the roulette: alpha from the maximum response along the ray, hit
// distance by convention, range and Eq. 2 tests.
fn intersect(p: Particle, ray: Ray) -> Hit {
    let miss = Hit(0.0, 0.0, false);
    let rel = ray.origin - p.mean;
    let oc = vec3<f32>(dot(p.row0, rel), dot(p.row1, rel), dot(p.row2, rel));
    let dc = vec3<f32>(dot(p.row0, ray.dir), dot(p.row1, ray.dir), dot(p.row2, ray.dir));
    let dd = dot(dc, dc);
    let cr = cross(oc, dc);
    let d2_min = dot(cr, cr) / dd;
    var alpha = p.opacity * response(d2_min);
    if (!(alpha >= params.alpha_cull && alpha > 0.0)) {
        return miss;
    }
    alpha = min(alpha, params.alpha_clamp);
    // Eq. 2 at the maximum density point, whatever the convention (hit.rs `intersect`).
    if (d2_min > params.cutoff * params.cutoff) {
        return miss;
    }
    var t = -dot(oc, dc) / dd;
    if (params.hit_distance == HIT_CENTER) {
        let dv = dot(ray.dir, ray.view);
        if (dv < CENTER_VIEW_COS_MIN) {
            return miss;
        }
        t = dot(p.mean - ray.origin, ray.view) / dv;
    } else if (params.hit_distance == HIT_ICOSAHEDRON) {
        t = icosahedron_crossing(oc, dc, p.extent, ray.t_min);
    }
    if (!(t > ray.t_min && t < ray.t_max)) {
        return miss;
    }
    return Hit(t, alpha, true);
}

// hit.rs ICOSAHEDRON_NORMALS, face i of the proxy (n·x ≤ ρ), computed rather than indexed in a
// constant array (which the compilers copy into private memory at every call): i < 8 the
// (±a, ±a, ±a) in the CPU's order, then the cyclic permutations (0, ±b, ±c), (±c, 0, ±b),
// (±b, ±c, 0).
const ICO_A: f32 = 0.57735026;
const ICO_B: f32 = 0.93417236;
const ICO_C: f32 = 0.3568221;

fn icosahedron_normal(i: u32) -> vec3<f32> {
    if (i < 8u) {
        let s = vec3<f32>(select(1.0, -1.0, (i & 4u) != 0u), select(1.0, -1.0, (i & 2u) != 0u), select(1.0, -1.0, (i & 1u) != 0u));
        return ICO_A * s;
    }
    let j = i - 8u;
    let s1 = select(1.0, -1.0, (j & 2u) != 0u);
    let s2 = select(1.0, -1.0, (j & 1u) != 0u);
    let b = ICO_B * s1;
    let c = ICO_C * s2;
    switch j / 4u {
        case 0u: { return vec3<f32>(0.0, b, c); }
        case 1u: { return vec3<f32>(c, 0.0, b); }
        default: { return vec3<f32>(b, c, 0.0); }
    }
}

// hit.rs `icosahedron_crossing`: the first crossing after t_min of o + t d with the icosahedron
// of inradius rho (its entry, else its exit); -1 (a miss, never in range) when there is none.
fn icosahedron_crossing(o: vec3<f32>, d: vec3<f32>, rho: f32, t_min: f32) -> f32 {
    var enter = -3.4e38;
    var exit = 3.4e38;
    var missed = false;
    for (var i = 0u; i < 20u; i++) {
        let n = icosahedron_normal(i);
        let num = rho - dot(n, o);
        let den = dot(n, d);
        if (den == 0.0) {
            missed = missed || num < 0.0;
        } else if (den < 0.0) {
            enter = max(enter, num / den);
        } else {
            exit = min(exit, num / den);
        }
    }
    if (missed || enter > exit) {
        return -1.0;
    }
    if (enter > t_min) {
        return enter;
    }
    return select(-1.0, exit, exit > t_min);
}

fn before(t: f32, id: u32, other_t: f32, other_id: u32) -> bool {
    return t < other_t || (t == other_t && id < other_id);
}

// ---- sh.rs ------------------------------------------------------------------------------------

fn sh_color(id: u32, dir: vec3<f32>) -> vec3<f32> {
    return sh_eval(id, params.sh_degree, dir);
}

// ---- bvh.rs: the splats' traversals -----------------------------------------------------------

// Bvh4::traverse: every particle of every leaf the ray overlaps before t_max, nearer child
// first, handed to `visit` (the including kernel's twin of the CPU closure), which returns the
// new t_max. The leaf loop is nested in the node loop, as on the CPU: each loop statement then
// runs few iterations per ray, which keeps lavapipe's loop limiter bound (see LOOP_BUDGET)
// meaningful.
fn traverse(ray: Ray, visitor: u32) {
    let inv = safe_inverse(ray.dir);
    var t_max = ray.t_max;
    traversal_begin(ROOT);
    loop {
        iterations += 1u;
        let r = traversal_next_leaf(ray.origin, inv, ray.t_min, t_max);
        if (r == NONE) {
            break;
        }
        for (var leaf = leaf_first(r); leaf < leaf_end(r); leaf++) {
            iterations += 1u;
            t_max = visit(visitor, ray, leaf, t_max);
        }
    }
}

// `traverse` for shadow rays, handing leaves to `visit_shadow`. A second copy of the loop, not
// a third visitor family of `visit`: GPU compilers inline every function, so each traversal
// call site carries the bodies of all the visitors its `visit` can reach, and the shadow ray is
// traced from inside the primary methods.
//
// Meshes block the light (shadow.rs `visibility_from`): their BVH follows the splats' in the node
// buffer, so the same loop walks it first and then the splats' (an opaque mesh hit ends the
// walk before any splat could shorten t_max), with triangles at its leaves; transparent ones let
// Π (1 − α) through (`shadow_mesh_t`).
fn traverse_shadow(ray: Ray) {
    let inv = safe_inverse(ray.dir);
    var t_max = ray.t_max;
    var triangle_leaf = params.mesh_root != NONE;
    traversal_begin(select(ROOT, params.mesh_root, triangle_leaf));
    loop {
        iterations += 1u;
        let r = traversal_next_leaf(ray.origin, inv, ray.t_min, t_max);
        if (r == NONE) {
            if (triangle_leaf) {
                triangle_leaf = false;
                traversal_begin(ROOT);
                continue;
            }
            break;
        }
        for (var leaf = leaf_first(r); leaf < leaf_end(r); leaf++) {
            iterations += 1u;
            if (!triangle_leaf) {
                t_max = visit_shadow(ray, leaf, t_max);
                continue;
            }
            // mesh.rs `Meshes::transmittance`: Π (1 − α) over the triangles crossed (each
            // shared edge of a transparent surface once), 0 at the first opaque one.
            let tri = triangles[leaf];
            var h = triangle_intersect(tri, ray);
            if (is_transparent(tri)) {
                h = triangle_crosses(tri, ray);
            }
            if (h.x >= 0.0 && h.x < ray.t_max) {
                shadow_mesh_t *= 1.0 - alpha_at(tri, h.y, h.z);
            }
            if (shadow_mesh_t == 0.0) {
                shadow_mesh = true;
                return;
            }
        }
    }
}

// ---- trace/mod.rs: the traversals' visitors ---------------------------------------------------

var<private> iterations: u32;

// The visitors of `traverse` (bvh.wgsl), the closures that trace/mod.rs hands to Bvh4::traverse
// (stochastic_visit in stochastic.wgsl, next_k_visit in kbuffer.wgsl; the shadow visitors in
// shadow.wgsl); their inputs are set in the private variables below before the traversal.
const VISIT_STOCHASTIC: u32 = 0u;
const VISIT_NEXT_K: u32 = 1u;

fn visit(visitor: u32, ray: Ray, leaf: u32, t_max: f32) -> f32 {
    if (visitor == VISIT_STOCHASTIC) {
        return stochastic_visit(ray, leaf, t_max);
    }
    return next_k_visit(ray, leaf, t_max);
}

// The shadow kind of the current shadow ray: the world's, or in the path tracer's pipeline
// the one path.wgsl chose (path_shadows).
fn shadow_kind() -> u32 {
    return select(params.shadows, path_shadows, PATH_MODE);
}

// The visitor of `traverse_shadow` (bvh.wgsl) for the current shadow kind.
fn visit_shadow(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    switch shadow_kind() {
        case SHADOWS_EXACT: {
            return transmittance_visit(ray, leaf, t_max);
        }
        case SHADOWS_STOCHASTIC: {
            return occluded_visit(ray, leaf, t_max);
        }
        default: { // SHADOWS_SORTED
            return shadow_sorted_visit(ray, leaf, t_max);
        }
    }
}

// What the visitors read: the pixel's decisions; for stochastic_visit the slots first_slot ..
// first_slot + n; for next_k_visit the buffer size k, the hit (after_t, after_id) the hits must
// lie behind, and whether only hits accepted in slot 0 count.
struct VisitInputs {
    pixel_key: u32,
    n: u32,
    first_slot: u32,
    k: u32,
    after_t: f32,
    after_id: u32,
    accepted: bool,
}

var<private> visit_in: VisitInputs;

// ---- trace/mod.rs: the methods ----------------------------------------------------------------

// A ray's state at the start of a frame: no radiance, T = 1, the first pass starting at t_min
// (stochastic-n sums colour and coverage in radiance and transmittance instead).
fn start_state(t_min: f32) -> PassState {
    var st = PassState(vec3<f32>(0.0), 1.0, t_min, NONE, 0u, NONE, vec3<f32>(0.0), 0.0);
    if (stochastic_slots()) {
        st.transmittance = 0.0;
    }
    return st;
}

// Algorithm 1 and stochastic-n, which the kernel runs alike (Algorithm 1 is m = n = 1).
fn stochastic_slots() -> bool {
    return params.method == METHOD_STOCHASTIC || params.method == METHOD_STOCHASTIC_N;
}

// The method whose sample `finish` completes: params.method, or the sorted composite of the
// hybrid pipeline's rasterized first hit (METHOD_EXACT) for its camera segment.
var<private> segment_method: u32;

fn segment_slots() -> bool {
    return segment_method == METHOD_STOCHASTIC || segment_method == METHOD_STOCHASTIC_N;
}

fn volumetric() -> bool {
    return params.lit == 1u && params.look == LOOK_VOLUMETRIC;
}

// Eq. 3 front to back over the hits in kb, continuing the state (trace/mod.rs
// `TraceScene::integrate`), with the integrated normal and the iso-opacity depth; with
// `light_hits` (the volumetric look) each hit is lit before it is composited.
fn integrate(st: ptr<function, PassState>, ray: Ray, pixel_key: u32, light_hits: bool) {
    for (var i = 0u; i < kb.len; i++) {
        iterations += 1u;
        var c = sh_color(kb.id[i], ray.dir);
        let alpha = kb.alpha[i];
        let n = particle_normal(kb.leaf[i], ray);
        if (light_hits) {
            c = lit(c, kb.id[i], kb.t[i], n, ray, pixel_key, 0u);
        }
        (*st).normal += (*st).transmittance * alpha * n;
        (*st).flags |= HIT;
        (*st).radiance += (*st).transmittance * alpha * c;
        (*st).transmittance *= 1.0 - alpha;
        if ((*st).picked == NONE && (*st).transmittance < params.iso_threshold) {
            (*st).picked = kb.id[i];
            (*st).depth = kb.t[i];
        }
    }
}

// The next pass starts behind the last hit of this one; true when the pass was not full (the
// ray has no more hits).
fn advance(st: ptr<function, PassState>) -> bool {
    if (kb.len < params.k) {
        return true;
    }
    (*st).after_t = kb.t[kb.len - 1u];
    (*st).after_id = kb.id[kb.len - 1u];
    return false;
}

// One step of a frame (trace/mod.rs `TraceScene::sample`, cut where a pass ends): a traversal of n
// slots of stochastic-n; a pass of the k-buffer (exact is the k-buffer with no limit) or of the
// stochastic pass; or depth sampling's one pass. True when the frame's sample is complete.
//
// Every method goes through this one function, which calls next_k, integrate and stochastic_n
// once each, and `finish` lights the rest in one place: GPU compilers inline every call, and
// the lit shading with its shadow traversal would be copied at every call site (lavapipe took
// minutes to compile the kernel with one call per method and mode).
fn step(ray: Ray, pixel_key: u32, pass_index: u32, st: ptr<function, PassState>) -> bool {
    if (stochastic_slots()) {
        let s = stochastic_n(ray, pixel_key, params.n, pass_index * params.n);
        (*st).radiance += s.xyz * f32(params.n);
        (*st).transmittance += s.w * f32(params.n);
        if (pass_index == 0u) {
            // The pick of slot 0, kept in the state's otherwise unused fields.
            (*st).normal = sample_pick.normal;
            (*st).depth = sample_pick.depth;
            (*st).picked = sample_pick.picked;
        }
        return pass_index + 1u >= params.m;
    }
    // The k-buffer stops when T ≤ min_transmittance (0 for the other methods, whose T stays
    // above it).
    if ((*st).transmittance <= params.min_transmittance) {
        return true;
    }
    let pass_method = params.method == METHOD_STOCHASTIC_PASS;
    let sampling = params.method == METHOD_DEPTH_SAMPLING_K;
    next_k(ray, params.k, (*st).after_t, (*st).after_id, sampling, pixel_key);
    if (pass_method && kb.len == 0u) {
        return true;
    }
    // The stochastic pass integrates each pass from T = 1, unlit.
    var acc = *st;
    if (pass_method) {
        acc = start_state(ray.t_min);
    }
    integrate(&acc, ray, pixel_key, volumetric() && !pass_method);
    if (!pass_method) {
        *st = acc;
        return sampling || advance(st);
    }
    let opacity = 1.0 - acc.transmittance;
    if (pass_u(pixel_key, pass_index) < opacity) {
        // kbuffer.rs `pass_sample`: colour L_pass / O at the pass's iso-depth, else its farthest
        // hit, with its normal; lit in `finish`.
        var t = acc.depth;
        var id = acc.picked;
        if (id == NONE) {
            t = kb.t[kb.len - 1u];
            id = kb.id[kb.len - 1u];
        }
        (*st).radiance = acc.radiance / opacity;
        (*st).depth = t;
        (*st).picked = id;
        (*st).normal = unit_normal(acc.normal, ray.dir);
        (*st).flags |= ACCEPTED;
        return true;
    }
    return advance(st);
}

// ---- mesh.rs and trace/mod.rs: what lies behind the splats ------------------------------------

// The closest mesh along the pixel's camera ray (set in `main`; triangle NONE where none).
var<private> surface: SurfaceHit;
// Its opacity α at the hit (mesh.rs `SurfaceHit::alpha`: 1 for an opaque surface): what lies
// behind the splats is α × the surface over (1 − α) × the same ray continued past it.
var<private> surface_alpha: f32;
// Whether the pick of the sample `finish` returned is the surface's (no splat picked).
var<private> surface_picked: bool;
// The coefficient of what lies behind in the sample `finish` returned (T for the sorted
// methods, the share of missing slots for stochastic-n, 1 for a stochastic pass that accepted
// none): the weight of the mesh's mirror and glass segments.
var<private> behind_weight: f32;
// The lit pick in the sample `finish` returned (zero where it lit none).
var<private> lit_pick: vec3<f32>;
// Whether the pipeline is the hybrid's (splat_gpu::TracePipeline::hybrid sets it): the kernel
// then continues the rasterizer's S samples and lights the volumetric look's fragments. A
// pipeline-overridable constant: every other render runs a kernel whose hybrid branches are
// constant false.
override HYBRID_MODE: bool = false;

// trace/mod.rs `surface_offset`.
fn surface_offset(x: vec3<f32>) -> f32 {
    return SURFACE_OFFSET * max(max(max(abs(x.x), abs(x.y)), abs(x.z)), 1.0);
}

// The sample of a finished frame and its pick: stochastic-n's average; the stochastic pass's
// accepted pass (or what lies behind); the integrated hits over what lies behind for the others
// (trace/mod.rs `TraceScene::finish`), depth sampling reporting the depth of its first accepted hit.
// What lies behind is the background or the lit mesh that clipped the ray (trace/mod.rs `behind`),
// computed here only, and only where the sample shows it. Lit once here where the method lights
// once: the accepted pass, and the surface look (L lit at the iso-opacity depth with the
// integrated normal and the picked particle's material, what lies behind where the threshold
// was never reached).
fn finish(st: PassState, ray: Ray, pixel_key: u32) -> vec4<f32> {
    let mesh = surface.triangle != NONE;
    let mesh_alpha = select(0.0, surface_alpha, mesh);
    surface_picked = false;
    var behind_pick = no_pick();
    if (mesh) {
        behind_pick = Pick(surface_normal(surface, ray), surface.t, NONE, 0u, 0u, 0u);
    }
    // The sample is out + behind_weight × (what lies behind), out.xyz + the lit pick where
    // `shade`; both lightings happen at the end, at one call site.
    var out = vec4<f32>(st.radiance, 1.0 - st.transmittance + st.transmittance * mesh_alpha);
    var shade = false;
    behind_weight = st.transmittance;
    if (segment_slots()) {
        let samples = f32(params.m * params.n);
        let misses = samples - st.transmittance;
        sample_pick = behind_pick;
        surface_picked = mesh;
        if (st.picked != NONE) {
            sample_pick = Pick(st.normal, st.depth, st.picked, 0u, 0u, 0u);
            surface_picked = false;
        }
        out = vec4<f32>(st.radiance, st.transmittance + misses * mesh_alpha) / samples;
        behind_weight = misses / samples;
    } else if (segment_method == METHOD_STOCHASTIC_PASS) {
        if ((st.flags & ACCEPTED) == 0u) {
            sample_pick = behind_pick;
            surface_picked = mesh;
            out = vec4<f32>(0.0, 0.0, 0.0, mesh_alpha);
            behind_weight = 1.0;
        } else {
            sample_pick = Pick(st.normal, st.depth, NONE, 0u, 0u, 0u);
            out = vec4<f32>(st.radiance, 1.0);
            shade = params.lit == 1u;
            behind_weight = 0.0;
        }
    } else {
        sample_pick = no_pick();
        if ((st.flags & HIT) != 0u) {
            sample_pick.normal = unit_normal(st.normal, ray.dir);
        }
        if (st.picked != NONE) {
            sample_pick.depth = st.depth;
        } else if (mesh) {
            sample_pick = behind_pick;
            surface_picked = true;
        }
        if (params.lit == 1u && !volumetric() && (st.flags & BEHIND_ONLY) == 0u) {
            if (st.picked == NONE) {
                sample_pick = behind_pick;
                surface_picked = mesh;
                out = vec4<f32>(0.0, 0.0, 0.0, mesh_alpha);
                behind_weight = 1.0;
            } else {
                sample_pick.picked = st.picked;
                shade = true;
            }
        }
        if (segment_method == METHOD_DEPTH_SAMPLING_K) {
            sample_pick.depth = select(-1.0, kb.t[0], kb.len > 0u);
            surface_picked = false;
        }
    }
    // Lit(…) of the pick (k = 0) and of the mesh's local share (k = 1), where the sample shows
    // them: one inlined copy of the lighting and its shadow traversal for both.
    var behind = params.background.xyz;
    lit_pick = vec3<f32>(0.0);
    // Two iterations a call, not counted: `iterations` bounds each loop statement's total by the
    // busiest lane's, and the batches of frames per dispatch shrink with every count a frame adds.
    // A constant count: a count known only at run time (the hybrid's fragments lit here too)
    // made lavapipe run every ray-tracing render about 8 % slower.
    for (var k = 0u; k < 2u; k++) {
        var m: Material;
        var c: vec3<f32>;
        var t: f32;
        var n: vec3<f32>;
        var offset = params.shadow_offset;
        var share = 1.0;
        if (k == 0u) {
            if (!shade) {
                continue;
            }
            m = material_of(st.picked);
            c = st.radiance;
            t = st.depth;
            n = sample_pick.normal;
        } else {
            if (!mesh || !(behind_weight > 0.0)) {
                continue;
            }
            let mm = mesh_materials[triangles[surface.triangle].mesh];
            share = local_share(mm);
            behind = vec3<f32>(0.0);
            if (share <= 0.0) {
                continue;
            }
            m = mm.shading;
            c = mm.color;
            t = surface.t;
            n = behind_pick.normal;
            offset = surface_offset(ray.origin + t * ray.dir);
        }
        let lit = share * lit_material(m, c, t, n, ray, pixel_key, 0u, offset);
        if (k == 0u) {
            out = vec4<f32>(lit, out.w);
            lit_pick = lit;
        } else {
            behind = surface_alpha * lit;
        }
    }
    return vec4<f32>(out.xyz + behind_weight * behind, out.w);
}

// ---- camera.rs and frame accumulation (render_frames) ----------------------------------------

fn pixel_ray(x: u32, y: u32) -> Ray {
    return camera_ray(x, y, vec2<f32>(0.5));
}

// camera.rs `Camera::ray`: through pixel (x, y) at sub-pixel position `offset`.
fn camera_ray(x: u32, y: u32, offset: vec2<f32>) -> Ray {
    return Ray(params.cam_center.xyz, normalize(camera_to_world(camera_dir(x, y, offset))), params.cam_row2.xyz, params.t_min, params.t_max);
}

// camera.rs `Camera::lens_ray` with the settings' lens: from the point `lens` of the lens of
// radius params.aperture toward where the pinhole ray through `offset` meets the plane in focus.
fn lens_ray(x: u32, y: u32, offset: vec2<f32>, lens: vec2<f32>) -> Ray {
    var ray = camera_ray(x, y, offset);
    if (params.aperture > 0.0) {
        let on_lens = vec3<f32>(params.aperture * concentric_disk(lens), 0.0);
        ray.origin = params.cam_center.xyz + camera_to_world(on_lens);
        let d = camera_dir(x, y, offset);
        let focus = params.focus_distance * select(normalize(d), d / d.z, d.z > 0.0);
        ray.dir = normalize(camera_to_world(focus - on_lens));
    }
    return ray;
}

// camera_sampling.rs `frame_sample`: point `frame` of the run's 4-D Owen-scrambled Sobol
// sequence (pixel offset in xy, lens point in zw).
fn frame_sample(frame: u32) -> vec4<f32> {
    let scramble = xxhash32(vec3<u32>(params.seed, frame >> 16u, FRAME_SOBOL_SALT));
    let i = frame & 0xffffu;
    return vec4<f32>(sobol_sample(i, 0u, scramble), sobol_sample(i, 1u, scramble), sobol_sample(i, 2u, scramble), sobol_sample(i, 3u, scramble));
}

// camera_sampling.rs `CameraSampling::ray`: the camera ray of pixel (x, y) in frame `frame`.
fn frame_ray(x: u32, y: u32, frame: u32) -> Ray {
    if (params.pixel_filter == FILTER_CENTER && params.aperture <= 0.0) {
        return pixel_ray(x, y);
    }
    let s = frame_sample(frame);
    let offset = select(vec2<f32>(0.5), s.xy, params.pixel_filter == FILTER_BOX);
    return lens_ray(x, y, offset, s.zw);
}

// Rᵀ v: a camera-space vector in world space.
fn camera_to_world(v: vec3<f32>) -> vec3<f32> {
    return params.cam_row0.xyz * v.x + params.cam_row1.xyz * v.y + params.cam_row2.xyz * v.z;
}

// frame.rs `PixelFrames::push` in f32: fold sample `s` of frame `frame` into a running mean
// and M2 (Welford), the mean then stored in params.accumulation's format.
fn welford(mean: ptr<function, vec4<f32>>, m2: ptr<function, vec4<f32>>, s: vec4<f32>, frame: u32) {
    let delta = s - *mean;
    *mean += delta / f32(frame + 1u);
    *m2 += delta * (s - *mean);
    *mean = stored(*mean, params.accumulation);
}

// Fold frame `frame`'s sample into the pixel's running Welford state (mean in out_mean, M2
// in out_var.xyz) and, for frame 0, write its pick.
fn fold(index: u32, s: vec4<f32>, frame: u32) {
    var mean = vec4<f32>(0.0);
    var m2 = vec4<f32>(0.0);
    if (frame > 0u) {
        mean = out_mean[index];
        m2 = vec4<f32>(out_var[index].xyz, 0.0);
    }
    welford(&mean, &m2, s, frame);
    out_mean[index] = mean;
    out_var[index] = vec4<f32>(m2.xyz, out_var[index].w);
    if (frame == 0u) {
        out_pick[index] = sample_pick;
    }
}

// One straight piece of a light path waiting to be traced (trace/mod.rs `secondary`, or
// `surface_sample`'s ray continued past a transparent surface): where it starts, where it goes,
// its bounce number, for a continued ray (layer > 0) the distance along it where it continues,
// its weight in the pixel's sample (per channel: a tinted mirror reflects each its share; grey
// at bounce 0) and how many transparent surfaces it has passed.
struct Segment {
    origin: vec3<f32>,
    depth: u32,
    dir: vec3<f32>,
    t_min: f32,
    weight: vec3<f32>,
    layer: u32,
}

// The pending segments of one frame, depth first: each segment pushes at most three (the ray
// continued past a transparent surface first, then the reflected and the refracted ray), so
// that while a segment of bounce d is traced each bounce before it holds at most two (a sibling
// and a continuation): SEGMENT_STACK entries hold paths of splat_gpu::MAX_LAYERED_BOUNCES
// bounces among transparent mirrors or glass, and of MAX_BOUNCES among opaque ones.
const SEGMENT_STACK: u32 = 16u;
var<private> segments: array<Segment, SEGMENT_STACK>;

// trace/mod.rs `surface_sample`'s bounces: the mirror share and Fresnel's share of the glass go to the
// reflected ray, the rest of the glass to the refracted one (none under total internal
// reflection), each one bounce deeper, weighted by the segment's weight and by what lies
// behind's coefficient in its sample. Returns the new stack top.
fn push_bounces(ray: Ray, seg: Segment, top: u32) -> u32 {
    let m = mesh_materials[triangles[surface.triangle].mesh];
    let n = surface_normal(surface, ray);
    let x = ray.origin + surface.t * ray.dir;
    let w = seg.weight * behind_weight * surface_alpha;
    let cos_i = clamp(-dot(ray.dir, n), 0.0, 1.0);
    var reflected = vec3<f32>(0.0);
    if (m.mirror > 0.0) {
        reflected = mirror_reflectance(m, cos_i);
    }
    var refracted = vec4<f32>(0.0);
    if (m.transmission > 0.0) {
        let eta = select(m.ior, 1.0 / m.ior, from_outside(surface, ray.dir));
        let f = fresnel(cos_i, eta);
        reflected += m.transmission * f;
        if (f < 1.0) {
            refracted = refract_dir(ray.dir, n, eta);
            refracted.w *= m.transmission * (1.0 - f);
        }
    }
    var t = top;
    if (refracted.w > 0.0) {
        segments[t] = Segment(x, seg.depth + 1u, refracted.xyz, 0.0, w * refracted.w, 0u);
        t += 1u;
    }
    if (any(reflected > vec3<f32>(0.0))) {
        segments[t] = Segment(x, seg.depth + 1u, reflect_dir(ray.dir, n), 0.0, w * reflected, 0u);
        t += 1u;
    }
    return t;
}

// One invocation per pixel. MODE_FRAMES: frames first_frame .. first_frame + frames of the
// render, each run to the end: the camera segment, then, among mirror and glass meshes, the
// segments it spawns, each a whole sample of the method (trace/mod.rs `trace_ray`), summed with their
// weights. MODE_PASS: step `pass_index` of frame `first_frame` only (a k-buffer or stochastic
// pass, or a chunk of params.n of the params.m slots of stochastic-n), the camera ray's state
// kept in pass_state between dispatches, so that each dispatch runs one traversal per ray,
// within lavapipe's loop budget (the host never runs a world with bounces this way). Either way
// the sample is folded in when the frame finishes, and out_var.w records the most loop
// iterations any dispatch of the render spent on the pixel. Long renders are many dispatches.
@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let index = gid.y * params.size.x + gid.x;
    iterations = 0u;
    let by_pass = params.mode == MODE_PASS;
    let hybrid = HYBRID_MODE && params.mode == MODE_HYBRID;
    var most = 0.0;
    if (params.first_frame > 0u || params.pass_index > 0u) {
        most = out_var[index].w;
    }
    let frames = select(params.frames, 1u, by_pass);
    // The hybrid continues each of the rasterizer's S samples, its camera ray through the
    // sample's position, weighted 1/S (raster/mod.rs: the pixel is the mean of its samples).
    let samples = select(1u, params.raster_samples, hybrid);
    let weight = 1.0 / f32(samples);
    // raster/mod.rs `light_surface`: the surface look lights sorted splatting's mean radiance
    // once, at sample 0's pick, and adds each sample's T_s × what lies behind it (no pick:
    // what lies behind it, whole). Sample 0's first hit then carries the mean radiance and the
    // pick, whose light counts whole, and the others add only what lies behind them.
    let lit_once = hybrid && params.first_hit != FIRST_HIT_ACCEPTED && params.lit == 1u && !volumetric();
    let pixel_picked = lit_once && hybrid_in[index * samples].picked != NONE;
    for (var f = 0u; f < frames; f++) {
        iterations += 1u;
        let frame = params.first_frame + f;
        let pixel_key = xxhash32(vec3<u32>(gid.x, gid.y, frame_key(params.seed, params.run_first + frame)));
        var total = vec4<f32>(0.0);
        var camera_pick = no_pick();
        var finished = false;
        // The camera segment first, then the pending ones: the stack (a dynamically indexed
        // private array, slow on CPU adapters) is touched only where a mesh bounces. The hybrid
        // goes on to each of the rasterizer's samples in turn, in the same loop (a loop around
        // it made lavapipe run every ray-tracing render about 40 % slower).
        var sample = 0u;
        var hit_index = index * samples;
        var camera = frame_ray(gid.x, gid.y, params.run_first + frame);
        if (hybrid) {
            camera = camera_ray(gid.x, gid.y, hybrid_in[hit_index].offset);
        }
        var seg = Segment(camera.origin, 0u, camera.dir, 0.0, vec3<f32>(weight), 0u);
        // Whether the camera pick waits for the ray continued past a transparent surface
        // (trace/mod.rs `surface_sample`: the surface's pick only where 1 − α is below the iso
        // threshold or nothing with a depth lies behind it).
        var pick_pending = false;
        var top = 0u;
        loop {
            bounce = seg.depth;
            // The camera ray from t_min; a secondary ray from the surface point on (its line
            // continues the mirrored or refracted one), meshes from surface_offset on.
            var ray = camera;
            var mesh_ray = camera;
            if (seg.depth > 0u) {
                ray = Ray(seg.origin, seg.dir, seg.dir, 0.0, params.t_max);
                mesh_ray = Ray(seg.origin, seg.dir, seg.dir, surface_offset(seg.origin), params.t_max);
            }
            if (seg.layer > 0u) {
                // trace/mod.rs `surface_sample`: the same ray past the transparent surface at
                // t_min, the splats from there, the meshes from surface_offset beyond it.
                let view = select(seg.dir, camera.view, seg.depth == 0u);
                let x = seg.origin + seg.t_min * seg.dir;
                ray = Ray(seg.origin, seg.dir, view, seg.t_min, params.t_max);
                let mesh_t_min = seg.t_min + surface_offset(x) / length(seg.dir);
                mesh_ray = Ray(seg.origin, seg.dir, view, mesh_t_min, params.t_max);
            }
            layer = seg.layer;
            // trace/mod.rs `trace_ray`: the closest mesh clips the ray.
            surface = SurfaceHit(FAR, NONE, 0.0, 0.0);
            surface_alpha = 1.0;
            if (params.mesh_root != NONE) {
                surface = mesh_traverse(params.mesh_root, mesh_ray, false);
                if (surface.triangle != NONE) {
                    ray.t_max = surface.t;
                    surface_alpha = alpha_at(triangles[surface.triangle], surface.b1, surface.b2);
                }
            }
            var st = start_state(ray.t_min);
            var first = 0u;
            var last = max(params.max_passes, params.m);
            if (by_pass) {
                first = params.pass_index;
                last = params.pass_index + 1u;
                if (params.pass_index > 0u) {
                    st = pass_state[index];
                }
            }
            segment_method = params.method;
            let rasterized = hybrid && seg.depth == 0u;
            if (rasterized) {
                // raster/mod.rs `Rasterizer::sorted` gave the splats in front of the mesh; the
                // ray tracer lights the pick with shadows and continues at the mesh. A
                // StochasticSplats first hit (`Rasterizer::stochastic_splat`) is one opaque
                // fragment or none: finished as an accepted pass or a missed one, the fragment
                // lit as the pick in either look.
                let accepted = params.first_hit == FIRST_HIT_ACCEPTED;
                segment_method = select(METHOD_EXACT, METHOD_STOCHASTIC_PASS, accepted);
                let h = hybrid_in[hit_index];
                if (pixel_picked && sample > 0u) {
                    st.flags |= BEHIND_ONLY;
                }
                st.radiance = h.radiance;
                if (HYBRID_MODE && params.first_hit == FIRST_HIT_FRAGMENTS) {
                    // The volumetric look (raster/mod.rs `sorted` with `lit_color` in the
                    // hybrid): each fragment lit along the sample's ray with the tracer's shadow
                    // rays (trace `light_pick`), weighted Tᵢ αᵢ, summed in order.
                    st.radiance = vec3<f32>(0.0);
                    for (var i = 0u; i < h.fragments.y; i++) {
                        iterations += 1u;
                        let g = hybrid_fragments[h.fragments.x + i];
                        st.radiance += g.weight * lit(g.color, g.id, g.t, g.normal, camera, pixel_key, 0u);
                    }
                }
                st.transmittance = h.transmittance;
                st.normal = h.normal;
                if (any(h.normal != vec3<f32>(0.0))) {
                    st.flags |= HIT;
                }
                if (h.picked != NONE) {
                    st.picked = h.picked;
                    st.depth = h.depth;
                    if (accepted) {
                        st.flags |= ACCEPTED;
                    }
                }
            }
            if ((st.flags & DONE) == 0u) {
                var done = rasterized;
                for (var p = first; p < last && !rasterized; p++) {
                    iterations += 1u;
                    if (step(ray, pixel_key, p, &st)) {
                        done = true;
                        break;
                    }
                }
                if (done || last >= params.max_passes) {
                    st.flags |= DONE;
                    let s = finish(st, ray, pixel_key);
                    total += vec4<f32>(seg.weight * s.xyz, select(0.0, seg.weight.x * s.w, seg.depth == 0u));
                    if (lit_once && rasterized) {
                        // Sample 0's lit pick counts whole, not 1/S.
                        total += vec4<f32>((1.0 - seg.weight.x) * lit_pick, 0.0);
                    }
                    if (seg.depth == 0u) {
                        let first_layer = seg.layer == 0u;
                        if (sample == 0u && (first_layer || pick_pending)) {
                            if (first_layer || sample_pick.depth >= 0.0) {
                                camera_pick = sample_pick;
                            }
                            pick_pending = surface_picked && !(1.0 - surface_alpha < params.iso_threshold);
                            if (rasterized) {
                                camera_pick.picked = st.picked; // the rasterizer reports its pick
                            }
                        }
                        finished = true;
                    }
                    if (surface.triangle != NONE && surface_alpha < 1.0 && !by_pass && behind_weight > 0.0) {
                        // The same ray past the transparent surface, one layer on (pushed first:
                        // traced after the surface's bounces).
                        let w = seg.weight * behind_weight * (1.0 - surface_alpha);
                        segments[top] = Segment(ray.origin, seg.depth, ray.dir, surface.t, w, seg.layer + 1u);
                        top += 1u;
                    }
                    let bounces = surface.triangle != NONE && seg.depth < min(params.max_bounces, MAX_BOUNCES);
                    if (bounces && !by_pass && behind_weight > 0.0) {
                        top = push_bounces(ray, seg, top);
                    }
                }
            }
            if (by_pass) {
                pass_state[index] = st;
            }
            if (top == 0u) {
                sample += 1u;
                if (sample >= samples) {
                    break;
                }
                // The next sample's camera segment (counted as a segment is).
                iterations += 1u;
                hit_index = index * samples + sample;
                camera = camera_ray(gid.x, gid.y, hybrid_in[hit_index].offset);
                seg = Segment(camera.origin, 0u, camera.dir, 0.0, vec3<f32>(weight), 0u);
                continue;
            }
            // The camera segment is the frame (counted by the frame loop); every other segment
            // counts itself, so frames without meshes batch as many per dispatch as before.
            iterations += 1u;
            top -= 1u;
            seg = segments[top];
        }
        if (finished) {
            sample_pick = camera_pick;
            fold(index, total, frame);
        }
    }
    out_var[index].w = max(most, f32(iterations));
}

// The scene arrays as this kernel reads them: element i of each through its accessor into
// out_mean[9 i + k], the particle's four vec4 (k = 0..3), the node's four (4..7) and the SH
// coefficient (8), bit for bit. GpuTracer::arrays_as_read reads them back, so that a test
// compares a scene split over bindings (splat_gpu::split) with the same scene whole, element by
// element, without compiling the whole kernel for the split. An array shorter than i reads a
// clamped element, which the host ignores.
@compute @workgroup_size(64, 1, 1)
fn split_gather(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.y * groups.x * 64u + gid.x;
    let base = 9u * i;
    if (base + 8u >= arrayLength(&out_mean)) {
        return;
    }
    let p = particle_at(i);
    let n = node_at(i);
    out_mean[base] = vec4<f32>(p.mean, p.opacity);
    out_mean[base + 1u] = vec4<f32>(p.row0, bitcast<f32>(p.id));
    out_mean[base + 2u] = vec4<f32>(p.row1, p.extent);
    out_mean[base + 3u] = vec4<f32>(p.row2, p.pad2);
    out_mean[base + 4u] = bitcast<vec4<f32>>(n.origin);
    out_mean[base + 5u] = bitcast<vec4<f32>>(n.planes_xy);
    out_mean[base + 6u] = bitcast<vec4<f32>>(n.planes_z);
    out_mean[base + 7u] = bitcast<vec4<f32>>(n.child);
    out_mean[base + 8u] = sh_at(i);
}
