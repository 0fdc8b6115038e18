// Types shared by the raster kernels (prepended to raster.wgsl, splat.wgsl and fold.wgsl).

// Everything fixed for one camera (192 bytes), mirrored by splat_gpu::RasterParams.
struct RasterParams {
    cam_row0: vec4<f32>,
    cam_row1: vec4<f32>,
    cam_row2: vec4<f32>,
    // World-to-camera translation (camera.rs: p_cam = R p + t).
    cam_translation: vec4<f32>,
    // fx, fy, cx, cy.
    intrinsics: vec4<f32>,
    background: vec4<f32>,
    size: vec2<u32>,
    // Particles in the scene.
    count: u32,
    sh_degree: u32,
    kernel_degree: u32,
    alpha_clamp: f32,
    alpha_cull: f32,
    iso_threshold: f32,
    // 3DGS's frustum guard: |x/z| and |y/z| are clamped to these before the Jacobian.
    guard: vec2<f32>,
    // Tiles across and down.
    tiles: vec2<u32>,
    // Draw mode: 0 over, 1 under, 2 stochastic splat, 3 Enderton, 4 stratified, 5 stratified
    // without the scramble.
    mode: u32,
    // Splat extent: EXTENT_3DGS or EXTENT_SQRT8.
    extent: u32,
    // Lighting (lighting.rs): 1 when a set reflects light; the look (LOOK_*); lights and sets.
    lit: u32,
    look: u32,
    light_count: u32,
    set_count: u32,
    // Ray range of the mesh pre-pass (settings.rs `t_min`, `t_max`).
    t_min: f32,
    t_max: f32,
    // 1 when the scene has meshes: the splats are depth tested against the mesh pre-pass and
    // the fold blends its colour under them.
    meshes: u32,
    // FIRST_HIT_SORTED or FIRST_HIT_ACCEPTED when the tile rasterizer writes the hybrid
    // pipeline's first hit (splat_gpu::GpuFirstHit: L and T before lighting and what lies
    // behind, the picked depth or −1) instead of a pixel; 0 otherwise.
    first_hit: u32,
    // Samples per pixel S (raster/samples.rs), at the positions of the sample-offset buffer.
    samples: u32,
    // The order of the Hilbert curve over the image (rng.rs `hilbert_order`): Laine–Karras's
    // pixel ids.
    hilbert_order: u32,
    // The scene's screen filter (splat_core::ScreenFilter): Σ′ = Σ₂ + filter_variance I, and
    // where filter_compensates is 1 the opacity × √(det Σ₂ / det Σ′).
    filter_variance: f32,
    filter_compensates: u32,
    // The camera's lens (LENS_*) and its distortion (lens.wgsl).
    lens: u32,
    // Splatting's near plane (RenderSettings::near): nearer centres are culled.
    near: f32,
    distortion: array<vec4<f32>, 3>,
    // normal.rs NormalMode (NORMAL_*) and the cutoff of its ellipsoid (Eq. 2).
    normal_mode: u32,
    cutoff: f32,
    // The frame key and u_shift of a StochasticSplats first hit (FrameParams' fields, which the
    // tile pass does not bind).
    frame_key: u32,
    u_shift: f32,
}

// What changes from frame to frame (16 bytes, one dynamic-offset slot per frame).
struct FrameParams {
    key: u32,
    index: u32,
    // frame.rs AccumulationFormat (ACCUMULATION_*): how the running mean is stored.
    accumulation: u32,
    // splat_core::Frames::u_shift, a test hook: every u is drawn as u − u_shift (0 in renders).
    u_shift: f32,
}

// One particle projected to the image (64 bytes), mirrored by splat_gpu::GpuSplat and
// splat_core::raster::Splat. An empty rect (x0 >= x1) marks a culled particle.
struct Splat {
    mean: vec2<f32>,
    depth: f32,
    opacity: f32,
    conic: vec3<f32>,
    id: u32,
    color: vec3<f32>,
    // The largest Mahalanobis term of the footprint: EXTENT_SQ, else the visible radius²
    // (UNBOUNDED without an alpha cull).
    bound: f32,
    rect: vec4<u32>,
}

