// Twin of crates/splat-core/src/mesh.rs, prepended to the kernels that walk meshes (trace.wgsl
// and the raster pipeline's mesh pre-pass, mesh_prepass.wgsl): the surface hit, its normal and
// bounces, and the traversal of the triangle BVH (after bvh.wgsl; the triangle itself is
// triangle.wgsl's). Reads the including kernel's `triangles`, `node_at` and `iterations`, and
// calls its `transparent_stops`.

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

// mesh.rs `Meshes::closest` and `SurfaceHit::facing`: the interpolated shading normal turned
// toward the ray (the face normal where interpolation turns it away).
fn surface_normal(h: SurfaceHit, ray: Ray) -> vec3<f32> {
    return facing_normal(triangles[h.triangle], h.b1, h.b2, ray.dir);
}

// mesh.rs `Meshes::closest` (filtered false) over the mesh BVH whose root is node `root`: every
// triangle of every leaf the ray overlaps, Möller–Trumbore with the core's edge slack; the
// closest hit within (t_min, t_max], ties to the lower leaf index. Filtered, a transparent
// triangle counts only where the including kernel's `transparent_stops(triangle, (t, b1, b2))`
// says its crossing stops the ray: never in the raster pre-pass (`Meshes::closest_opaque`:
// transparent triangles are the raster operations' fragments), by the path's decision in the
// path tracer (`Meshes::closest_accepted`).
fn mesh_traverse(root: u32, ray: Ray, filtered: bool) -> SurfaceHit {
    var best = SurfaceHit(FAR, NONE, 0.0, 0.0);
    let inv = safe_inverse(ray.dir);
    var t_max = ray.t_max;
    traversal_begin(root);
    loop {
        iterations += 1u;
        let r = traversal_next_leaf(ray.origin, inv, ray.t_min, t_max);
        if (r == NONE) {
            break;
        }
        for (var k = leaf_first(r); k < leaf_end(r); k++) {
            iterations += 1u;
            let tri = triangles[k];
            let h = triangle_intersect(tri, ray);
            if (h.x < 0.0 || h.x > t_max || (filtered && is_transparent(tri) && !transparent_stops(tri, h))) {
                continue;
            }
            if (h.x < best.t || (h.x == best.t && k < best.triangle)) {
                best = SurfaceHit(h.x, k, h.y, h.z);
                t_max = h.x;
            }
        }
    }
    return best;
}
