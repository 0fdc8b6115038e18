// Twin of crates/splat-core/src/mesh.rs's triangle and material (`PreparedTriangle`,
// `MeshMaterial`), prepended to every kernel that meets a triangle: the ray tracer and the mesh
// pre-pass (through mesh.wgsl, which walks their BVH) and the raster operations, which draw
// transparent triangles as fragments (rop.wgsl). Reads common.wgsl's `Ray` and lighting.wgsl's
// `Material`.

// mesh.rs `EDGE_SLACK`.
const EDGE_SLACK: f32 = 1e-6;

// One mesh triangle (96 bytes), mirrored by splat_gpu::GpuTriangle (mesh.rs `PreparedTriangle`):
// in the mesh BVH's leaf order where a kernel walks the BVH, in the meshes' order where the
// raster operations draw it.
struct Triangle {
    p0: vec3<f32>,
    mesh: u32,
    e1: vec3<f32>,
    alpha0: f32,
    e2: vec3<f32>,
    alpha1: f32,
    n0: vec3<f32>,
    alpha2: f32,
    n1: vec3<f32>,
    // Its place in the meshes' order (the id keying a transparent triangle's decisions).
    order: u32,
    n2: vec3<f32>,
    pad: u32,
}

// A mesh's material (112 bytes), mirrored by splat_gpu::GpuMeshMaterial (mesh.rs
// `MeshMaterial`): base colour, mirror and glass shares, index of refraction, the mirror's tint,
// and the shading shares.
struct MeshMaterial {
    color: vec3<f32>,
    mirror: f32,
    transmission: f32,
    ior: f32,
    // GGX roughness of the mirror and glass shares (the path tracer's).
    roughness: f32,
    // 1 with the path tracer's dielectric specular layer over the local share.
    specular_layer: u32,
    // The mirror share's reflectance at normal incidence (Schlick's F₀).
    mirror_tint: vec3<f32>,
    pad2: u32,
    shading: Material,
}

// mesh.rs `MeshMaterial::local_share`: 1 − mirror − transmission.
fn local_share(m: MeshMaterial) -> f32 {
    return max(1.0 - m.mirror - m.transmission, 0.0);
}

// mesh.rs `schlick`: F₀ + (1 − F₀)(1 − cos θᵢ)⁵, glTF's conductor Fresnel.
fn schlick(f0: vec3<f32>, cos_i: f32) -> vec3<f32> {
    let m = clamp(1.0 - cos_i, 0.0, 1.0);
    let m2 = m * m;
    return f0 + (vec3<f32>(1.0) - f0) * (m2 * m2 * m);
}

// mesh.rs `MeshMaterial::layer_f0`: ((ior − 1)/(ior + 1))² with the specular layer, 0 without.
fn layer_f0(m: MeshMaterial) -> f32 {
    let r = (m.ior - 1.0) / (m.ior + 1.0);
    return select(0.0, r * r, m.specular_layer == 1u);
}

// mesh.rs `MeshMaterial::mirror_reflectance`: mirror × F(cos θᵢ).
fn mirror_reflectance(m: MeshMaterial, cos_i: f32) -> vec3<f32> {
    return m.mirror * schlick(m.mirror_tint, cos_i);
}

// mesh.rs `MeshMaterial::background_share`: what a forward-shaded surface (the raster
// pre-pass's, the raster operations') takes from the background, its mirror and glass shares.
fn background_share(m: MeshMaterial, cos_i: f32) -> vec3<f32> {
    return mirror_reflectance(m, cos_i) + m.transmission;
}

// mesh.rs `PreparedTriangle::is_transparent`: an opacity below 1 somewhere.
fn is_transparent(tri: Triangle) -> bool {
    return tri.alpha0 < 1.0 || tri.alpha1 < 1.0 || tri.alpha2 < 1.0;
}

// mesh.rs `PreparedTriangle::alpha_at`: the opacity at barycentrics (b1, b2), clamped; a
// constant opacity exactly.
fn alpha_at(tri: Triangle, b1: f32, b2: f32) -> f32 {
    if (tri.alpha0 == tri.alpha1 && tri.alpha1 == tri.alpha2) {
        return tri.alpha0;
    }
    return clamp((1.0 - b1 - b2) * tri.alpha0 + b1 * tri.alpha1 + b2 * tri.alpha2, 0.0, 1.0);
}

// mesh.rs `PreparedTriangle::plane_barycentrics`: (b1, b2, 1) where the ray's line meets the
// triangle's plane, inside the triangle or not; (0, 0, 0) when the ray runs parallel to it.
fn plane_barycentrics(tri: Triangle, ray: Ray) -> vec3<f32> {
    let p = cross(ray.dir, tri.e2);
    let det = dot(tri.e1, p);
    if (abs(det) < 1e-12) {
        return vec3<f32>(0.0);
    }
    let s = ray.origin - tri.p0;
    return vec3<f32>(dot(s, p) / det, dot(ray.dir, cross(s, tri.e1)) / det, 1.0);
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

// mesh.rs `canonical`: whether edge direction d is the canonical one of its two (its first
// non-zero coordinate positive).
fn canonical_edge(d: vec3<f32>) -> bool {
    if (d.x != 0.0) {
        return d.x > 0.0;
    }
    if (d.y != 0.0) {
        return d.y > 0.0;
    }
    return d.z > 0.0;
}

// mesh.rs `PreparedTriangle::crosses`: `triangle_intersect` within (t_min, t_max) with each edge
// shared by two triangles counted once (a crossing within the slack of an edge belongs to the
// triangle that runs along it in its canonical direction); t = −1 where it does not cross.
fn triangle_crosses(tri: Triangle, ray: Ray) -> vec3<f32> {
    let h = triangle_intersect(tri, ray);
    if (h.x < 0.0 || !(h.x < ray.t_max) || !owns_crossing(tri, h.y, h.z)) {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    return h;
}

// mesh.rs `PreparedTriangle::owns`: whether a crossing at barycentrics (b1, b2) is this
// triangle's, inside it beyond the slack or within the slack of an edge it runs along in the
// canonical direction.
fn owns_crossing(tri: Triangle, b1: f32, b2: f32) -> bool {
    // The edge opposite each vertex: p1 → p2, p2 → p0, p0 → p1.
    return ((1.0 - b1 - b2) > EDGE_SLACK || canonical_edge(tri.e2 - tri.e1))
        && (b1 > EDGE_SLACK || canonical_edge(-tri.e2))
        && (b2 > EDGE_SLACK || canonical_edge(tri.e1));
}

// v / |v| where that is finite, else `fallback` (glam's `try_normalize`).
fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let rcp = 1.0 / length(v);
    return select(fallback, v * rcp, rcp > 0.0 && rcp < 3.0e38);
}

// mesh.rs `SurfaceHit::facing`'s normal at barycentrics (b1, b2) for a ray of direction d: the
// interpolated shading normal turned toward the ray (the face normal where interpolation turns
// it away).
fn facing_normal(tri: Triangle, b1: f32, b2: f32, d: vec3<f32>) -> vec3<f32> {
    let face = normalize_or(cross(tri.e1, tri.e2), vec3<f32>(0.0));
    let n = normalize_or((1.0 - b1 - b2) * tri.n0 + b1 * tri.n1 + b2 * tri.n2, face);
    let side = select(-1.0, 1.0, dot(d, face) < 0.0);
    return select(side * face, side * n, dot(side * n, d) < 0.0);
}
