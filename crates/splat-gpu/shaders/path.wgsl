// The Monte Carlo path tracer of crates/splat-core/src/path/{mod,bsdf,sampler}.rs, appended to
// trace.wgsl (whose traversals, shadow rays, lights and meshes it calls) with its own entry
// point, `path_main`. A megakernel: one invocation runs whole paths of one pixel, frame after
// frame, and makes the CPU's decisions (the same Sobol points or hashes per pixel, sample index
// and dimension).

// path/mod.rs `PathSettings` as the kernel reads it (96 bytes), mirrored by
// splat_gpu::PathParams.
struct PathParams {
    max_depth: u32,
    roulette_depth: u32,
    // METHOD_STOCHASTIC, METHOD_STOCHASTIC_N or METHOD_EXACT.
    estimator: u32,
    // Instantiations of stochastic-n.
    n: u32,
    // SAMPLER_SOBOL (Owen-scrambled) or SAMPLER_HASH (sampler.rs `SamplerKind`).
    sampler: u32,
    // ENVIRONMENT_CONSTANT or ENVIRONMENT_GRADIENT (path/mod.rs `Environment`).
    environment: u32,
    // Emissive triangles.
    emitters: u32,
    // 1 with a thin lens.
    lens: u32,
    env_a: vec4<f32>,
    env_b: vec4<f32>,
    env_up: vec4<f32>,
    aperture: f32,
    focus_distance: f32,
    pad0: u32,
    pad1: u32,
}


@group(0) @binding(13) var<uniform> path: PathParams;
// Sobol direction numbers, bit-reversed, 16 per dimension (sampler.rs `sobol_directions`).
@group(0) @binding(14) var<storage, read> sobol_vectors: array<u32>;
// Emissive triangles: cumulative selection probability (f32 bits) and leaf-order index
// (path/mod.rs `Emitters`).
@group(0) @binding(15) var<storage, read> emitters: array<vec2<u32>>;
// P(select) / area of every leaf-order triangle (0 for the others).
@group(0) @binding(16) var<storage, read> emitter_density: array<f32>;

// ---- sampler.rs --------------------------------------------------------------------------------

// Whether the pipeline is the path tracer's (splat_gpu::PathPipeline sets it): trace.wgsl's
// particle_u and visit_shadow then take the path's decisions. A pipeline-overridable constant,
// so that the ray-tracing kernel compiles without the path's code in its traversal loops.
override PATH_MODE: bool = false;
// The pixel's sequence seed (Sobol) or pixel-and-frame seed (hash), and the sample index.
var<private> path_seed: u32;
var<private> path_index: u32;
// The bounce whose light samples path_light_sample draws.
var<private> path_bounce: u32;
// The shadow kind of the current shadow ray (SHADOWS_STOCHASTIC or SHADOWS_EXACT).
var<private> path_shadows: u32;

// splat_gpu::layout::SAMPLER_* and ENVIRONMENT_* (a test compares them).
const SAMPLER_SOBOL: u32 = 0u;
const SAMPLER_HASH: u32 = 1u;
const ENVIRONMENT_CONSTANT: u32 = 0u;
const ENVIRONMENT_GRADIENT: u32 = 1u;
const PATH_DIM_ID: u32 = 0xfffffff8u;
const LIGHT_STREAM: u32 = 0xffffffefu;
const DIMS_PER_BOUNCE: u32 = 8u;
const SOBOL_DIMENSIONS: u32 = 256u;

// sobol_burley `parts::hash` (skeeto's hash-prospector).
fn sobol_hash(x: u32) -> u32 {
    var n = x ^ 0xe6fe3bebu;
    n ^= n >> 16u;
    n *= 0x7feb352du;
    n ^= n >> 15u;
    n *= 0x846ca68bu;
    n ^= n >> 16u;
    return n;
}

// sobol_burley `parts::owen_scramble_rev`.
fn owen_scramble_rev(x: u32, scramble: u32) -> u32 {
    var n = x;
    n ^= n * 0x3d20adeau;
    n += scramble;
    n *= (scramble >> 16u) | 1u;
    n ^= n * 0x05526c56u;
    n ^= n * 0x53a22864u;
    return n;
}

