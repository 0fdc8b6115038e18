// The splatting render pipeline: one instanced quad per splat covering the rect of its extent
// (the 3DGS tiles, gsplat's alpha-cull bounds or the √8σ ellipse's), and the
// fragment stages of sorted blending (vk_gaussian_splatting Lighting §1.5) and StochasticSplats (vk_gaussian_splatting Stochastic transparency §1), each
// the twin of a branch of crates/splat-core/src/raster/mod.rs (Rasterizer::sorted and
// Rasterizer::stochastic_splat with one sample at the pixel centre).

@group(0) @binding(0) var<storage, read> params: RasterParams;
@group(0) @binding(1) var<storage, read> frame: FrameParams;
// The projected splats, `splat_at(i)` (binding 2, split over more by splat_gpu::RasterSplit).
// The depth order, `order_at(r)` (binding 3, split over more by splat_gpu::RasterSplit).
@group(0) @binding(4) var<storage, read> draw_args: array<u32, 4>;
// Per sample of each pixel (entry pixel × S + i) the mesh pre-pass's colour and distance
// (mesh_prepass.wgsl), read where params.meshes is 1.
@group(0) @binding(5) var<storage, read> behind: array<vec4<f32>>;

// The depth test against the meshes (raster/mod.rs `Rasterizer::sorted` keeps fragments with
// t < t_mesh, the stochastic methods' sample buffers those with t ≤ t_mesh): whether a fragment
// at distance t of sample i of `pixel` lies behind the sample's mesh.
fn behind_mesh(pixel: vec2<u32>, i: u32, t: f32, at_mesh: bool) -> bool {
    if (params.meshes == 0u) {
        return false;
    }
    let t_mesh = behind[(pixel.y * params.size.x + pixel.x) * params.samples + i].w;
    return t > t_mesh || (at_mesh && t == t_mesh);
}

// The same for splat s's one-sample fragment at pixel position p, at centre depth z |d_cam|.
fn centre_behind_mesh(s: Splat, p: vec2<f32>, at_mesh: bool) -> bool {
    return behind_mesh(vec2<u32>(p), 0u, s.depth * stretch(p), at_mesh);
}

// View depth z maps to the depth buffer as z · 2⁻¹⁰⁰: a power of two, so the map is exact and
// keeps the f32 order of every depth (z ≥ 0.2 stays a normal float, z up to ~10³⁰ fits in [0, 1]).
const DEPTH_SCALE: f32 = 7.888609e-31;

struct VertexOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) splat: u32,
}

// Instance i draws the splat of rank count − 1 − i (over: back to front) or of rank i (under
// and stochastic: front to back) of the order bound as `order_at`: the visible splats in
// (depth, id) order, or for StochasticSplats at the max-density plane in scene order
// (splat_gpu::GpuRasterizer::order_parts says why).
@vertex
fn vs(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    var rank = instance;
    if (params.mode == MODE_OVER) {
        rank = draw_args[1] - 1u - instance;
    }
    let index = order_at(rank);
    let rect = vec4<f32>(splat_at(index).rect);
    // Two triangles: corners 0 1 2, 2 1 3 of the rect, in pixels.
    let corner = array<vec2<u32>, 6>(
        vec2<u32>(0u, 0u), vec2<u32>(1u, 0u), vec2<u32>(0u, 1u),
        vec2<u32>(0u, 1u), vec2<u32>(1u, 0u), vec2<u32>(1u, 1u),
    )[vertex];
    let p = vec2<f32>(select(rect.x, rect.z, corner.x == 1u), select(rect.y, rect.w, corner.y == 1u));
    let size = vec2<f32>(params.size);
    // Pixel coordinates (y down) to clip space (y up); a culled splat's rect is empty, so its
    // quad has no area.
    let ndc = vec2<f32>(2.0 * p.x / size.x - 1.0, 1.0 - 2.0 * p.y / size.y);
    // A constant depth over the quad (w = 1, so no perspective division): the rasterizer's
    // plane equation has zero slope and every fragment gets this value, with early depth tests.
    let z = splat_at(index).depth * DEPTH_SCALE;
    return VertexOut(vec4<f32>(ndc, z, 1.0), index);
}

// Sorted blending: over outputs (c, α) for SRC_ALPHA / ONE_MINUS_SRC_ALPHA; under outputs
// premultiplied (α c, α) for ONE_MINUS_DST_ALPHA / ONE.
@fragment
fn fs_sorted(in: VertexOut) -> @location(0) vec4<f32> {
    let s = splat_at(in.splat);
    let alpha = splat_alpha(s, in.position.xy, params);
    if (alpha <= 0.0 || centre_behind_mesh(s, in.position.xy, true)) {
        discard;
    }
    if (params.mode == MODE_UNDER) {
        return vec4<f32>(alpha * s.color, alpha);
    }
    return vec4<f32>(s.color, alpha);
}

