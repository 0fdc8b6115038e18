// Temporal accumulation of raster frames: each frame's colour target is folded into a running
// Welford mean and M2 per pixel, the accumulation of the ray-tracing kernel (trace.wgsl `fold`).
// The target is read by `frame_color` (fold_target.wgsl: one sample; fold_target_msaa.wgsl: the
// mean of the S samples, the MSAA resolve).

@group(0) @binding(0) var<uniform> params: RasterParams;
@group(0) @binding(1) var<uniform> frame: FrameParams;
@group(0) @binding(3) var<storage, read_write> out_mean: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> out_var: array<vec4<f32>>;
// The mesh pre-pass's colour and distance per pixel (mesh_prepass.wgsl), read where
// params.meshes is 1.
@group(0) @binding(5) var<storage, read> behind: array<vec4<f32>>;

@compute @workgroup_size(8, 8, 1)
fn fold(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.size.x || gid.y >= params.size.y) {
        return;
    }
    let index = gid.y * params.size.x + gid.x;
    var s = frame_color(vec2<i32>(gid.xy));
    if (params.meshes == 1u) {
        // Every draw started from transparent black: what lies behind (a mesh or the
        // background) shows through the remaining transmittance, the mesh covering it
        // (vk_gaussian_splatting Lighting §1.5.3, the mesh blended with 1 − α_dst).
        let b = behind[index];
        let covered = select(0.0, 1.0, b.w < 3.0e38);
        s = vec4<f32>(s.xyz + (1.0 - s.w) * b.xyz, s.w + (1.0 - s.w) * covered);
    } else if (params.mode == MODE_UNDER) {
        // Front to back left premultiplied colour and coverage: the background shows through
        // the remaining transmittance.
        s = vec4<f32>(s.xyz + (1.0 - s.w) * params.background.xyz, s.w);
    }
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