// sobol_burley `parts::sobol_rev`: the top 16 bits of the reversed index select the direction
// numbers, unrolled (no loop: lavapipe's budget counts loops).
fn sobol_rev(index_rev: u32, dim: u32) -> u32 {
    let v = dim * 16u;
    var s = 0u;
    s ^= select(0u, sobol_vectors[v + 0u], (index_rev & 0x80000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 1u], (index_rev & 0x40000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 2u], (index_rev & 0x20000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 3u], (index_rev & 0x10000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 4u], (index_rev & 0x08000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 5u], (index_rev & 0x04000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 6u], (index_rev & 0x02000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 7u], (index_rev & 0x01000000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 8u], (index_rev & 0x00800000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 9u], (index_rev & 0x00400000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 10u], (index_rev & 0x00200000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 11u], (index_rev & 0x00100000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 12u], (index_rev & 0x00080000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 13u], (index_rev & 0x00040000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 14u], (index_rev & 0x00020000u) != 0u);
    s ^= select(0u, sobol_vectors[v + 15u], (index_rev & 0x00010000u) != 0u);
    return s;
}

// sobol_burley `sample`: dimension `dim` of point `index` of the sequence seeded by `seed`.
fn sobol_sample(index: u32, dim: u32, seed: u32) -> f32 {
    let shuffled = owen_scramble_rev(reverseBits(index), sobol_hash(seed ^ 0x79c68e4au));
    let sobol = sobol_rev(shuffled, dim);
    var c = 0x912f69bau;
    switch dim & 3u {
        case 1u: { c = 0x174f18abu; }
        case 2u: { c = 0x691e72cau; }
        case 3u: { c = 0xb40cc1b8u; }
        default: {}
    }
    let scramble = (dim >> 2u) ^ (seed * 0x9c8f2d3bu) ^ c;
    let bits = reverseBits(owen_scramble_rev(sobol, sobol_hash(scramble)));
    return bitcast<f32>((bits >> 9u) | 0x3f800000u) - 1.0;
}

// sampler.rs `PathSampler::new`.
fn path_sampler_begin(x: u32, y: u32, seed: u32, index: u32) {
    path_index = index;
    if (path.sampler == SAMPLER_SOBOL) {
        path_seed = xxhash32(vec3<u32>(x, y, seed ^ 0x50B01000u));
    } else {
        path_seed = xxhash32(vec3<u32>(x, y, frame_key(seed, index)));
    }
}

// sampler.rs `PathSampler::draw`: dimension `dim` of stream `stream`.
fn path_draw(dim: u32, stream: u32) -> f32 {
    if (path.sampler == SAMPLER_HASH) {
        return unit_f32(pcg(xxhash32(vec3<u32>(path_seed, stream, dim))));
    }
    let block = dim / SOBOL_DIMENSIONS;
    let seed = xxhash32(vec3<u32>(path_seed, stream, block | ((path_index >> 16u) << 8u)));
    return sobol_sample(path_index & 0xffffu, dim % SOBOL_DIMENSIONS, seed);
}

fn path_dim(dim: u32) -> f32 {
    return path_draw(dim, PATH_DIM_ID);
}

fn path_dim2(dim: u32) -> vec2<f32> {
    return vec2<f32>(path_dim(dim), path_dim(dim + 1u));
}

// sampler.rs `PathSampler::particle`: the acceptance draw of particle `id` in `decision`.
fn path_particle(id: u32, decision: u32) -> f32 {
    if (path.sampler == SAMPLER_HASH) {
        return path_draw(decision, id);
    }
    let seed = xxhash32(vec3<u32>(path_seed, id, decision | ((path_index >> 16u) << 24u)));
    return sobol_sample(path_index & 0xffffu, 0u, seed);
}

// sampler.rs `PathDecide::light_sample`.
fn path_light_sample(light: u32) -> vec2<f32> {
    let dim = dim_light_point(path_bounce);
    let stream = LIGHT_STREAM - light;
    return vec2<f32>(path_draw(dim, stream), path_draw(dim + 1u, stream));
}

// sampler.rs `Dim::index`.
fn dim_lobe(b: u32) -> u32 {
    return 4u + DIMS_PER_BOUNCE * b;
}
fn dim_direction(b: u32) -> u32 {
    return 5u + DIMS_PER_BOUNCE * b;
}
fn dim_light_pick(b: u32) -> u32 {
    return 7u + DIMS_PER_BOUNCE * b;
}
fn dim_light_point(b: u32) -> u32 {
    return 8u + DIMS_PER_BOUNCE * b;
}
fn dim_roulette(b: u32) -> u32 {
    return 10u + DIMS_PER_BOUNCE * b;
}

