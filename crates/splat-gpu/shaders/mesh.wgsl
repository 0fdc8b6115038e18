// Twin of crates/splat-core/src/mesh.rs, prepended to the kernels that meet meshes (trace.wgsl
// and the raster pipeline's mesh pre-pass, mesh_prepass.wgsl): triangles, their intersection and
// normals, and the traversal of their BVH (after bvh.wgsl). Reads the including kernel's
// `triangles`, `nodes` and `iterations`, and bvh.wgsl's `Ray`.

// mesh.rs `EDGE_SLACK`.
const EDGE_SLACK: f32 = 1e-6;

// One mesh triangle in the mesh BVH's leaf order (96 bytes), mirrored by splat_gpu::GpuTriangle
// (mesh.rs `PreparedTriangle`).
struct Triangle {
    p0: vec3<f32>,
    mesh: u32,
    e1: vec3<f32>,
    pad0: u32,
    e2: vec3<f32>,
    pad1: u32,
    n0: vec3<f32>,
    pad2: u32,
    n1: vec3<f32>,
    pad3: u32,
    n2: vec3<f32>,
    pad4: u32,
}

// A mesh's material (96 bytes), mirrored by splat_gpu::GpuMeshMaterial (mesh.rs `MeshMaterial`):
// base colour, mirror and glass shares, index of refraction, and the shading shares.
struct MeshMaterial {
    color: vec3<f32>,
    mirror: f32,
    transmission: f32,
    ior: f32,
    // GGX roughness of the mirror and glass shares (the path tracer's).
    roughness: f32,
    pad1: u32,
    shading: Material,
}

// mesh.rs `MeshMaterial::local_share`: 1 − mirror − transmission.
fn local_share(m: MeshMaterial) -> f32 {
    return max(1.0 - m.mirror - m.transmission, 0.0);
}

// mesh.rs `reflect`.
fn reflect_dir(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - 2.0 * dot(d, n) * n;
}

// mesh.rs `refract`: the refracted unit direction through a surface of unit normal n facing the
// incoming ray, eta = n_incident / n_transmitted; w = 0 under total internal reflection.
fn refract_dir(d: vec3<f32>, n: vec3<f32>, eta: f32) -> vec4<f32> {
    if (eta == 1.0) {
        return vec4<f32>(d, 1.0);
    }
    let cos_i = -dot(d, n);
    let sin2_t = eta * eta * max(1.0 - cos_i * cos_i, 0.0);
    if (sin2_t >= 1.0) {
        return vec4<f32>(0.0);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    return vec4<f32>(normalize(eta * d + (eta * cos_i - cos_t) * n), 1.0);
}

// mesh.rs `fresnel`: the unpolarised reflectance of a smooth dielectric.
fn fresnel(cos_i: f32, eta: f32) -> f32 {
    if (eta == 1.0) {
        return 0.0;
    }
    let sin2_t = eta * eta * max(1.0 - cos_i * cos_i, 0.0);
    if (sin2_t >= 1.0) {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5 * (r_s * r_s + r_p * r_p);
}

// Whether a ray of direction d meets the hit's triangle from outside (against its outward face
// normal), mesh.rs `SurfaceHit::facing`.
fn from_outside(h: SurfaceHit, d: vec3<f32>) -> bool {
    let tri = triangles[h.triangle];
    return dot(d, normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0))) < 0.0;
}

// Where a ray meets a mesh: distance, leaf-order triangle (NONE: no hit) and barycentrics.
struct SurfaceHit {
    t: f32,
    triangle: u32,
    b1: f32,
    b2: f32,
}

// mesh.rs `PreparedTriangle::intersect` (Möller–Trumbore with the edge slack): (t, b1, b2) for
// t > ray.t_min; t = −1 on a miss. The caller checks t against its t_max.
fn triangle_intersect(tri: Triangle, ray: Ray) -> vec3<f32> {
    let miss = vec3<f32>(-1.0, 0.0, 0.0);
    let p = cross(ray.dir, tri.e2);
    let det = dot(tri.e1, p);
    if (abs(det) < 1e-12) {
        return miss;
    }
    let inv = 1.0 / det;
    let s = ray.origin - tri.p0;
    let b1 = dot(s, p) * inv;
    if (!(b1 >= -EDGE_SLACK && b1 <= 1.0 + EDGE_SLACK)) {
        return miss;
    }
    let q = cross(s, tri.e1);
    let b2 = dot(ray.dir, q) * inv;
    if (b2 < -EDGE_SLACK || b1 + b2 > 1.0 + EDGE_SLACK) {
        return miss;
    }
    let t = dot(tri.e2, q) * inv;
    if (!(t > ray.t_min)) {
        return miss;
    }
    return vec3<f32>(t, b1, b2);
}

// v / |v| where that is finite, else `fallback` (glam's `try_normalize`).
fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let rcp = 1.0 / length(v);
    return select(fallback, v * rcp, rcp > 0.0 && rcp < 3.0e38);
}

// mesh.rs `Meshes::closest` and `SurfaceHit::facing`: the interpolated shading normal turned
// toward the ray (the face normal where interpolation turns it away).
fn surface_normal(h: SurfaceHit, ray: Ray) -> vec3<f32> {
    let tri = triangles[h.triangle];
    let face = normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0));
    let n = normalize_or((1.0 - h.b1 - h.b2) * tri.n0 + h.b1 * tri.n1 + h.b2 * tri.n2, face);
    let side = select(-1.0, 1.0, dot(ray.dir, face) < 0.0);
    return select(side * face, side * n, dot(side * n, ray.dir) < 0.0);
}

// Meshes::closest (any_hit false) and Meshes::occludes (any_hit true) over the mesh BVH whose
// root is node `root`: every
// triangle of every leaf the ray overlaps, Möller–Trumbore with the core's edge slack; the
// closest hit within (t_min, t_max], ties to the lower leaf index, or the first hit within
// (t_min, t_max). One loop for both: the shadow ray and the camera ray call it at one site each.
fn mesh_traverse(root: u32, ray: Ray, any_hit: bool) -> SurfaceHit {
    var best = SurfaceHit(FAR, NONE, 0.0, 0.0);
    let inv = safe_inverse(ray.dir);
    var t_max = ray.t_max;
    traversal_begin(root, ray.origin, inv, ray.t_min, t_max);
    loop {
        iterations += 1u;
        let node = traversal_next_leaf(ray.origin, inv, ray.t_min, t_max);
        if (node == NONE) {
            break;
        }
        let nd = nodes[node];
        for (var k = nd.first; k < nd.first + nd.count; k++) {
            iterations += 1u;
            let h = triangle_intersect(triangles[k], ray);
            if (h.x < 0.0) {
                continue;
            }
            if (any_hit) {
                if (h.x < ray.t_max) {
                    return SurfaceHit(h.x, k, h.y, h.z);
                }
            } else if (h.x <= t_max && (h.x < best.t || (h.x == best.t && k < best.triangle))) {
                best = SurfaceHit(h.x, k, h.y, h.z);
                t_max = h.x;
            }
        }
    }
    return best;
}
