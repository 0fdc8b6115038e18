// The display pass of a progressive view (progressive.rs): one fragment per pixel of the
// view reads its running Welford state and frame 0's pick and writes what the mode shows.
// The CPU twin is display.rs `Display::shade`; values are display-referred, so into an sRGB
// target the shader writes their linear equivalent and the stored byte is round(255 v).
// `Pick` comes from pick.wgsl, prepended.

struct DisplayParams {
    mode: u32,
    frames: u32,
    width: u32,
    height: u32,
    depth_near: f32,
    depth_far: f32,
    variance_scale: f32,
    srgb_target: u32,
}

const MODE_COLOUR: u32 = 0u;
const MODE_DEPTH: u32 = 1u;
const MODE_NORMAL: u32 = 2u;
const MODE_VARIANCE: u32 = 3u;

@group(0) @binding(0) var<storage, read> display: DisplayParams;
@group(0) @binding(1) var<storage, read> mean: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> m2: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> picks: array<Pick>;

// One triangle that covers the target.
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn shade(index: u32) -> vec3<f32> {
    let pick = picks[index];
    switch display.mode {
        case MODE_DEPTH: {
            if (pick.depth < 0.0) {
                return vec3<f32>(0.0);
            }
            let span = max(display.depth_far - display.depth_near, 1.17549435e-38);
            return vec3<f32>(1.0 - saturate((pick.depth - display.depth_near) / span));
        }
        case MODE_NORMAL: {
            if (all(pick.normal == vec3<f32>(0.0))) {
                return vec3<f32>(0.0);
            }
            return saturate(0.5 * pick.normal + 0.5);
        }
        case MODE_VARIANCE: {
            var variance = vec3<f32>(0.0);
            if (display.frames > 1u) {
                variance = m2[index].xyz / f32(display.frames - 1u);
            }
            let v = max((variance.x + variance.y + variance.z) / 3.0, 0.0);
            return vec3<f32>(saturate(sqrt(v) * display.variance_scale));
        }
        default: {
            return saturate(mean[index].xyz);
        }
    }
}

// The sRGB decoding of a display value (IEC 61966-2-1).
fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    return select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
}

@fragment
fn fs_main(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let x = min(u32(position.x), display.width - 1u);
    let y = min(u32(position.y), display.height - 1u);
    var c = shade(y * display.width + x);
    if (display.srgb_target == 1u) {
        c = srgb_to_linear(c);
    }
    return vec4<f32>(c, 1.0);
}
