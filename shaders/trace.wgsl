// Ray tracing of transparent 3D Gaussians through a BVH (bvh.wgsl), every method of
// splat_core::trace. Each function mirrors its CPU twin in crates/splat-core/src/{hit,rng,
// trace,frame}.rs; the decisions use the same counter-based hashes, so a GPU frame makes the
// CPU frame's choices.

// One particle in BVH leaf order (64 bytes), mirrored by splat_gpu::GpuParticle.
struct Particle {
    mean: vec3<f32>,
    opacity: f32,
    // Rows of the canonical transform M = S⁻¹ Rᵀ.
    row0: vec3<f32>,
    id: u32,
    row1: vec3<f32>,
    pad1: f32,
    row2: vec3<f32>,
    pad2: f32,
}

// Everything a dispatch needs (192 bytes), mirrored by splat_gpu::Params.
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
    pad2: u32,
}

// The state of one ray between passes (pass-per-dispatch mode), mirrored by splat_gpu::PassState.
struct PassState {
    radiance: vec3<f32>,
    transmittance: f32,
    after_t: f32,
    after_id: u32,
    flags: u32,
    pad: u32,
}

// params.mode (splat_gpu::layout::MODE_*): whole frames per invocation, or one pass of one frame.
const MODE_FRAMES: u32 = 0u;
const MODE_PASS: u32 = 1u;
const DONE: u32 = 1u;
const ACCEPTED: u32 = 2u;
// The method identities of splat_core::trace::MethodCode (a test compares them).
const METHOD_EXACT: u32 = 0u;
const METHOD_KBUFFER: u32 = 1u;
const METHOD_STOCHASTIC: u32 = 2u;
const METHOD_STOCHASTIC_N: u32 = 3u;
const METHOD_STOCHASTIC_PASS: u32 = 4u;
const METHOD_DEPTH_SAMPLING: u32 = 5u;
const METHOD_OPAQUE: u32 = 6u; // CPU only: refused by GpuTracer::supports
const MAX_SLOTS: u32 = 64u;
const PASS_ID: u32 = 0xffffffffu;
const OFFSET_ID: u32 = 0xfffffffeu;
// lavapipe (Mesa's CPU Vulkan driver) stops a loop after 65535 iterations of its SIMD loop per
// invocation (gallivm's loop limiter), silently: a ray that needs more would be cut short.
// Every loop body below starts with `iterations += 1u`; a loop statement cannot iterate more
// often than lanes × the busiest lane's total, which the host checks against the budget.
const LOOP_BUDGET: u32 = 65535u;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> particles: array<Particle>;
@group(0) @binding(2) var<storage, read> nodes: array<Node>;
@group(0) @binding(3) var<storage, read> sh: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> out_mean: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_var: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> pass_state: array<PassState>;

// ---- rng.rs ---------------------------------------------------------------------------------

fn fract_(x: f32) -> f32 {
    return x - floor(x);
}

fn trig_hash(p: vec3<f32>) -> f32 {
    let r = fract_(47453.547 * sin(91.3458 * p.z));
    return fract_(43758.547 * sin(12.9898 * (p.x + r) + 78.233 * (p.y + r)));
}

// rng.rs `RayRng::particle`: u of particle `id` in sample `slot`, lowered by the test hook.
fn particle_u(pixel_seed: u32, id: u32, slot: u32, hit: vec3<f32>) -> f32 {
    return unshifted_particle_u(pixel_seed, id, slot, hit) - params.u_shift;
}

fn unshifted_particle_u(pixel_seed: u32, id: u32, slot: u32, hit: vec3<f32>) -> f32 {
    if (params.rng_scheme == 0u) {
        return unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, id, slot))));
    }
    let o = vec3<f32>(
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, OFFSET_ID, 3u * slot)))),
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, OFFSET_ID, 3u * slot + 1u)))),
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, OFFSET_ID, 3u * slot + 2u)))),
    );
    return trig_hash(hit + o);
}

fn pass_u(pixel_seed: u32, pass_index: u32) -> f32 {
    return unit_f32(pcg(xxhash32(vec3<u32>(pixel_seed, PASS_ID, pass_index)))) - params.u_shift;
}

// ---- kernel.rs, hit.rs ----------------------------------------------------------------------

fn response(d2: f32) -> f32 {
    return kernel_response(d2, params.kernel_degree);
}

struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    view: vec3<f32>,
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
    var t = -dot(oc, dc) / dd;
    var d2_hit = d2_min;
    if (params.hit_distance == 1u) {
        let dv = dot(ray.dir, ray.view);
        if (dv <= 0.0) {
            return miss;
        }
        t = dot(p.mean - ray.origin, ray.view) / dv;
        let q = oc + t * dc;
        d2_hit = dot(q, q);
    }
    if (!(t > params.t_min && t < params.t_max)) {
        return miss;
    }
    if (d2_hit > params.cutoff * params.cutoff) {
        return miss;
    }
    return Hit(t, alpha, true);
}

fn before(t: f32, id: u32, other_t: f32, other_id: u32) -> bool {
    return t < other_t || (t == other_t && id < other_id);
}

// ---- sh.rs ------------------------------------------------------------------------------------

fn sh_color(id: u32, dir: vec3<f32>) -> vec3<f32> {
    return sh_eval(id, params.sh_degree, dir);
}

// ---- trace.rs: stochastic (Algorithm 1) and its N-sample extension (§3.5) ---------------------

var<private> iterations: u32;

var<private> best_t: array<f32, MAX_SLOTS>;
var<private> best_id: array<u32, MAX_SLOTS>;
var<private> best_leaf: array<u32, MAX_SLOTS>;
var<private> slot_u: array<f32, MAX_SLOTS>;

// The visitors of `traverse` (bvh.wgsl), the closures that trace.rs hands to Bvh::traverse;
// their inputs are set in the private variables below before the traversal.
const VISIT_STOCHASTIC: u32 = 0u;
const VISIT_NEXT_K: u32 = 1u;

fn visit(visitor: u32, ray: Ray, leaf: u32, t_max: f32) -> f32 {
    if (visitor == VISIT_STOCHASTIC) {
        return stochastic_visit(ray, leaf, t_max);
    }
    return next_k_visit(ray, leaf, t_max);
}

// What the visitors read: the pixel's decisions; for stochastic_visit the slots first_slot ..
// first_slot + n; for next_k_visit the buffer size k, the hit (after_t, after_id) the hits must
// lie behind, and whether only hits accepted in slot 0 count.
struct VisitInputs {
    pixel_seed: u32,
    n: u32,
    first_slot: u32,
    k: u32,
    after_t: f32,
    after_id: u32,
    accepted: bool,
}

var<private> visit_in: VisitInputs;

fn stochastic_traverse(ray: Ray, pixel_seed: u32, n: u32, first_slot: u32) {
    for (var s = 0u; s < n; s++) {
        iterations += 1u;
        best_t[s] = FAR;
        best_id[s] = NONE;
    }
    visit_in = VisitInputs(pixel_seed, n, first_slot, 0u, 0.0, NONE, false);
    traverse(ray, VISIT_STOCHASTIC);
}

// One particle of Algorithm 1's traversal in each of the n slots (trace.rs
// `TraceScene::stochastic_n`); returns t_max clipped at the farthest slot's hit.
fn stochastic_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let p = particles[leaf];
    let early = params.rng_scheme == 0u;
    if (early) {
        let bound = min(p.opacity, params.alpha_clamp);
        var any = false;
        for (var s = 0u; s < visit_in.n; s++) {
            iterations += 1u;
            slot_u[s] = particle_u(visit_in.pixel_seed, p.id, visit_in.first_slot + s, vec3<f32>(0.0));
            any = any || slot_u[s] < bound;
        }
        if (!any) {
            return t_max;
        }
    }
    let h = intersect(p, ray);
    if (!h.ok) {
        return t_max;
    }
    var farthest = 0.0;
    for (var s = 0u; s < visit_in.n; s++) {
        iterations += 1u;
        if (before(h.t, p.id, best_t[s], best_id[s])) {
            var u = slot_u[s];
            if (!early) {
                u = particle_u(visit_in.pixel_seed, p.id, visit_in.first_slot + s, ray.origin + h.t * ray.dir);
            }
            if (u < h.alpha) {
                best_t[s] = h.t;
                best_id[s] = p.id;
                best_leaf[s] = leaf;
            }
        }
        farthest = max(farthest, best_t[s]);
    }
    return min(farthest, params.t_max);
}

// ---- trace.rs: the k closest hits behind (after_t, after_id) ---------------------------------

