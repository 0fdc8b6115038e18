// Lighting a hit and its shadow rays (normal.rs, lighting.rs), the twin of splat-core's
// trace/shadow.rs: sorted, stochastic and exact shadows, meshes blocking the light. Part of
// the trace kernel (splat_gpu::TRACE_WGSL).

// normal.rs `particle_normal` of the particle in leaf `leaf` (lighting.wgsl `particle_normal_of`).
fn particle_normal(leaf: u32, ray: Ray) -> vec3<f32> {
    let p = particle_at(leaf);
    return particle_normal_of(p.row0, p.row1, p.row2, p.mean, ray.origin, ray.dir, params.normal_mode, params.cutoff);
}

// composite.rs `integrated_normal` for a ray with hits: the integrated normal, or the
// camera-facing −dir when it is shorter than DEGENERATE_NORMAL.
fn unit_normal(sum: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let len = length(sum);
    return select(-dir, sum / len, len > DEGENERATE_NORMAL);
}

// lighting.wgsl's loop counter: every loop body counts toward lavapipe's budget.
fn count_iteration() {
    iterations += 1u;
}

// rng.rs `RayRng::light_sample`.
fn light_sample(pixel_key: u32, light: u32, slot: u32) -> vec2<f32> {
    let key = (bounce_slot(slot) << 7u) | (light << 1u);
    return vec2<f32>(
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, LIGHT_ID, key)))),
        unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, LIGHT_ID, key | 1u)))),
    );
}

// lighting.rs `shadow_slot`.
fn shadow_slot(slot: u32, light: u32) -> u32 {
    return 0x80000000u | (slot << 6u) | light;
}

// shadow.rs `TraceScene::lit`: Lit(x, n, v, c) of particle `id` at distance t along the ray;
// c itself when lighting is off or the particle's set only emits.
fn lit(c: vec3<f32>, id: u32, t: f32, n: vec3<f32>, ray: Ray, pixel_key: u32, slot: u32) -> vec3<f32> {
    if (params.lit == 0u) {
        return c;
    }
    return lit_material(material_of(id), c, t, n, ray, pixel_key, slot, params.shadow_offset);
}

// lighting.rs `Lighting::shade_material`: Lit(x, n, v, c) with material m, each light's shadow
// ray starting `offset` along it.
fn lit_material(m: Material, c: vec3<f32>, t: f32, n: vec3<f32>, ray: Ray, pixel_key: u32, slot: u32, offset: f32) -> vec3<f32> {
    if (m.emissive_only == 1u) {
        return c;
    }
    let x = ray.origin + t * ray.dir;
    let v = -ray.dir;
    if (params.light_count == 0u) {
        // lighting.rs `headlight`: from the eye, no falloff, no shadows.
        return material_unlit(m, c) + material_direct(m, c, n, v, Incident(-ray.dir, t, vec3<f32>(1.0), true));
    }
    var sum = material_unlit(m, c);
    for (var j = 0u; j < params.light_count; j++) {
        iterations += 1u;
        let light = lights[j];
        var u = vec2<f32>(0.0);
        if (light.radius > 0.0) {
            u = light_sample(pixel_key, j, slot);
        }
        let inc = light_incident(light, x, u);
        if (!inc.ok) {
            continue;
        }
        let direct = material_direct(m, c, n, v, inc);
        if (any(direct != vec3<f32>(0.0))) {
            sum += direct * visibility(x, offset, inc, pixel_key, shadow_slot(slot, j));
        }
    }
    return sum;
}

// The decisions of the current stochastic shadow ray and what the shadow visitors found.
struct ShadowInputs {
    pixel_key: u32,
    slot: u32,
}

var<private> shadow_in: ShadowInputs;
var<private> shadow_t: f32;
var<private> shadow_blocked: bool;
var<private> shadow_mesh: bool;
// The light the meshes let through: Π (1 − α) of the transparent triangles crossed.
var<private> shadow_mesh_t: f32;