// sampler.rs `decision` and `shadow_decision`.
fn decision(b: u32, slot: u32) -> u32 {
    return (b << 12u) | slot;
}
fn shadow_decision(b: u32, light: u32) -> u32 {
    return 0x00800000u | (b << 12u) | light;
}

// ---- bsdf.rs -----------------------------------------------------------------------------------

const PI: f32 = 3.14159265;
const MIN_ROUGHNESS: f32 = 1e-3;

struct Bsdf {
    diffuse: f32,
    albedo: vec3<f32>,
    conductor: f32,
    dielectric: f32,
    alpha: f32,
    eta: f32,
}

// bsdf.rs `BsdfSample`; `ok` is false for an absorbed draw.
struct BsdfSample {
    wi: vec3<f32>,
    weight: vec3<f32>,
    pdf: f32,
    delta: bool,
    ok: bool,
}

fn ggx_d(h: vec3<f32>, alpha: f32) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let k = h.z * h.z * (a2 - 1.0) + 1.0;
    return a2 / (PI * k * k);
}

fn ggx_lambda(w: vec3<f32>, alpha: f32) -> f32 {
    let cos2 = w.z * w.z;
    if (cos2 <= 0.0) {
        return FAR;
    }
    let tan2 = max(1.0 - cos2, 0.0) / cos2;
    return 0.5 * (sqrt(1.0 + alpha * alpha * tan2) - 1.0);
}

fn ggx_g1(w: vec3<f32>, alpha: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(w, alpha));
}

fn ggx_g2(wo: vec3<f32>, wi: vec3<f32>, alpha: f32) -> f32 {
    return 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha));
}

fn visible_normal_pdf(wo: vec3<f32>, h: vec3<f32>, alpha: f32) -> f32 {
    return ggx_g1(wo, alpha) * max(dot(wo, h), 0.0) * ggx_d(h, alpha) / wo.z;
}

fn visible_normal(wo: vec3<f32>, alpha: f32, u: vec2<f32>) -> vec3<f32> {
    let wh = normalize(vec3<f32>(alpha * wo.x, alpha * wo.y, wo.z));
    let phi = 2.0 * PI * u.x;
    let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
    let sin_theta = sqrt(clamp(1.0 - z * z, 0.0, 1.0));
    let h = vec3<f32>(sin_theta * cos(phi), sin_theta * sin(phi), z) + wh;
    return normalize(vec3<f32>(alpha * h.x, alpha * h.y, max(h.z, 0.0)));
}

fn reflect_about(wo: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    return 2.0 * dot(wo, h) * h - wo;
}

fn cosine_hemisphere(u: vec2<f32>) -> vec3<f32> {
    let d = concentric_disk(u);
    return vec3<f32>(d.x, d.y, sqrt(max(1.0 - dot(d, d), 0.0)));
}

// bsdf.rs `conductor_eval`: (f|cos θᵢ|, p).
fn conductor_eval(wo: vec3<f32>, wi: vec3<f32>, alpha: f32) -> vec2<f32> {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return vec2<f32>(0.0);
    }
    let h = normalize(wo + wi);
    let d = ggx_d(h, alpha);
    return vec2<f32>(d * ggx_g2(wo, wi, alpha) / (4.0 * wo.z), visible_normal_pdf(wo, h, alpha) / (4.0 * dot(wo, h)));
}

// bsdf.rs `dielectric_eval`: (f|cos θᵢ|, p).
fn dielectric_eval(wo: vec3<f32>, wi: vec3<f32>, alpha: f32, eta: f32) -> vec2<f32> {
    if (wo.z <= 0.0 || wi.z == 0.0) {
        return vec2<f32>(0.0);
    }
    let is_reflection = wi.z > 0.0;
    let raw = select(wo + eta * wi, wo + wi, is_reflection);
    let len = length(raw);
    if (!(len > 0.0 && len < FAR)) {
        return vec2<f32>(0.0);
    }
    var h = raw / len;
    if (h.z < 0.0) {
        h = -h;
    }
    let cos_o = dot(wo, h);
    let cos_i = dot(wi, h);
    if (cos_o <= 0.0 || (is_reflection && cos_i <= 0.0) || (!is_reflection && cos_i >= 0.0)) {
        return vec2<f32>(0.0);
    }
    let f = fresnel(cos_o, 1.0 / eta);
    let d = ggx_d(h, alpha);
    let g2 = ggx_g2(wo, wi, alpha);
    let vn = visible_normal_pdf(wo, h, alpha);
    if (is_reflection) {
        return vec2<f32>(f * d * g2 / (4.0 * wo.z), f * vn / (4.0 * cos_o));
    }
    let denom = (cos_o + eta * cos_i) * (cos_o + eta * cos_i);
    let jacobian = eta * eta * abs(cos_i) / denom;
    return vec2<f32>((1.0 - f) * d * g2 * cos_o * jacobian / (wo.z * eta * eta), (1.0 - f) * vn * jacobian);
}