var<private> kb_t: array<f32, MAX_SLOTS>;
var<private> kb_id: array<u32, MAX_SLOTS>;
var<private> kb_alpha: array<f32, MAX_SLOTS>;
var<private> kb_len: u32;

// Collect the k closest hits strictly behind (after_t, after_id) into kb_*; with `accepted`,
// only hits accepted by roulette in slot 0 count (depth sampling).
fn next_k(ray: Ray, k: u32, after_t: f32, after_id: u32, accepted: bool, pixel_seed: u32) {
    kb_len = 0u;
    visit_in = VisitInputs(pixel_seed, 1u, 0u, k, after_t, after_id, accepted);
    traverse(ray, VISIT_NEXT_K);
}

// One particle of next_k's traversal: kept in the sorted k-buffer when it is behind the
// previous pass and before the farthest kept hit (trace.rs `KBuf::insert`); returns t_max
// clipped at the farthest kept hit once the buffer is full.
fn next_k_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let p = particles[leaf];
    let k = visit_in.k;
    let h = intersect(p, ray);
    if (!h.ok || !before(visit_in.after_t, visit_in.after_id, h.t, p.id)) {
        return t_max;
    }
    if (kb_len == k && !before(h.t, p.id, kb_t[k - 1u], kb_id[k - 1u])) {
        return t_max;
    }
    if (visit_in.accepted && !(particle_u(visit_in.pixel_seed, p.id, 0u, ray.origin + h.t * ray.dir) < h.alpha)) {
        return t_max;
    }
    // Insertion sort, dropping the farthest when full.
    var i = select(kb_len, k - 1u, kb_len == k);
    if (kb_len < k) {
        kb_len += 1u;
    }
    loop {
        iterations += 1u;
        if (i == 0u || !before(h.t, p.id, kb_t[i - 1u], kb_id[i - 1u])) {
            break;
        }
        kb_t[i] = kb_t[i - 1u];
        kb_id[i] = kb_id[i - 1u];
        kb_alpha[i] = kb_alpha[i - 1u];
        i -= 1u;
    }
    kb_t[i] = h.t;
    kb_id[i] = p.id;
    kb_alpha[i] = h.alpha;
    if (kb_len == k) {
        return kb_t[k - 1u];
    }
    return t_max;
}

// ---- trace.rs: the methods -------------------------------------------------------------------

// A sample: rgb radiance over the background, a = coverage.
fn start_state() -> PassState {
    return PassState(vec3<f32>(0.0), 1.0, params.t_min, NONE, 0u, 0u);
}

// Eq. 3 front to back over the hits in kb_*, continuing the state's radiance and
// transmittance (trace.rs `TraceScene::integrate`).
fn integrate(st: ptr<function, PassState>, dir: vec3<f32>) {
    for (var i = 0u; i < kb_len; i++) {
        iterations += 1u;
        (*st).radiance += (*st).transmittance * kb_alpha[i] * sh_color(kb_id[i], dir);
        (*st).transmittance *= 1.0 - kb_alpha[i];
    }
}

// The integrated hits over the background: L + T × background, coverage 1 − T.
fn over_background(st: PassState) -> vec4<f32> {
    return vec4<f32>(st.radiance + st.transmittance * params.background.xyz, 1.0 - st.transmittance);
}

// The next pass starts behind the last hit of this one; true when the pass was not full (the
// ray has no more hits).
fn advance(st: ptr<function, PassState>) -> bool {
    if (kb_len < params.k) {
        return true;
    }
    (*st).after_t = kb_t[kb_len - 1u];
    (*st).after_id = kb_id[kb_len - 1u];
    return false;
}

// One pass of the k-buffer: the next K hits behind the last one, integrated front to back
// (Eq. 3). true when the ray is finished.
fn kbuffer_step(ray: Ray, pixel_seed: u32, st: ptr<function, PassState>) -> bool {
    if ((*st).transmittance <= params.min_transmittance) {
        return true;
    }
    next_k(ray, params.k, (*st).after_t, (*st).after_id, false, pixel_seed);
    integrate(st, ray.dir);
    return advance(st);
}