// shadow.rs `TraceScene::shadow_visibility`: the shadow ray from x + offset l toward the light,
// by the world's shadow kind (the path tracer's, path_shadows, in its pipeline); an opaque mesh
// on the way blocks it, transparent ones let Π (1 − α) through.
fn visibility(x: vec3<f32>, offset: f32, inc: Incident, pixel_key: u32, slot: u32) -> vec3<f32> {
    let shadow = Ray(x + offset * inc.l, inc.l, inc.l, params.t_min, min(inc.distance - offset, params.t_max));
    let kind = shadow_kind();
    if (shadow.t_max <= params.t_min || kind == SHADOWS_NONE) {
        return vec3<f32>(1.0);
    }
    // One traversal call for every kind and the meshes (see traverse_shadow).
    shadow_t = 1.0;
    shadow_in = ShadowInputs(pixel_key, slot);
    shadow_blocked = false;
    shadow_mesh = false;
    shadow_mesh_t = 1.0;
    sb.len = 0u;
    traverse_shadow(shadow);
    if (shadow_mesh) {
        return vec3<f32>(0.0);
    }
    switch kind {
        case SHADOWS_EXACT: {
            return vec3<f32>(shadow_mesh_t * shadow_t);
        }
        case SHADOWS_STOCHASTIC: {
            return select(vec3<f32>(shadow_mesh_t), vec3<f32>(0.0), shadow_blocked);
        }
        default: { // SHADOWS_SORTED
            return shadow_mesh_t * sorted_shadow(shadow);
        }
    }
}

// shadow.rs `TraceScene::transmittance`: Π(1 − αᵢ) over every hit.
fn transmittance_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let h = intersect(particle_at(leaf), ray);
    if (h.ok) {
        shadow_t *= 1.0 - h.alpha;
    }
    return t_max;
}

// shadow.rs `TraceScene::occluded`: Russian roulette on each hit, stopped at the first accept.
fn occluded_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    if (shadow_blocked) {
        return t_max;
    }
    let p = particle_at(leaf);
    if (params.rng_scheme == RNG_HASH
        && particle_u(shadow_in.pixel_key, p.id, shadow_in.slot, vec3<f32>(0.0)) >= min(p.opacity, params.alpha_clamp)) {
        return t_max;
    }
    let h = intersect(p, ray);
    if (!h.ok) {
        return t_max;
    }
    if (particle_u(shadow_in.pixel_key, p.id, shadow_in.slot, ray.origin + h.t * ray.dir) < h.alpha) {
        shadow_blocked = true;
        return -1.0; // every node is now beyond t_max
    }
    return t_max;
}

// shadow.rs `TraceScene::sorted_shadow`'s pass: the shadow_k nearest hits, into sb.
fn shadow_sorted_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let p = particle_at(leaf);
    let h = intersect(p, ray);
    if (!h.ok) {
        return t_max;
    }
    return hitbuf_insert(&sb, params.shadow_k, h.t, p.id, h.alpha, leaf, t_max);
}

// shadow.rs `TraceScene::sorted_shadow`: T ← T ((1 − α) + colored α c) front to back over the
// pass in sb, in shadow once every channel is below the threshold.
fn sorted_shadow(ray: Ray) -> vec3<f32> {
    var t = vec3<f32>(1.0);
    for (var i = 0u; i < sb.len; i++) {
        iterations += 1u;
        var tint = vec3<f32>(0.0);
        if (params.shadow_colored > 0.0) {
            tint = sh_color(sb.id[i], ray.dir);
        }
        t *= vec3<f32>(1.0 - sb.alpha[i]) + params.shadow_colored * sb.alpha[i] * tint;
        if (max(max(t.x, t.y), t.z) < params.shadow_threshold) {
            return vec3<f32>(0.0);
        }
    }
    return t;
}
