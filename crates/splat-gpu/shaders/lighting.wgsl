// Twin of crates/splat-core/src/lighting.rs, prepended to the kernels that light particles:
// the material of a splat set, the incident light of one light sample and the Blinn–Phong
// shading Lit(x, n, v, c) = (k_e + k_a) c + Σ_l V_l E_l [k_d c max(0, n·l) + k_s max(0, n·h)^s].

// composite.rs DEGENERATE_NORMAL: an integrated normal shorter than this faces the camera.
const DEGENERATE_NORMAL: f32 = 1e-6;

// One splat set's material and first particle id (64 bytes), mirrored by splat_gpu::GpuMaterial.
struct Material {
    emissive: vec3<f32>,
    first: u32,
    ambient: vec3<f32>,
    shininess: f32,
    diffuse: vec3<f32>,
    // 1 when the set only emits (lighting.rs `Material::is_emissive`).
    emissive_only: u32,
    specular: vec3<f32>,
    pad: u32,
}

// One light (64 bytes), mirrored by splat_gpu::GpuLight; the cone's cosines come from the host.
struct Light {
    position: vec3<f32>,
    kind: u32,
    direction: vec3<f32>,
    radius: f32,
    color: vec3<f32>,
    intensity: f32,
    cos_inner: f32,
    cos_outer: f32,
    pad0: u32,
    pad1: u32,
}

const LIGHT_POINT: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_DIRECTIONAL: u32 = 2u;

// lighting.rs `Incident`; `ok` is false where the light sends nothing.
struct Incident {
    l: vec3<f32>,
    distance: f32,
    irradiance: vec3<f32>,
    ok: bool,
}

// normal.rs NormalMode: NORMAL_PLANE (max-density plane) or NORMAL_ELLIPSOID (kernel ellipsoid).
const NORMAL_PLANE: u32 = 0u;
const NORMAL_ELLIPSOID: u32 = 1u;

// normal.rs `particle_normal`: n ∝ Mᵀ x_c for the rows of the canonical transform
// M = S⁻¹ Rᵀ, at x_c = o_c (the max-density plane), or for NORMAL_ELLIPSOID where the ray enters
// the cutoff sphere |x_c| = s (o_c when it starts inside or misses it; hit.rs `sphere_entry`'s
// stable discriminant); oriented toward the ray origin (−dir when degenerate).
fn particle_normal_of(row0: vec3<f32>, row1: vec3<f32>, row2: vec3<f32>, mean: vec3<f32>, origin: vec3<f32>, dir: vec3<f32>, mode: u32, cutoff: f32) -> vec3<f32> {
    let rel = origin - mean;
    let oc = vec3<f32>(dot(row0, rel), dot(row1, rel), dot(row2, rel));
    var xc = oc;
    let s2 = cutoff * cutoff;
    if (mode == NORMAL_ELLIPSOID && dot(oc, oc) > s2) {
        let dc = vec3<f32>(dot(row0, dir), dot(row1, dir), dot(row2, dir));
        let a = dot(dc, dc);
        let cr = cross(oc, dc);
        let disc = a * s2 - dot(cr, cr);
        if (disc >= 0.0) {
            let t = (-dot(oc, dc) - sqrt(disc)) / a;
            if (t > 0.0) {
                xc = oc + t * dc;
            }
        }
    }
    let m = row0 * xc.x + row1 * xc.y + row2 * xc.z;
    let rcp = 1.0 / sqrt(dot(m, m));
    var n = -dir;
    if (rcp > 0.0 && rcp < 3.0e38) {
        n = m * rcp;
    }
    if (dot(n, dir) > 0.0) {
        n = -n;
    }
    return n;
}

// lighting.rs `concentric_disk`.
fn concentric_disk(u: vec2<f32>) -> vec2<f32> {
    let p = 2.0 * u - vec2<f32>(1.0);
    if (p.x == 0.0 && p.y == 0.0) {
        return vec2<f32>(0.0);
    }
    var r = p.y;
    var theta = 1.5707964 - 0.7853982 * (p.x / p.y);
    if (abs(p.x) > abs(p.y)) {
        r = p.x;
        theta = 0.7853982 * (p.y / p.x);
    }
    return r * vec2<f32>(cos(theta), sin(theta));
}

// glam's `Vec3::any_orthonormal_pair` (Duff et al. 2017), with Rust's signum (−0 is negative).
fn orthonormal_pair(n: vec3<f32>) -> array<vec3<f32>, 2> {
    let sign = select(1.0, -1.0, (bitcast<u32>(n.z) >> 31u) == 1u);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return array<vec3<f32>, 2>(
        vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3<f32>(b, sign + n.y * n.y * a, -n.y),
    );
}

// lighting.rs `disk_point`: a point of the disk of `radius` around `centre` facing `axis`.
fn disk_point(centre: vec3<f32>, axis: vec3<f32>, radius: f32, u: vec2<f32>) -> vec3<f32> {
    if (radius == 0.0) {
        return centre;
    }
    let b = orthonormal_pair(axis);
    let d = radius * concentric_disk(u);
    return centre + d.x * b[0] + d.y * b[1];
}