// StochasticSplats: u = hash(pixel, frame, splat id, sample 0), the decision of
// splat_core::rng::RayRng::particle; accepted fragments are written opaque under the depth
// test (less, write on), the others discarded. Equal depths keep the lower id, which is drawn
// first (instances in id order, and Vulkan keeps primitive order): the CPU's (depth, id) test.
// The depth comes from the vertex stage, not frag_depth, so the hardware can test it before
// the shader runs (a written frag_depth disables early depth testing). This function is the
// decision: the splat this fragment writes, or a discard.
fn accepted_splat(in: VertexOut) -> Splat {
    let s = splat_at(in.splat);
    let alpha = splat_alpha(s, in.position.xy, params);
    let pixel = vec2<u32>(in.position.xy);
    let pixel_key = xxhash32(vec3<u32>(pixel.x, pixel.y, frame.key));
    let u = unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, 0u)))) - frame.u_shift;
    if (!(u < alpha) || centre_behind_mesh(s, in.position.xy, false)) {
        discard;
    }
    return s;
}

@fragment
fn fs_stochastic(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(accepted_splat(in).color, 1.0);
}

// Lit StochasticSplats: the written fragment shaded with its own splat's normal and position
// (forward shading; vk_gaussian_splatting Lighting §1.2, §2.2). A pipeline of its own: with the
// lighting code in the unlit entry point lavapipe kept about 1.5 MB per frame (2.4 GB against
// 0.1 GB for 1,533 frames of the convergence test).
@fragment
fn fs_stochastic_lit(in: VertexOut) -> @location(0) vec4<f32> {
    let s = accepted_splat(in);
    return vec4<f32>(splat_lit(s, in.position.xy), 1.0);
}

// ---- S samples per pixel: the hardware's multisampling (Laine & Karras 2011 §1, §5) ---------
//
// The fragment shader runs once per pixel at its centre (alpha evaluated there, the shading
// rate of MSAA), and returns through @builtin(sample_mask) which of the S samples it writes:
// those inside the footprint (raster/mod.rs `Rasterizer::fragments`' coverage), and for
// StochasticSplats only those whose own decision accepts it. The depth test and write then run
// per sample in fixed function, and the fold resolves the S samples to their mean. The sample
// positions are the hardware's (the standard pattern, raster/samples.rs), uploaded from the
// core so that the CPU reference decides at the same points.

// Sub-pixel position of sample i in [0, 1)² (params.samples of them).
@group(0) @binding(6) var<storage, read> sample_offsets: array<vec2<f32>>;

struct Masked {
    @location(0) color: vec4<f32>,
    @builtin(sample_mask) mask: u32,
}

// Bit i set where sample i of the pixel at corner `pixel` lies in splat s's footprint, in front
// of the sample's mesh (`behind_mesh` at the centre depth along the sample's ray).
fn coverage(s: Splat, pixel: vec2<f32>, at_mesh: bool) -> u32 {
    var mask = 0u;
    for (var i = 0u; i < params.samples; i++) {
        let p = pixel + sample_offsets[i];
        if (covers(s, p, params) && !behind_mesh(vec2<u32>(pixel), i, s.depth * stretch(p), at_mesh)) {
            mask |= 1u << i;
        }
    }
    return mask;
}

// Sorted blending at S samples: the fragment's alpha once per pixel, its coverage per sample.
@fragment
fn fs_sorted_msaa(in: VertexOut) -> Masked {
    let s = splat_at(in.splat);
    let alpha = fragment_alpha(s, in.position.xy, params);
    let mask = coverage(s, floor(in.position.xy), true);
    if (alpha <= 0.0 || mask == 0u) {
        discard;
    }
    if (params.mode == MODE_UNDER) {
        return Masked(vec4<f32>(alpha * s.color, alpha), mask);
    }
    return Masked(vec4<f32>(s.color, alpha), mask);
}

// StochasticSplats at S samples: sample i is written where it is covered and its own
// u_i = hash(pixel, frame, splat id, i) is below α (raster/mod.rs `stochastic_splat`, slot = i).
@fragment
fn fs_stochastic_msaa(in: VertexOut) -> Masked {
    let s = splat_at(in.splat);
    let alpha = fragment_alpha(s, in.position.xy, params);
    let pixel = vec2<u32>(in.position.xy);
    let pixel_key = xxhash32(vec3<u32>(pixel.x, pixel.y, frame.key));
    var mask = coverage(s, floor(in.position.xy), false);
    for (var i = 0u; i < params.samples; i++) {
        let u = unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, i)))) - frame.u_shift;
        if (!(u < alpha)) {
            mask &= ~(1u << i);
        }
    }
    if (alpha <= 0.0 || mask == 0u) {
        discard;
    }
    return Masked(vec4<f32>(s.color, 1.0), mask);
}
