// Temporal accumulation of raster frames: each frame's colour target is folded into a running
// Welford mean and M2 per pixel, the accumulation of the ray-tracing kernel (trace.wgsl `fold`).
// The target is read by `frame_color` (fold_target.wgsl: one sample; fold_target_msaa.wgsl: the
// mean of the S samples, the MSAA resolve), each sample composed over what lies behind it.

@group(0) @binding(0) var<storage, read> params: RasterParams;
@group(0) @binding(1) var<storage, read> frame: FrameParams;
@group(0) @binding(3) var<storage, read_write> out_mean: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> out_var: array<vec4<f32>>;
// The mesh pre-pass's colour and distance per sample (entry pixel × S + i, mesh_prepass.wgsl),
// read where params.meshes is 1.
@group(0) @binding(5) var<storage, read> behind: array<vec4<f32>>;

// Sample i of pixel `pixel` (colour and coverage s of the draw) over what lies behind it. The
// raster operations' target (Enderton, Laine–Karras) holds the resolved pixel, what lies behind
// included (rop.wgsl `resolve_rop`).
fn composed(s: vec4<f32>, pixel: u32, i: u32) -> vec4<f32> {
    if (params.mode >= MODE_ENDERTON) {
        return s;
    }
    if (params.meshes == 1u) {
        // Every draw started from transparent black: what lies behind (a mesh or the
        // background) shows through the remaining transmittance, the mesh covering it
        // (vk_gaussian_splatting Lighting §1.5.3, the mesh blended with 1 − α_dst).
        let b = behind[pixel * params.samples + i];
        let covered = select(0.0, 1.0, b.w < 3.0e38);
        return vec4<f32>(s.xyz + (1.0 - s.w) * b.xyz, s.w + (1.0 - s.w) * covered);
    }
    if (params.mode == MODE_UNDER) {
        // Front to back left premultiplied colour and coverage: the background shows through
        // the remaining transmittance.
        return vec4<f32>(s.xyz + (1.0 - s.w) * params.background.xyz, s.w);
    }
    return s;
}

@compute @workgroup_size(8, 8, 1)
fn fold(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let index = gid.y * params.size.x + gid.x;
    let s = frame_color(vec2<i32>(gid.xy), index);
    var mean = vec4<f32>(0.0);
    var m2 = vec4<f32>(0.0);
    if (frame.index > 0u) {
        mean = out_mean[index];
        m2 = out_var[index];
    }
    let delta = s - mean;
    mean += delta / f32(frame.index + 1u);
    m2 += delta * (s - mean);
    out_mean[index] = stored(mean, frame.accumulation);
    out_var[index] = m2;
}
