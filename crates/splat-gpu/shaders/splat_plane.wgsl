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

@fragment
fn fs_stochastic_plane(in: VertexOut, @builtin(sample_index) i: u32) -> PlaneOut {
    let s = splats[in.splat];
    let corner = floor(in.position.xy);
    let p = corner + sample_offsets[i];
    let alpha = fragment_alpha(s, corner + vec2<f32>(0.5), params);
    let pixel = vec2<u32>(corner);
    let pixel_key = xxhash32(vec3<u32>(pixel.x, pixel.y, frame.key));
    let u = unit_f32(pcg(xxhash32(vec3<u32>(pixel_key, s.id, i)))) - frame.u_shift;
    if (alpha <= 0.0 || !covers(s, p, params) || !(u < alpha)) {
        discard;
    }
    let t = plane_depth(s.id, camera_origin(), pixel_dir(p));
    return PlaneOut(vec4<f32>(s.color, 1.0), t * DEPTH_SCALE);
}
