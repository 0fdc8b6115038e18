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

// A fragment written at sample i: its splat and its distance t along the sample's ray.
struct Written {
    s: Splat,
    t: f32,
}

// StochasticSplats' decision at sample i of the fragment's pixel (raster/mod.rs
// `stochastic_splat`, slot = i): its splat where the sample is covered, u_i < α (the alpha at
// the pixel centre) and the fragment, at the max-density plane (`plane`) or the centre depth,
// lies in front of the sample's mesh; else the fragment is discarded.
fn accepted_sample(in: VertexOut, i: u32, plane: bool) -> Written {
    let s = splat_at(in.splat);
    let corner = floor(in.position.xy);
    let alpha = fragment_alpha(s, corner + vec2<f32>(0.5), params);
    let pixel = vec2<u32>(corner);
    let pixel_key = xxhash32(vec3<u32>(pixel.x, pixel.y, frame.key));
    let u = unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, i)))) - frame.u_shift;
    let p = corner + sample_offsets[i];
    if (alpha <= 0.0 || !covers(s, p, params) || !(u < alpha)) {
        discard;
    }
    var t = s.depth * stretch(p);
    if (plane) {
        t = plane_depth(s.id, camera_origin(), pixel_dir(p));
    }
    if (behind_mesh(pixel, i, t, false)) {
        discard;
    }
    return Written(s, t);
}

@fragment
fn fs_stochastic_plane(in: VertexOut, @builtin(sample_index) i: u32) -> PlaneOut {
    let w = accepted_sample(in, i, true);
    return PlaneOut(vec4<f32>(w.s.color, 1.0), w.t * DEPTH_SCALE);
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
    let w = accepted_sample(in, i, LIT_PLANE_DEPTH == 1u);
    let corner = floor(in.position.xy);
    let origin = camera_origin();
    let dir = pixel_dir(corner + sample_offsets[i]);
    let n = splat_normal(w.s.id, origin, pixel_dir(corner + sample_offsets[0]));
    return PlaneOut(vec4<f32>(shade_unshadowed(w.s.color, w.s.id, origin, dir, w.t, n), 1.0), w.t * DEPTH_SCALE);
}
