// The Monte Carlo path tracer of crates/splat-core/src/path/mod.rs (with sampler.wgsl and
// bsdf.wgsl, the twins of path/sampler.rs and path/bsdf.rs), appended to trace.wgsl (whose
// traversals, shadow rays, lights and meshes it calls) with its own entry point, `path_main`. A megakernel: one invocation runs whole paths of one pixel, frame after
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
    pad0: u32,
    env_a: vec4<f32>,
    env_b: vec4<f32>,
    env_up: vec4<f32>,
}

@group(0) @binding(13) var<storage, read> path: PathParams;
// Sobol direction numbers, bit-reversed, 16 per dimension (sampler.rs `sobol_directions`).
@group(0) @binding(14) var<storage, read> sobol_vectors: array<u32>;
// Emissive triangles: cumulative selection probability (f32 bits) and leaf-order index
// (path/mod.rs `Emitters`).
@group(0) @binding(15) var<storage, read> emitters: array<vec2<u32>>;
// P(select) / area of every leaf-order triangle (0 for the others).
@group(0) @binding(16) var<storage, read> emitter_density: array<f32>;

// Whether the pipeline is the path tracer's (GpuTracer::render_path compiles it so): trace.wgsl's
// particle_u and visit_shadow then take the path's decisions. A pipeline-overridable constant,
// so that the ray-tracing kernel compiles without the path's code in its traversal loops.
override PATH_MODE: bool = false;
// The shadow kind of the current shadow ray (SHADOWS_STOCHASTIC or SHADOWS_EXACT).
var<private> path_shadows: u32;
// splat_gpu::layout::ENVIRONMENT_* (a test compares them).
const ENVIRONMENT_CONSTANT: u32 = 0u;
const ENVIRONMENT_GRADIENT: u32 = 1u;

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
    let le = mesh_emission(mesh_materials[tri.mesh]) * alpha_at(tri, b1, b2);
    return EmitterSample(Incident(l, distance - surface_offset(p), le / pdf, true), pdf);
}

// mesh.wgsl's filter of transparent crossings, `PathTracer::surface`: a crossing the triangle
// owns stops the path with probability the opacity there (the triangle's draw of the segment
// after bounce path_bounce, keyed by its place in the meshes' order).
fn transparent_stops(tri: Triangle, h: vec3<f32>) -> bool {
    return owns_crossing(tri, h.y, h.z)
        && path_particle(tri.order, surface_decision(path_bounce)) - params.u_shift < alpha_at(tri, h.y, h.z);
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
    let id = particle_at(leaf).id;
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
            next_k(seg, MAX_HITS, after_t, after_id, false, 0u);
            let len = kb.len;
            for (var i = 0u; i < len; i++) {
                iterations += 1u;
                let alpha = kb.alpha[i];
                radiance += t * alpha * gaussian_radiance(kb.leaf[i], kb.t[i], seg, b, true);
                t *= 1.0 - alpha;
            }
            if (len < MAX_HITS) {
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

// `PathTracer::camera_ray`: a random point in the pixel and, with the settings' lens, on the
// lens, from the path's own Sobol dimensions.
fn path_camera_ray(x: u32, y: u32) -> Ray {
    return lens_ray(x, y, path_dim2(0u), path_dim2(2u));
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
            hit = mesh_traverse(params.mesh_root, Ray(ray.origin, ray.dir, ray.view, max(ray.t_min, mesh_t_min), ray.t_max), true);
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
        var bs = Bsdf(local_share(m), min(m.shading.diffuse * m.color, vec3<f32>(1.0)), m.mirror, m.mirror_tint, m.transmission, layer_f0(m), 0.0, select(1.0 / m.ior, m.ior, outside));
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
        path_sampler_begin(gid.x, gid.y, params.seed, params.run_first + frame);
        let l = path_radiance(path_camera_ray(gid.x, gid.y));
        sample_pick = no_pick();
        fold(index, vec4<f32>(l, 1.0), frame);
    }
    out_var[index].w = max(most, f32(iterations));
}
