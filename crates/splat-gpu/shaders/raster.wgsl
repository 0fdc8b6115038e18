// Compute stages of the splatting path: EWA projection and culling, the twin of
// crates/splat-core/src/raster/project.rs. With binning.wgsl (tile lists), depth_pick.wgsl (the
// compute tile rasterizer) and rop.wgsl (the raster operations of Enderton and Laine–Karras),
// each the twin of the splat-gpu raster/ file of its name, it makes the raster kernels
// (splat_gpu::RASTER_WGSL).

// One particle in scene order (48 bytes), mirrored by splat_gpu::RasterParticle.
struct RasterParticle {
    mean: vec3<f32>,
    opacity: f32,
    // Covariance Σ = R S² Rᵀ: (xx, xy, xz) and (yy, yz, zz).
    cov_a: vec3<f32>,
    pad0: f32,
    cov_b: vec3<f32>,
    pad1: f32,
}

@group(0) @binding(0) var<storage, read> params: RasterParams;
// The particles and SH coefficients of the chunk this dispatch projects: `project_chunk.y`
// particles from scene index `project_chunk.x` on (splat_gpu::RasterScene uploads them in
// chunks of one binding each, projected by a dispatch each; particle k of the chunk is
// `particles[k]`).
@group(0) @binding(1) var<storage, read> particles: array<RasterParticle>;
@group(0) @binding(29) var<storage, read> project_chunk: vec2<u32>;
// Its SH (binding 2), coefficient i of the chunk read by sh.wgsl's `sh_at(i)` as the scene's
// storage holds them (declared by splat_gpu::RasterSplit).
// The projected splats, `splat_at(i)` and `splat_set(i, s)` (binding 3, split over more by
// splat_gpu::RasterSplit).
// Depth sort: keys (depth bits, NONE when culled; `depth_key_set(i, k)`, binding 4) and values
// (particle ids; `order_set(i, id)`, binding 5); after the sort, `order_at(r)` is the particle of
// rank r among the visible splats, the only ones it sorts (both split over more bindings by
// splat_gpu::RasterSplit, as the sort cuts them).
// Indirect draw arguments (vertex count, instance count = visible splats, 0, 0): the length of
// every order of the visible splats (binning.wgsl `drawn`).
@group(0) @binding(6) var<storage, read_write> draw_args: array<atomic<u32>, 4>;

const TILE: u32 = 16u;

fn flat_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * 256u + gid.x;
}

fn cull(i: u32) {
    var culled = splat_at(i);
    culled.rect = vec4<u32>(0u);
    splat_set(i, culled);
    depth_key_set(i, NONE);
    order_set(i, NONE); // dropped by the sort (splat_gpu::sort::CULLED)
}

// A particle projected to the image: its mean, Σ₂ as (a, b, c), its depth, and whether it is
// in front of the camera.
struct Projected {
    mean: vec2<f32>,
    cov: vec3<f32>,
    depth: f32,
    visible: bool,
}

// project.rs `ewa`: through the pinhole, Σ₂ = J W Σ Wᵀ Jᵀ at the centre, depth z.
fn ewa(p: RasterParticle) -> Projected {
    var out: Projected;
    out.visible = false;
    let r0 = params.cam_row0.xyz;
    let r1 = params.cam_row1.xyz;
    let r2 = params.cam_row2.xyz;
    let t = vec3<f32>(dot(r0, p.mean), dot(r1, p.mean), dot(r2, p.mean)) + params.cam_translation.xyz;
    if (!(t.z > params.near)) {
        return out;
    }
    let fx = params.intrinsics.x;
    let fy = params.intrinsics.y;
    let tx = clamp(t.x / t.z, -params.guard.x, params.guard.x) * t.z;
    let ty = clamp(t.y / t.z, -params.guard.y, params.guard.y) * t.z;
    // Rows of J W (2 × 3).
    let jw0 = (fx / t.z) * r0 - (fx * tx / (t.z * t.z)) * r2;
    let jw1 = (fy / t.z) * r1 - (fy * ty / (t.z * t.z)) * r2;
    let sigma = mat3x3<f32>(
        vec3<f32>(p.cov_a.x, p.cov_a.y, p.cov_a.z),
        vec3<f32>(p.cov_a.y, p.cov_b.x, p.cov_b.y),
        vec3<f32>(p.cov_a.z, p.cov_b.y, p.cov_b.z),
    );
    let s0 = sigma * jw0;
    let s1 = sigma * jw1;
    out.cov = vec3<f32>(dot(jw0, s0), dot(jw0, s1), dot(jw1, s1));
    out.mean = vec2<f32>(fx * t.x / t.z + params.intrinsics.z, fy * t.y / t.z + params.intrinsics.w);
    out.depth = t.z;
    out.visible = true;
    return out;
}