fn point_incident(x: vec3<f32>, light: vec3<f32>, e: vec3<f32>) -> Incident {
    let to = light - x;
    let d2 = dot(to, to);
    if (!(d2 > 0.0)) {
        return Incident(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), false);
    }
    let distance = sqrt(d2);
    return Incident(to / distance, distance, e / d2, true);
}

fn smoothstep_(a: f32, b: f32, x: f32) -> f32 {
    let t = clamp((x - a) / (b - a), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// lighting.rs `Light::incident`: the light arriving at `x` from sample `u` of the emitter.
fn light_incident(light: Light, x: vec3<f32>, u: vec2<f32>) -> Incident {
    let e = light.color * light.intensity;
    if (light.kind == LIGHT_DIRECTIONAL) {
        let back = -light.direction;
        let b = orthonormal_pair(back);
        let d = concentric_disk(u);
        let l = normalize(back + light.radius * (d.x * b[0] + d.y * b[1]));
        return Incident(l, 3.0e38, e, true);
    }
    var sample = light.position;
    if (light.radius != 0.0) {
        sample = disk_point(light.position, normalize(light.position - x), light.radius, u);
    }
    var inc = point_incident(x, sample, e);
    if (light.kind == LIGHT_SPOT && inc.ok) {
        let c = dot(-inc.l, light.direction);
        var cone = smoothstep_(light.cos_outer, light.cos_inner, c);
        if (light.cos_inner <= light.cos_outer) {
            cone = select(0.0, 1.0, c >= light.cos_outer);
        }
        inc.irradiance *= cone;
        inc.ok = cone > 0.0;
    }
    return inc;
}

// lighting.rs `Material::unlit`: (k_e + k_a) c.
fn material_unlit(m: Material, c: vec3<f32>) -> vec3<f32> {
    return (m.emissive + m.ambient) * c;
}

// lighting.rs `Material::direct`: one light's Blinn–Phong term before visibility.
fn material_direct(m: Material, c: vec3<f32>, n: vec3<f32>, v: vec3<f32>, inc: Incident) -> vec3<f32> {
    let n_l = dot(n, inc.l);
    if (!(n_l > 0.0)) {
        return vec3<f32>(0.0);
    }
    let hv = inc.l + v;
    let hl = length(hv);
    var specular = 0.0;
    if (any(m.specular != vec3<f32>(0.0))) {
        var h = vec3<f32>(0.0);
        if (hl > 0.0) {
            h = hv * (1.0 / hl);
        }
        // max(0, n·h)^s with 0^0 = 1, as Rust's powf has it (WGSL's pow is undefined at 0).
        let nh = max(dot(n, h), 0.0);
        specular = select(select(0.0, 1.0, m.shininess == 0.0), pow(nh, m.shininess), nh > 0.0);
    }
    return inc.irradiance * (m.diffuse * c * n_l + m.specular * specular);
}

// lighting.rs `Lighting::material`: the set whose first id is the last at or below `id`. Reads
// the including kernel's `materials` and `params.set_count`; `count_iteration` is the kernel's
// loop counter (trace.wgsl's lavapipe budget) or nothing.
fn material_of(id: u32) -> Material {
    var m = materials[0];
    for (var i = 1u; i < params.set_count; i++) {
        count_iteration();
        if (materials[i].first > id) {
            break;
        }
        m = materials[i];
    }
    return m;
}

// lighting.rs `Lighting::shade_unshadowed`: Lit of particle `id` hit at t along the ray
// (origin, dir) with normal n, every light visible and sampled at its centre (the raster
// pipelines have no shadows, vk_gaussian_splatting Lighting §3); c itself when lighting is off or
// the set only emits. Reads `params.lit`, `params.light_count` and `lights`.
fn shade_unshadowed(c: vec3<f32>, id: u32, origin: vec3<f32>, dir: vec3<f32>, t: f32, n: vec3<f32>) -> vec3<f32> {
    if (params.lit == 0u) {
        return c;
    }
    return shade_material_unshadowed(material_of(id), c, origin, dir, t, n);
}

// `shade_unshadowed` with the material given (a mesh's, lit whatever the splats' sets say).
fn shade_material_unshadowed(m: Material, c: vec3<f32>, origin: vec3<f32>, dir: vec3<f32>, t: f32, n: vec3<f32>) -> vec3<f32> {
    if (m.emissive_only == 1u) {
        return c;
    }
    let x = origin + t * dir;
    let v = -dir;
    var sum = material_unlit(m, c);
    if (params.light_count == 0u) {
        return sum + material_direct(m, c, n, v, Incident(-dir, t, vec3<f32>(1.0), true));
    }
    for (var j = 0u; j < params.light_count; j++) {
        count_iteration();
        let inc = light_incident(lights[j], x, vec2<f32>(0.5));
        if (inc.ok) {
            sum += material_direct(m, c, n, v, inc);
        }
    }
    return sum;
}