// bsdf.rs `Bsdf::eval`: f|cos θᵢ| (rgb) and the mixture density (w).
fn bsdf_eval(b: Bsdf, wo: vec3<f32>, wi: vec3<f32>) -> vec4<f32> {
    var f = vec3<f32>(0.0);
    var pdf = 0.0;
    if (b.diffuse > 0.0 && wi.z > 0.0) {
        f += b.diffuse * b.albedo * (wi.z / PI);
        pdf += b.diffuse * wi.z / PI;
    }
    if (b.alpha != 0.0) {
        if (b.conductor > 0.0) {
            let c = conductor_eval(wo, wi, b.alpha);
            f += vec3<f32>(b.conductor * c.x);
            pdf += b.conductor * c.y;
        }
        if (b.dielectric > 0.0) {
            let d = dielectric_eval(wo, wi, b.alpha, b.eta);
            f += vec3<f32>(b.dielectric * d.x);
            pdf += b.dielectric * d.y;
        }
    }
    return vec4<f32>(f, pdf);
}

fn absorbed() -> BsdfSample {
    return BsdfSample(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, false, false);
}

fn delta_sample(wi: vec3<f32>, weight: f32) -> BsdfSample {
    return BsdfSample(wi, vec3<f32>(weight), 0.0, true, true);
}

// bsdf.rs `Bsdf::sample`.
fn bsdf_sample(b: Bsdf, wo: vec3<f32>, u_lobe: f32, u: vec2<f32>) -> BsdfSample {
    var pick = u_lobe;
    var wi = vec3<f32>(0.0);
    if (pick < b.diffuse) {
        wi = cosine_hemisphere(u);
    } else {
        pick -= b.diffuse;
        if (pick < b.conductor) {
            if (b.alpha == 0.0) {
                return delta_sample(vec3<f32>(-wo.x, -wo.y, wo.z), 1.0);
            }
            wi = reflect_about(wo, visible_normal(wo, b.alpha, u));
            if (!(wi.z > 0.0)) {
                return absorbed();
            }
        } else if (pick - b.conductor < b.dielectric) {
            if (b.alpha == 0.0) {
                let f = fresnel(wo.z, 1.0 / b.eta);
                if (u.x < f) {
                    return delta_sample(vec3<f32>(-wo.x, -wo.y, wo.z), 1.0);
                }
                let r = refract_dir(-wo, vec3<f32>(0.0, 0.0, 1.0), 1.0 / b.eta);
                if (r.w == 0.0) {
                    return absorbed();
                }
                return delta_sample(r.xyz, 1.0 / (b.eta * b.eta));
            }
            let h = visible_normal(wo, b.alpha, u);
            let cos_o = dot(wo, h);
            if (cos_o <= 0.0) {
                return absorbed();
            }
            if ((pick - b.conductor) / b.dielectric < fresnel(cos_o, 1.0 / b.eta)) {
                wi = reflect_about(wo, h);
                if (!(wi.z > 0.0)) {
                    return absorbed();
                }
            } else {
                let r = refract_dir(-wo, h, 1.0 / b.eta);
                if (r.w == 0.0 || !(r.z < 0.0)) {
                    return absorbed();
                }
                wi = r.xyz;
            }
        } else {
            return absorbed();
        }
    }
    let e = bsdf_eval(b, wo, wi);
    if (!(e.w > 0.0) || all(e.xyz == vec3<f32>(0.0))) {
        return absorbed();
    }
    return BsdfSample(wi, e.xyz / e.w, e.w, false, true);
}

// ---- path/mod.rs -------------------------------------------------------------------------------

