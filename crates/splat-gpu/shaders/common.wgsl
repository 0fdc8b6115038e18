// Shared by every kernel (prepended to each shader module by splat-gpu): the counter-based
// hashes of crates/splat-core/src/rng.rs and the kernel response of kernel.rs.

fn xxhash32(p: vec3<u32>) -> u32 {
    let P2 = 2246822519u;
    let P3 = 3266489917u;
    let P4 = 668265263u;
    let P5 = 374761393u;
    var h = p.z + P5 + p.x * P3;
    h = P4 * ((h << 17u) | (h >> 15u));
    h = h + p.y * P3;
    h = P4 * ((h << 17u) | (h >> 15u));
    h = P2 * (h ^ (h >> 15u));
    h = P3 * (h ^ (h >> 13u));
    return h ^ (h >> 16u);
}

fn pcg(v: u32) -> u32 {
    let s = v * 747796405u + 2891336453u;
    let w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (w >> 22u) ^ w;
}

fn unit_f32(bits: u32) -> f32 {
    return f32(bits >> 8u) * (1.0 / 16777216.0);
}

// frame.rs `AccumulationFormat::code` and `store`: the running mean as it is kept between
// frames (full precision, half precision, or 8-bit unorm).
const ACCUMULATION_F32: u32 = 0u;
const ACCUMULATION_F16: u32 = 1u;
const ACCUMULATION_UNORM8: u32 = 2u;

fn stored(v: vec4<f32>, format: u32) -> vec4<f32> {
    if (format == ACCUMULATION_F16) {
        return vec4<f32>(round_f16(v.x), round_f16(v.y), round_f16(v.z), round_f16(v.w));
    }
    if (format == ACCUMULATION_UNORM8) {
        return floor(0.5 + 255.0 * clamp(v, vec4<f32>(0.0), vec4<f32>(1.0))) / 255.0;
    }
    return v;
}

// The f16 nearest to x (ties to even; past the largest finite f16, 65504, infinity), as an f32:
// the low bits of the f32 that f16 lacks are rounded away on the bit pattern, so that no kernel
// needs the optional f16 packing capability (pack2x16float).
fn round_f16(x: f32) -> f32 {
    let b = bitcast<u32>(x);
    let sign = b & 0x80000000u;
    let a = b & 0x7fffffffu;
    if (a >= 0x7f800000u) {
        return x;
    }
    if (a >= 0x477ff000u) {
        return bitcast<f32>(sign | 0x7f800000u);
    }
    let e = i32(a >> 23u) - 127;
    if (e < -24) {
        // Below the smallest subnormal 2^-24: 0, or 2^-24 above its half.
        return bitcast<f32>(sign | select(0u, 0x33800000u, a > 0x33000000u));
    }
    // f16 keeps 10 mantissa bits where normal (e ≥ −14), fewer below.
    let shift = 13u + u32(max(-14 - e, 0));
    let unit = 1u << shift;
    let rem = a & (unit - 1u);
    var r = a - rem;
    if (rem > (unit >> 1u) || (rem == (unit >> 1u) && (r & unit) != 0u)) {
        r += unit;
    }
    return bitcast<f32>(sign | r);
}

fn frame_key(seed: u32, frame: u32) -> u32 {
    return xxhash32(vec3<u32>(frame, seed, 0x5EEDF4A3u));
}

// kernel.rs: the generalized Gaussian response exp(−4.5 (d²/9)^(n/2)) of degree n.
fn kernel_response(d2: f32, degree: u32) -> f32 {
    let u = d2 * (1.0 / 9.0);
    var un = u;
    if (degree == 4u) {
        un = u * u;
    } else if (degree == 8u) {
        un = (u * u) * (u * u);
    } else if (degree != 2u) {
        un = pow(u, f32(degree) * 0.5);
    }
    return exp(-4.5 * un);
}

// No index: no particle, splat, triangle or node (u32::MAX).
const NONE: u32 = 0xffffffffu;

// hit.rs `Ray`: hits count within (t_min, t_max); `view` is the camera's forward axis for
// camera rays (the `Center` hit distance), the ray's own direction otherwise.
struct Ray {
    origin: vec3<f32>,
    dir: vec3<f32>,
    view: vec3<f32>,
    t_min: f32,
    t_max: f32,
}
