// Appended to splat.wgsl for the one entry point that needs sample-rate shading (wgpu's
// MULTISAMPLED_SHADING capability), so that the others validate without it.

// ---- the max-density plane (StochasticSplats' pop-free billboards) --------------------------
//
// Each sample's depth is the point of maximum density along its own ray, so the shader runs
// per sample (reading @builtin(sample_index) asks for sample-rate shading) and writes it as
// @builtin(frag_depth): the hardware can no longer test depth before the shader runs.

struct PlaneOut {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
}

// StochasticSplats' decision at sample i of the fragment's pixel (raster/mod.rs
// `stochastic_splat`, slot = i): its splat where the sample is covered and u_i < α (the alpha
// at the pixel centre), else the fragment is discarded.
fn accepted_sample(in: VertexOut, i: u32) -> Splat {
    let s = splats[in.splat];
    let corner = floor(in.position.xy);
    let alpha = fragment_alpha(s, corner + vec2<f32>(0.5), params);
    let pixel = vec2<u32>(corner);
    let pixel_key = xxhash32(vec3<u32>(pixel.x, pixel.y, frame.key));
    let u = unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, i)))) - frame.u_shift;
    if (alpha <= 0.0 || !covers(s, corner + sample_offsets[i], params) || !(u < alpha)) {
        discard;
    }
    return s;
}

@fragment
fn fs_stochastic_plane(in: VertexOut, @builtin(sample_index) i: u32) -> PlaneOut {
    let s = accepted_sample(in, i);
    let p = floor(in.position.xy) + sample_offsets[i];
    let t = plane_depth(s.id, camera_origin(), pixel_dir(p));
    return PlaneOut(vec4<f32>(s.color, 1.0), t * DEPTH_SCALE);
}

// ---- lit StochasticSplats, sample by sample ----------------------------------------------------
//
// raster/mod.rs `resolve` lights each written sample with `lit_color`: at the sample's depth
// along the sample's own ray, with the splat's normal along sample 0's ray. At S > 1 or at the
// plane depth that colour differs from sample to sample, so the shader runs per sample and
// writes the sample's distance t as its depth, the order of the CPU's per-sample depth test.

// 1: the distance of the max-density plane, 0: of the billboard through the centre.
override LIT_PLANE_DEPTH: u32 = 0u;

@fragment
fn fs_stochastic_lit_sample(in: VertexOut, @builtin(sample_index) i: u32) -> PlaneOut {
    let s = accepted_sample(in, i);
    let corner = floor(in.position.xy);
    let p = corner + sample_offsets[i];
    let origin = camera_origin();
    let dir = pixel_dir(p);
    var t = s.depth * stretch(p);
    if (LIT_PLANE_DEPTH == 1u) {
        t = plane_depth(s.id, origin, dir);
    }
    let n = splat_normal(s.id, origin, pixel_dir(corner + sample_offsets[0]));
    return PlaneOut(vec4<f32>(shade_unshadowed(s.color, s.id, origin, dir, t, n), 1.0), t * DEPTH_SCALE);
}