// `Environment::radiance`.
fn environment(dir: vec3<f32>) -> vec3<f32> {
    if (path.environment == ENVIRONMENT_CONSTANT) {
        return path.env_a.xyz;
    }
    return mix(path.env_a.xyz, path.env_b.xyz, max(dot(dir, path.env_up.xyz), 0.0));
}

// `emission`: the local share of k_e ⊙ c.
fn mesh_emission(m: MeshMaterial) -> vec3<f32> {
    return local_share(m) * m.shading.emissive * m.color;
}

fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    let b2 = b * b;
    return select(0.0, a2 / (a2 + b2), a2 + b2 > 0.0);
}

// `same_side`.
fn same_side(w: vec3<f32>, face: vec3<f32>, local_z: f32) -> bool {
    return (dot(w, face) > 0.0) == (local_z > 0.0);
}

// A shading frame (`Frame`): tangent, bitangent, normal.
struct Frame {
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
}

fn frame_of(n: vec3<f32>) -> Frame {
    let p = orthonormal_pair(n);
    return Frame(p[0], p[1], n);
}

fn to_local(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, f.t), dot(v, f.b), dot(v, f.n));
}

fn to_world(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return v.x * f.t + v.y * f.b + v.z * f.n;
}

// `Emitters::pick`: the first triangle whose cumulative probability exceeds u.
fn pick_emitter(u: f32) -> u32 {
    var lo = 0u;
    var hi = path.emitters;
    loop {
        iterations += 1u;
        if (lo >= hi) {
            break;
        }
        let mid = (lo + hi) / 2u;
        if (bitcast<f32>(emitters[mid].x) <= u) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return emitters[min(lo, path.emitters - 1u)].y;
}

// One point on the emissive meshes as the irradiance estimate arriving at a point (ok false
// where there is none), and the density of its direction per solid angle.
struct EmitterSample {
    inc: Incident,
    pdf: f32,
}

// `emitter_sample`.
fn emitter_sample(x: vec3<f32>, b: u32) -> EmitterSample {
    let none = EmitterSample(Incident(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), false), 0.0);
    if (path.emitters == 0u) {
        return none;
    }
    let k = pick_emitter(path_dim(dim_light_pick(b)));
    let tri = triangles[k];
    let u = path_dim2(dim_light_point(b));
    var b1 = u.x;
    var b2 = u.y;
    if (u.x + u.y > 1.0) {
        b1 = 1.0 - u.x;
        b2 = 1.0 - u.y;
    }
    let p = tri.p0 + b1 * tri.e1 + b2 * tri.e2;
    let to = p - x;
    let distance = length(to);
    if (!(distance > 0.0)) {
        return none;
    }
    let l = to / distance;
    let cos_l = abs(dot(normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0)), l));
    if (!(cos_l > 0.0)) {
        return none;
    }
    let pdf = emitter_density[k] * distance * distance / cos_l;
    let le = mesh_emission(mesh_materials[tri.mesh]);
    return EmitterSample(Incident(l, distance - surface_offset(p), le / pdf, true), pdf);
}

// `emitter_pdf`.
fn emitter_pdf(h: SurfaceHit, dir: vec3<f32>) -> f32 {
    let tri = triangles[h.triangle];
    let cos_l = abs(dot(normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0)), dir));
    return select(0.0, emitter_density[h.triangle] * h.t * h.t / cos_l, cos_l > 0.0);
}

// `PathTracer::visibility`: trace.wgsl's `visibility` by the path's shadow kind, stochastic or
// (exact) the transmittance.
fn path_visibility(x: vec3<f32>, offset: f32, inc: Incident, slot: u32, exact: bool) -> f32 {
    path_shadows = select(SHADOWS_STOCHASTIC, SHADOWS_EXACT, exact);
    return visibility(x, offset, inc, 0u, slot).x;
}