// params.mode: which draw the splatting pipeline runs (splat_gpu::raster::Draw, checked by a test).
const MODE_OVER: u32 = 0u;
const MODE_UNDER: u32 = 1u;
const MODE_STOCHASTIC: u32 = 2u;
// The raster operations of the compute tile pass (rop.wgsl), whose target holds each pixel's
// resolved samples, what lies behind them included.
const MODE_ENDERTON: u32 = 3u;
const MODE_STRATIFIED: u32 = 4u;
const MODE_STRATIFIED_PLAIN: u32 = 5u;
// params.extent (splat_core::raster::SplatExtent): the 3DGS rasterizer's 16 × 16 tiles around
// its box of half-width ⌈3 √λ_max⌉ (BOX_SIGMAS, with 3DGS's floor EIGEN_FLOOR under the
// eigenvalue discriminant; BLOCK), the √8σ ellipse (fragments with a Mahalanobis term above
// EXTENT_SQ are discarded), or gsplat's: every pixel above the alpha cull.
// params.first_hit: the tile pass writes sorted splatting's first hit (Eq. 3 in front of the
// meshes) or StochasticSplats' (the closest accepted fragment).
const FIRST_HIT_SORTED: u32 = 1u;
const FIRST_HIT_ACCEPTED: u32 = 2u;
// The volumetric look's first hit from sorted splatting: a pass that counts each sample's
// fragments, then one that writes them for the ray tracer to light (splat_gpu::GpuFragment).
const FIRST_HIT_COUNT: u32 = 3u;
const FIRST_HIT_FRAGMENTS: u32 = 4u;
const LOOK_SURFACE: u32 = 0u;
const LOOK_VOLUMETRIC: u32 = 1u;
const EXTENT_3DGS: u32 = 0u;
const EXTENT_SQRT8: u32 = 1u;
const EXTENT_ALPHA_CULL: u32 = 2u;
const EXTENT_SQ: f32 = 8.0;
const BOX_SIGMAS: f32 = 3.0;
const EIGEN_FLOOR: f32 = 0.1;
const BLOCK: f32 = 16.0;
const UNBOUNDED: f32 = 3.40282347e38; // f32::MAX

// project.rs `Splat::covers`: whether pixel position p lies in the splat's footprint, its rect
// and its bounding ellipse.
fn covers(s: Splat, p: vec2<f32>, params: RasterParams) -> bool {
    let r = vec4<f32>(s.rect);
    return all(p >= r.xy) && all(p < r.zw) && mahalanobis(s, p) <= s.bound;
}

// kernel.rs `KernelParams::visible_radius`, squared: the Mahalanobis term beyond which the
// alpha cull takes every hit of opacity o.
fn visible_radius_sq(o: f32, params: RasterParams) -> f32 {
    if (params.alpha_cull <= 0.0) {
        return UNBOUNDED;
    }
    if (!(o >= params.alpha_cull)) {
        return 0.0;
    }
    let x = (log(o / params.alpha_cull) + 1e-5) / 4.5;
    return 9.0 * pow(x, 2.0 / f32(params.kernel_degree)) * 1.001;
}

// A = dᵀ Σ′⁻¹ d at continuous pixel position p (raster/project.rs, Splat::mahalanobis).
fn mahalanobis(s: Splat, p: vec2<f32>) -> f32 {
    let d = p - s.mean;
    return s.conic.x * d.x * d.x + 2.0 * s.conic.y * d.x * d.y + s.conic.z * d.y * d.y;
}

// alpha = opacity × response(A) at p, clamped; 0 when outside the quad or below the cull
// (Splat::alpha and KernelParams::alpha).
fn splat_alpha(s: Splat, p: vec2<f32>, params: RasterParams) -> f32 {
    if (!covers(s, p, params)) {
        return 0.0;
    }
    return fragment_alpha(s, p, params);
}

// The alpha of a fragment whose samples may lie elsewhere in the pixel: the same at p without
// the footprint test (raster/mod.rs `Rasterizer::fragments` evaluates it at the pixel centre
// and tests each sample's coverage apart).
fn fragment_alpha(s: Splat, p: vec2<f32>, params: RasterParams) -> f32 {
    let a = mahalanobis(s, p);
    let alpha = s.opacity * kernel_response(a, params.kernel_degree);
    if (!(alpha >= params.alpha_cull && alpha > 0.0)) {
        return 0.0;
    }
    return min(alpha, params.alpha_clamp);
}