// project.rs `unscented` (3DGUT, α = 1, β = 2, κ = 0, so λ = 0): the sigma points μ ± √3 s_i r_i,
// the columns s_i r_i those of R S, the inverse of particle i's canonical transform S⁻¹ Rᵀ
// (rows in `canonical`), projected through the lens; mean weights 0 and 1/6, covariance
// weights 2 and 1/6; depth the distance of the centre.
fn unscented(i: u32, p: RasterParticle) -> Projected {
    var out: Projected;
    out.visible = false;
    // R, whose rows the params hold (mat3x3 takes columns).
    let world_to_camera = transpose(mat3x3<f32>(params.cam_row0.xyz, params.cam_row1.xyz, params.cam_row2.xyz));
    let centre = world_to_camera * p.mean + params.cam_translation.xyz;
    out.depth = length(centre);
    if (!(out.depth > params.near)) {
        return out;
    }
    let m0 = canonical_at(3u * i).xyz;
    let m1 = canonical_at(3u * i + 1u).xyz;
    let m2 = canonical_at(3u * i + 2u).xyz;
    let det = dot(m0, cross(m1, m2));
    let axes = mat3x3<f32>(cross(m1, m2), cross(m2, m0), cross(m0, m1)) * (sqrt(3.0) / det);
    let p0 = lens_project(centre);
    if (p0.z == 0.0) {
        return out;
    }
    var points: array<vec2<f32>, 6>;
    for (var k = 0u; k < 3u; k++) {
        let step = world_to_camera * axes[k];
        let plus = lens_project(centre + step);
        let minus = lens_project(centre - step);
        if (plus.z == 0.0 || minus.z == 0.0) {
            return out;
        }
        points[2u * k] = plus.xy;
        points[2u * k + 1u] = minus.xy;
    }
    var mean = vec2<f32>(0.0);
    for (var k = 0u; k < 6u; k++) {
        mean += points[k] / 6.0;
    }
    let e0 = p0.xy - mean;
    var cov = 2.0 * vec3<f32>(e0.x * e0.x, e0.x * e0.y, e0.y * e0.y);
    for (var k = 0u; k < 6u; k++) {
        let e = points[k] - mean;
        cov += vec3<f32>(e.x * e.x, e.x * e.y, e.y * e.y) / 6.0;
    }
    out.mean = mean;
    out.cov = cov;
    out.visible = true;
    return out;
}

// project.rs `inria_tiles`: the pixels of the 3DGS rasterizer's tiles around its box of
// half-width r = ⌈3 √λ_max⌉ centred at p = mean − ½ (its pixel coordinates), empty when none.
fn inria_tiles(mean: vec2<f32>, a: f32, c: f32, det: f32) -> vec4<f32> {
    let mid = 0.5 * (a + c);
    let lambda_max = mid + sqrt(max(mid * mid - det, EIGEN_FLOOR));
    let r = ceil(BOX_SIGMAS * sqrt(lambda_max));
    let p = mean - vec2<f32>(0.5);
    let size = vec2<f32>(params.size);
    let grid = ceil(size / BLOCK);
    let lo = clamp(floor((p - vec2<f32>(r)) / BLOCK), vec2<f32>(0.0), grid);
    let hi = clamp(floor((p + vec2<f32>(r + BLOCK - 1.0)) / BLOCK), vec2<f32>(0.0), grid);
    return vec4<f32>(lo * BLOCK, min(hi * BLOCK, size));
}

// project.rs `ellipse_box`: the pixels around the ellipse A ≤ bound of Σ′ = [[a, b], [b, c]],
// clipped to the image.
fn ellipse_box(mean: vec2<f32>, a: f32, c: f32, bound: f32) -> vec4<f32> {
    let r = sqrt(bound * vec2<f32>(a, c));
    let size = vec2<f32>(params.size);
    return vec4<f32>(max(floor(mean - r), vec2<f32>(0.0)), min(ceil(mean + r), size));
}

// project.rs `project`: Σ₂ by `ewa` through the pinhole or `unscented` through another lens, the
// screen filter (Σ′ = Σ₂ + s I, the opacity × ρ; filter.rs `ScreenFilter::apply`), the rect of
// the extent, the SH colour from the camera centre, and the sort key and value; culled particles
// get the value NONE, which the depth sort drops.
@compute @workgroup_size(256, 1, 1)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    // k in the chunk, i in the scene.
    let k = flat_index(gid, groups);
    if (k >= project_chunk.y) {
        return;
    }
    let i = project_chunk.x + k;
    cull(i);
    let p = particles[k];
    if (p.opacity < params.alpha_cull) {
        return;
    }
    var projected: Projected;
    if (params.lens == LENS_PINHOLE) {
        projected = ewa(p);
    } else {
        projected = unscented(i, p);
    }
    if (!projected.visible) {
        return;
    }
    let a2 = projected.cov.x;
    let b = projected.cov.y;
    let c2 = projected.cov.z;
    let a = a2 + params.filter_variance;
    let c = c2 + params.filter_variance;
    let det = a * c - b * b;
    if (!(det > 0.0) || det > 3.0e38) {
        return;
    }
    var opacity = p.opacity;
    if (params.filter_compensates == 1u) {
        let det2 = a2 * c2 - b * b;
        opacity = select(0.0, sqrt(det2 / det), det2 > 0.0) * p.opacity;
        if (opacity < params.alpha_cull) {
            return;
        }
    }
    let mean = projected.mean;
    // Within the 3DGS tiles the alpha cull alone decides: the footprint is cut to the visible
    // radius, the same pixels kept.
    var bound = visible_radius_sq(opacity, params);
    if (params.extent == EXTENT_SQRT8) {
        bound = EXTENT_SQ;
    }
    var rect = ellipse_box(mean, a, c, bound);
    if (params.extent == EXTENT_3DGS) {
        let tiles = inria_tiles(mean, a, c, det);
        rect = vec4<f32>(max(rect.xy, tiles.xy), min(rect.zw, tiles.zw));
    }
    if (!(rect.x < rect.z && rect.y < rect.w)) {
        return;
    }
    let v = p.mean - camera_origin();
    var dir = vec3<f32>(0.0);
    if (dot(v, v) > 0.0) {
        dir = normalize(v);
    }
    var s: Splat;
    s.mean = mean;
    s.depth = projected.depth;
    s.opacity = opacity;
    s.conic = vec3<f32>(c / det, -b / det, a / det);
    s.id = i;
    s.color = sh_eval(k, params.sh_degree, dir);
    s.bound = bound;
    s.rect = vec4<u32>(rect);
    splat_set(i, s);
    depth_key_set(i, bitcast<u32>(projected.depth));
    order_set(i, i);
    atomicAdd(&draw_args[1], 1u);
}