// `gaussian_radiance`: Lᵢ of the Gaussian in leaf `leaf` hit at t.
fn gaussian_radiance(leaf: u32, t: f32, ray: Ray, b: u32, exact: bool) -> vec3<f32> {
    let id = particles[leaf].id;
    let c = sh_color(id, ray.dir);
    let m = material_of(id);
    if (m.emissive_only == 1u) {
        return c;
    }
    let n = particle_normal(leaf, ray);
    let x = ray.origin + t * ray.dir;
    let v = -ray.dir;
    let offset = params.shadow_offset;
    var lit = material_unlit(m, c);
    if (params.light_count == 0u) {
        lit += material_direct(m, c, n, v, Incident(-ray.dir, t, vec3<f32>(1.0), true));
    }
    for (var j = 0u; j < params.light_count; j++) {
        iterations += 1u;
        let inc = light_incident(lights[j], x, path_light_sample(j));
        if (!inc.ok) {
            continue;
        }
        let direct = material_direct(m, c, n, v, inc);
        if (any(direct != vec3<f32>(0.0))) {
            lit += direct * path_visibility(x, offset, inc, shadow_decision(b, j), exact);
        }
    }
    let e = emitter_sample(x, b);
    if (e.inc.ok) {
        let direct = material_direct(m, c, n, v, e.inc);
        if (any(direct != vec3<f32>(0.0))) {
            lit += direct * path_visibility(x, offset, e.inc, shadow_decision(b, 64u), exact);
        }
    }
    return lit;
}

// `PathTracer::gaussians`: the radiance the segment's Gaussians send back (xyz) and the weight
// of the path past them (w).
fn path_gaussians(seg: Ray, b: u32) -> vec4<f32> {
    var radiance = vec3<f32>(0.0);
    if (path.estimator == METHOD_EXACT) {
        var t = 1.0;
        var after_t = seg.t_min;
        var after_id = NONE;
        loop {
            iterations += 1u;
            next_k(seg, MAX_SLOTS, after_t, after_id, false, 0u);
            let len = kb.len;
            for (var i = 0u; i < len; i++) {
                iterations += 1u;
                let alpha = kb.alpha[i];
                radiance += t * alpha * gaussian_radiance(kb.leaf[i], kb.t[i], seg, b, true);
                t *= 1.0 - alpha;
            }
            if (len < MAX_SLOTS) {
                break;
            }
            after_t = kb.t[len - 1u];
            after_id = kb.id[len - 1u];
        }
        return vec4<f32>(radiance, t);
    }
    let n = select(1u, path.n, path.estimator == METHOD_STOCHASTIC_N);
    stochastic_traverse(seg, 0u, n, decision(b, 0u));
    var empty = 0u;
    for (var s = 0u; s < n; s++) {
        iterations += 1u;
        if (best_id[s] == NONE) {
            empty += 1u;
        } else {
            radiance += gaussian_radiance(best_leaf[s], best_t[s], seg, b, false);
        }
    }
    return vec4<f32>(radiance / f32(n), f32(empty) / f32(n));
}

// `direct_at_surface`: every world light and one emitter sample (MIS) at a mesh vertex.
fn direct_at_surface(x: vec3<f32>, face: vec3<f32>, fr: Frame, wo: vec3<f32>, bs: Bsdf, b: u32) -> vec3<f32> {
    let offset = surface_offset(x);
    var sum = vec3<f32>(0.0);
    for (var j = 0u; j < params.light_count; j++) {
        iterations += 1u;
        let inc = light_incident(lights[j], x, path_light_sample(j));
        if (!inc.ok) {
            continue;
        }
        let wi = to_local(fr, inc.l);
        if (!same_side(inc.l, face, wi.z)) {
            continue;
        }
        let f = bsdf_eval(bs, wo, wi).xyz;
        if (any(f != vec3<f32>(0.0))) {
            sum += f * inc.irradiance * path_visibility(x, offset, inc, shadow_decision(b, j), false);
        }
    }
    let e = emitter_sample(x, b);
    if (e.inc.ok) {
        let wi = to_local(fr, e.inc.l);
        var f = vec4<f32>(0.0);
        if (same_side(e.inc.l, face, wi.z)) {
            f = bsdf_eval(bs, wo, wi);
        }
        if (any(f.xyz != vec3<f32>(0.0))) {
            let v = path_visibility(x, offset, e.inc, shadow_decision(b, 64u), false);
            sum += f.xyz * e.inc.irradiance * v * power_heuristic(e.pdf, f.w);
        }
    }
    return sum;
}

// `PathTracer::camera_ray`: a random point in the pixel and, with a lens, on the lens.
fn path_camera_ray(x: u32, y: u32) -> Ray {
    let offset = path_dim2(0u);
    var ray = camera_ray(x, y, offset);
    if (path.lens == 1u && path.aperture > 0.0) {
        let on_lens = vec3<f32>(path.aperture * concentric_disk(path_dim2(2u)), 0.0);
        ray.origin = params.cam_center.xyz + camera_to_world(on_lens);
        ray.dir = normalize(camera_to_world(path.focus_distance * camera_dir(x, y, offset) - on_lens));
    }
    return ray;
}