// One pass of the vk stochastic pass: its K sorted hits integrated from T = 1, accepted with
// probability 1 − T_pass (radiance divided by it). true when the ray is finished.
fn stochastic_pass_step(ray: Ray, pixel_seed: u32, pass_index: u32, st: ptr<function, PassState>) -> bool {
    next_k(ray, params.k, (*st).after_t, (*st).after_id, false, pixel_seed);
    if (kb_len == 0u) {
        return true;
    }
    var pass_st = start_state();
    integrate(&pass_st, ray.dir);
    let opacity = 1.0 - pass_st.transmittance;
    if (pass_u(pixel_seed, pass_index) < opacity) {
        (*st).radiance = pass_st.radiance / opacity;
        (*st).flags |= ACCEPTED;
        return true;
    }
    return advance(st);
}

// One pass of a multi-pass method (exact, k-buffer, stochastic pass); true when the ray is
// finished.
fn pass_step(ray: Ray, pixel_seed: u32, pass_index: u32, st: ptr<function, PassState>) -> bool {
    if (params.method == METHOD_STOCHASTIC_PASS) {
        return stochastic_pass_step(ray, pixel_seed, pass_index, st);
    }
    return kbuffer_step(ray, pixel_seed, st);
}

// The sample of a finished multi-pass ray.
fn pass_sample(st: PassState) -> vec4<f32> {
    if (params.method != METHOD_STOCHASTIC_PASS) {
        return over_background(st);
    }
    if ((st.flags & ACCEPTED) != 0u) {
        return vec4<f32>(st.radiance, 1.0);
    }
    return vec4<f32>(params.background.xyz, 0.0);
}

// Every pass of a multi-pass method in one invocation.
fn multi_pass(ray: Ray, pixel_seed: u32) -> vec4<f32> {
    var st = start_state();
    for (var pass_index = 0u; pass_index < params.max_passes; pass_index++) {
        iterations += 1u;
        if (pass_step(ray, pixel_seed, pass_index, &st)) {
            break;
        }
    }
    return pass_sample(st);
}

fn stochastic_n(ray: Ray, pixel_seed: u32, n: u32, first_slot: u32) -> vec4<f32> {
    stochastic_traverse(ray, pixel_seed, n, first_slot);
    var sum = vec4<f32>(0.0);
    for (var s = 0u; s < n; s++) {
        iterations += 1u;
        if (best_id[s] == NONE) {
            sum += vec4<f32>(params.background.xyz, 0.0);
        } else {
            sum += vec4<f32>(sh_color(best_id[s], ray.dir), 1.0);
        }
    }
    return sum / f32(n);
}

fn depth_sampling(ray: Ray, pixel_seed: u32) -> vec4<f32> {
    next_k(ray, params.k, params.t_min, NONE, true, pixel_seed);
    var st = start_state();
    integrate(&st, ray.dir);
    return over_background(st);
}

// One frame of the method (trace.rs `TraceScene::sample`).
fn sample(ray: Ray, pixel_seed: u32) -> vec4<f32> {
    switch params.method {
        case METHOD_STOCHASTIC: {
            return stochastic_n(ray, pixel_seed, 1u, 0u);
        }
        case METHOD_STOCHASTIC_N: {
            var sum = vec4<f32>(0.0);
            for (var pass_index = 0u; pass_index < params.m; pass_index++) {
                iterations += 1u;
                sum += stochastic_n(ray, pixel_seed, params.n, pass_index * params.n);
            }
            return sum / f32(params.m);
        }
        case METHOD_DEPTH_SAMPLING: {
            return depth_sampling(ray, pixel_seed);
        }
        default: { // METHOD_EXACT, METHOD_KBUFFER, METHOD_STOCHASTIC_PASS
            return multi_pass(ray, pixel_seed);
        }
    }
}

// ---- camera.rs and frame accumulation (render_frames) ----------------------------------------

fn pixel_ray(x: u32, y: u32) -> Ray {
    let d_cam = vec3<f32>(
        (f32(x) + 0.5 - params.intrinsics.z) / params.intrinsics.x,
        (f32(y) + 0.5 - params.intrinsics.w) / params.intrinsics.y,
        1.0,
    );
    let d = params.cam_row0.xyz * d_cam.x + params.cam_row1.xyz * d_cam.y + params.cam_row2.xyz * d_cam.z;
    return Ray(params.cam_center.xyz, normalize(d), params.cam_row2.xyz);
}

