// Lighting of the splatting kernels (after lighting.wgsl, in raster.wgsl and splat.wgsl): the
// twins of crates/splat-core/src/raster/mod.rs `Rasterizer::lit_color` and the surface look of
// `Rasterizer::light_surface`. Both modules bind the lighting at 13–15.

@group(0) @binding(13) var<storage, read> materials: array<Material>;
@group(0) @binding(14) var<storage, read> lights: array<Light>;
// Per particle in scene order, the rows of its canonical transform M = S⁻¹ Rᵀ with the mean in
// w (three entries): its normal, `canonical_at(3 id + row)` (binding 15, split over more by
// splat_gpu::RasterSplit).

// The splat kernels have no loop budget to count.
fn count_iteration() {
}

// camera.rs `Camera::center`: −Rᵀ t.
fn camera_origin() -> vec3<f32> {
    let t = params.cam_translation.xyz;
    return -(t.x * params.cam_row0.xyz + t.y * params.cam_row1.xyz + t.z * params.cam_row2.xyz);
}

// camera.rs `Camera::ray`: the unit direction through pixel position p (through the lens).
fn pixel_dir(p: vec2<f32>) -> vec3<f32> {
    let d = lens_dir(p);
    return normalize(params.cam_row0.xyz * d.x + params.cam_row1.xyz * d.y + params.cam_row2.xyz * d.z);
}

// raster/mod.rs `Rasterizer::pixel`'s stretch at pixel position p: through the pinhole |d_cam|
// (a splat at view depth z lies at distance z |d_cam| along the ray); through another lens 1
// (splat depths are distances).
fn stretch(p: vec2<f32>) -> f32 {
    if (params.lens == LENS_PINHOLE) {
        return length(lens_dir(p));
    }
    return 1.0;
}

// normal.rs `particle_normal` of particle `id` for the ray (origin, dir), in the settings' mode.
fn splat_normal(id: u32, origin: vec3<f32>, dir: vec3<f32>) -> vec3<f32> {
    let r0 = canonical_at(3u * id);
    let r1 = canonical_at(3u * id + 1u);
    let r2 = canonical_at(3u * id + 2u);
    let mean = vec3<f32>(r0.w, r1.w, r2.w);
    return particle_normal_of(r0.xyz, r1.xyz, r2.xyz, mean, origin, dir, params.normal_mode, params.cutoff);
}

// raster/mod.rs `lit_color`: the splat's colour, lit at its billboard depth along the ray
// through pixel position p with its own normal (the SH colour when lighting is off).
fn splat_lit(s: Splat, p: vec2<f32>) -> vec3<f32> {
    if (params.lit == 0u) {
        return s.color;
    }
    let origin = camera_origin();
    let dir = pixel_dir(p);
    return shade_unshadowed(s.color, s.id, origin, dir, s.depth * stretch(p), splat_normal(s.id, origin, dir));
}

// raster/mod.rs `Rasterizer::depth` with FragmentDepth::MaxDensityPlane: in the particle's
// canonical frame (o, d) = M (origin − μ, dir), t = −o·d / d·d along the sample's unit ray.
fn plane_depth(id: u32, origin: vec3<f32>, dir: vec3<f32>) -> f32 {
    let r0 = canonical_at(3u * id);
    let r1 = canonical_at(3u * id + 1u);
    let r2 = canonical_at(3u * id + 2u);
    let x = origin - vec3<f32>(r0.w, r1.w, r2.w);
    let o = vec3<f32>(dot(r0.xyz, x), dot(r1.xyz, x), dot(r2.xyz, x));
    let d = vec3<f32>(dot(r0.xyz, dir), dot(r1.xyz, dir), dot(r2.xyz, dir));
    return -dot(o, d) / dot(d, d);
}