// `PathTracer::radiance`: one path.
fn path_radiance(camera: Ray) -> vec3<f32> {
    var ray = camera;
    var beta = vec3<f32>(1.0);
    var l = vec3<f32>(0.0);
    var mesh_t_min = ray.t_min;
    var prev_pdf = -1.0; // < 0: the camera or a delta lobe
    for (var b = 0u; b <= path.max_depth; b++) {
        iterations += 1u;
        path_bounce = b;
        var hit = SurfaceHit(FAR, NONE, 0.0, 0.0);
        if (params.mesh_root != NONE) {
            hit = mesh_traverse(params.mesh_root, Ray(ray.origin, ray.dir, ray.view, max(ray.t_min, mesh_t_min), ray.t_max), false);
        }
        var seg = ray;
        if (hit.triangle != NONE) {
            seg.t_max = hit.t;
        }
        let g = path_gaussians(seg, b);
        l += beta * g.xyz;
        beta *= g.w;
        if (all(beta == vec3<f32>(0.0))) {
            break;
        }
        if (hit.triangle == NONE) {
            l += beta * environment(ray.dir);
            break;
        }
        let x = ray.origin + hit.t * ray.dir;
        let tri = triangles[hit.triangle];
        let m = mesh_materials[tri.mesh];
        let le = mesh_emission(m);
        if (any(le != vec3<f32>(0.0))) {
            var w = 1.0;
            if (prev_pdf >= 0.0) {
                w = power_heuristic(prev_pdf, emitter_pdf(hit, ray.dir));
            }
            l += beta * le * w;
        }
        if (b == path.max_depth) {
            break;
        }
        let face_out = normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0));
        let outside = dot(ray.dir, face_out) < 0.0;
        let face = select(-face_out, face_out, outside);
        let n = surface_normal(hit, ray);
        let fr = frame_of(n);
        let wo = to_local(fr, -ray.dir);
        var bs = Bsdf(local_share(m), min(m.shading.diffuse * m.color, vec3<f32>(1.0)), m.mirror, m.transmission, 0.0, select(1.0 / m.ior, m.ior, outside));
        if (m.roughness >= MIN_ROUGHNESS) {
            bs.alpha = m.roughness * m.roughness;
        }
        if (bs.diffuse > 0.0 || (bs.alpha != 0.0 && bs.conductor + bs.dielectric > 0.0)) {
            l += beta * direct_at_surface(x, face, fr, wo, bs, b);
        }
        let next = bsdf_sample(bs, wo, path_dim(dim_lobe(b)), path_dim2(dim_direction(b)));
        if (!next.ok) {
            break;
        }
        let dir = normalize(to_world(fr, next.wi));
        if (!same_side(dir, face, next.wi.z)) {
            break;
        }
        beta *= next.weight;
        prev_pdf = select(next.pdf, -1.0, next.delta);
        if (b + 1u >= path.roulette_depth) {
            let q = min(max(max(beta.x, beta.y), beta.z), 0.95);
            if (path_dim(dim_roulette(b)) >= q) {
                break;
            }
            beta /= q;
        }
        ray = Ray(x, dir, dir, 0.0, params.t_max);
        mesh_t_min = surface_offset(x);
    }
    return l;
}

// One invocation per pixel: frames first_frame .. first_frame + frames, one path each, folded
// into the pixel's running mean and M2 (as trace.wgsl's main), the loop count in out_var.w.
@compute @workgroup_size(8, 8, 1)
fn path_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    bounce = 0u;
    let index = gid.y * params.size.x + gid.x;
    iterations = 0u;
    var most = 0.0;
    if (params.first_frame > 0u) {
        most = out_var[index].w;
    }
    for (var f = 0u; f < params.frames; f++) {
        iterations += 1u;
        let frame = params.first_frame + f;
        path_sampler_begin(gid.x, gid.y, params.seed, frame);
        let l = path_radiance(path_camera_ray(gid.x, gid.y));
        sample_pick = no_pick();
        fold(index, vec4<f32>(l, 1.0), frame);
    }
    out_var[index].w = max(most, f32(iterations));
}