// frame.rs `PixelFrames::push` in f32: fold sample `s` of frame `frame` into a running mean
// and M2 (Welford).
fn welford(mean: ptr<function, vec4<f32>>, m2: ptr<function, vec4<f32>>, s: vec4<f32>, frame: u32) {
    let delta = s - *mean;
    *mean += delta / f32(frame + 1u);
    *m2 += delta * (s - *mean);
}

// One invocation per pixel: frames first_frame .. first_frame + frames of the render, folded
// into the running Welford state of the pixel (mean in out_mean, M2 in out_var.xyz, the most
// loop iterations any of its dispatches spent in out_var.w). Long renders are many dispatches.
@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let index = gid.y * params.size.x + gid.x;
    let ray = pixel_ray(gid.x, gid.y);
    iterations = 0u;
    if (params.mode == MODE_PASS) {
        one_pass(index, gid.xy, ray);
        return;
    }
    var mean = vec4<f32>(0.0);
    var m2 = vec4<f32>(0.0);
    var most = 0.0;
    if (params.first_frame > 0u) {
        mean = out_mean[index];
        m2 = vec4<f32>(out_var[index].xyz, 0.0);
        most = out_var[index].w;
    }
    for (var f = 0u; f < params.frames; f++) {
        iterations += 1u;
        let frame = params.first_frame + f;
        let pixel_seed = xxhash32(vec3<u32>(gid.x, gid.y, frame_key(params.seed, frame)));
        welford(&mean, &m2, sample(ray, pixel_seed), frame);
    }
    out_mean[index] = mean;
    out_var[index] = vec4<f32>(m2.xyz, max(most, f32(iterations)));
}

// Fold one frame's sample into the pixel's running Welford state (pass-per-dispatch mode).
fn fold(index: u32, s: vec4<f32>, frame: u32) {
    var mean = vec4<f32>(0.0);
    var m2 = vec4<f32>(0.0);
    var most = 0.0;
    if (frame > 0u) {
        mean = out_mean[index];
        m2 = vec4<f32>(out_var[index].xyz, 0.0);
    }
    if (frame > 0u || params.pass_index > 0u) {
        most = out_var[index].w;
    }
    welford(&mean, &m2, s, frame);
    out_mean[index] = mean;
    out_var[index] = vec4<f32>(m2.xyz, max(most, f32(iterations)));
}

// Pass-per-dispatch mode: pass `params.pass_index` of frame `params.first_frame` (a k-buffer or
// stochastic pass, or a chunk of params.n of the params.m slots of stochastic-n), continuing the
// ray's state; the sample is folded in when it finishes. Each dispatch then runs one traversal
// per ray, within lavapipe's loop budget.
fn one_pass(index: u32, pixel: vec2<u32>, ray: Ray) {
    var st = pass_state[index];
    if (params.pass_index == 0u) {
        st = start_state();
        if (params.method == METHOD_STOCHASTIC_N) {
            st.transmittance = 0.0; // the stochastic-n state sums colour and coverage instead
        }
    }
    if ((st.flags & DONE) == 0u) {
        let pixel_seed = xxhash32(vec3<u32>(pixel.x, pixel.y, frame_key(params.seed, params.first_frame)));
        var finished = false;
        if (params.method == METHOD_STOCHASTIC_N) {
            // Slots pass_index·n … of the frame's params.m slots: the same decisions as one
            // traversal of all of them, since each slot's pick ignores the others.
            let s = stochastic_n(ray, pixel_seed, params.n, params.pass_index * params.n);
            st.radiance += s.xyz * f32(params.n);
            st.transmittance += s.w * f32(params.n);
            finished = (params.pass_index + 1u) * params.n >= params.m;
        } else {
            finished = pass_step(ray, pixel_seed, params.pass_index, &st);
        }
        if (finished || params.pass_index + 1u >= params.max_passes) {
            st.flags |= DONE;
            var s = pass_sample(st);
            if (params.method == METHOD_STOCHASTIC_N) {
                s = vec4<f32>(st.radiance, st.transmittance) / f32(params.m);
            }
            fold(index, s, params.first_frame);
        } else if (params.first_frame > 0u || params.pass_index > 0u) {
            out_var[index].w = max(out_var[index].w, f32(iterations));
        } else {
            out_var[index] = vec4<f32>(0.0, 0.0, 0.0, f32(iterations));
        }
    }
    pass_state[index] = st;
}
