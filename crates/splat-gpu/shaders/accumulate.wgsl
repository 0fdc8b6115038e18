// Temporal accumulation of frames into a running mean, mean ← mix(mean, frame, 1/(n + 1)), as
// the vk_gaussian_splatting post pass does, stored as f32, f16 (pack2x16float) or 8-bit unorm.

struct AccParams {
    count: u32,
    frame: u32,
    format: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> acc_params: AccParams;
@group(0) @binding(1) var<storage, read> frame_in: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> acc32: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> acc16: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> acc8: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn accumulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= acc_params.count) {
        return;
    }
    let w = 1.0 / f32(acc_params.frame + 1u);
    let x = frame_in[i];
    switch acc_params.format {
        case 1u: {
            let old = vec4<f32>(unpack2x16float(acc16[i].x), unpack2x16float(acc16[i].y));
            let v = mix(old, x, w);
            acc16[i] = vec2<u32>(pack2x16float(v.xy), pack2x16float(v.zw));
        }
        case 2u: {
            acc8[i] = pack4x8unorm(mix(unpack4x8unorm(acc8[i]), x, w));
        }
        default: {
            acc32[i] = mix(acc32[i], x, w);
        }
    }
}
