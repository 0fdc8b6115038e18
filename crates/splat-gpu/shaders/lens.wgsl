// The camera's lens, the twin of crates/splat-core/src/lens.rs and `Camera::direction` and
// `Camera::project` in camera.rs, in f32: COLMAP's camera models, a pixel's direction through
// the inverse of the distortion (Newton's method with COLMAP's trust region), and a point's
// pixel through the lens. Part of the trace kernel (splat_gpu::TRACE_WGSL) and of the raster
// kernels (splat_gpu::RASTER_WGSL and the splat and mesh pre-pass modules), whose `params`
// both carry `size`, `intrinsics`, `lens` (one of these) and `distortion`.

const LENS_PINHOLE: u32 = 0u;
const LENS_PERSPECTIVE: u32 = 1u;
const LENS_FISHEYE: u32 = 2u;
const LENS_EQUIRECTANGULAR: u32 = 3u;
const UNDISTORT_STEPS: u32 = 100u;
const UNDISTORT_TOLERANCE_F32: f32 = 1e-6;
// π, under its own name: the trace kernel's PI lives in bsdf.wgsl, which the raster kernels lack.
const HALF_TURN: f32 = 3.14159265358979;

// lens.rs `Distortion::apply`: (du, dv) and the rows of the Jacobian of x + d(x).
struct Distorted {
    d: vec2<f32>,
    j0: vec2<f32>,
    j1: vec2<f32>,
}

fn distortion_at(x: vec2<f32>) -> Distorted {
    let a = params.distortion[0];
    let b = params.distortion[1];
    let p1 = params.distortion[2].x;
    let p2 = params.distortion[2].y;
    let s1 = params.distortion[2].z;
    let s2 = params.distortion[2].w;
    let u = x.x;
    let v = x.y;
    let r2 = u * u + v * v;
    let n = 1.0 + r2 * (a.x + r2 * (a.y + r2 * (a.z + r2 * a.w)));
    let d = 1.0 + r2 * (b.x + r2 * (b.y + r2 * b.z));
    let dn = a.x + r2 * (2.0 * a.y + r2 * (3.0 * a.z + r2 * 4.0 * a.w));
    let dd = b.x + r2 * (2.0 * b.y + r2 * 3.0 * b.z);
    let rho = n / d - 1.0;
    let rho_r2 = (dn * d - n * dd) / (d * d);
    var out: Distorted;
    out.d = vec2<f32>(
        u * rho + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u) + s1 * r2,
        v * rho + 2.0 * p2 * u * v + p1 * (r2 + 2.0 * v * v) + s2 * r2,
    );
    out.j0 = vec2<f32>(
        1.0 + rho + 2.0 * u * u * rho_r2 + 2.0 * p1 * v + 6.0 * p2 * u + 2.0 * s1 * u,
        2.0 * u * v * rho_r2 + 2.0 * p1 * u + 2.0 * p2 * v + 2.0 * s1 * v,
    );
    out.j1 = vec2<f32>(
        2.0 * u * v * rho_r2 + 2.0 * p2 * v + 2.0 * p1 * u + 2.0 * s2 * u,
        1.0 + rho + 2.0 * v * v * rho_r2 + 2.0 * p2 * u + 6.0 * p1 * v + 2.0 * s2 * v,
    );
    return out;
}

// lens.rs `Distortion::undistort`: the undistorted coordinates of `distorted`.
fn undistort(distorted: vec2<f32>) -> vec2<f32> {
    var x = distorted;
    for (var i = 0u; i < UNDISTORT_STEPS; i++) {
        let at = distortion_at(x);
        let f = x + at.d - distorted;
        let det = at.j0.x * at.j1.y - at.j0.y * at.j1.x;
        if (!(abs(det) > 0.0)) {
            break;
        }
        var step = vec2<f32>(at.j1.y * f.x - at.j0.y * f.y, at.j0.x * f.y - at.j1.x * f.x) / det;
        let radius = max(0.1 * length(x), 0.1);
        let len = length(step);
        if (len > radius) {
            step *= radius / len;
        }
        x -= step;
        if (length(step) < UNDISTORT_TOLERANCE_F32 * max(1.0, length(x))) {
            break;
        }
    }
    return x;
}

// The camera-space direction through pixel (x, y) at `offset` (lens_dir).
fn camera_dir(x: u32, y: u32, offset: vec2<f32>) -> vec3<f32> {
    return lens_dir(vec2<f32>(f32(x) + offset.x, f32(y) + offset.y));
}

// camera.rs `Camera::direction`: the camera-space direction through continuous pixel position
// p, (u, v, 1) for the pinhole and a unit vector through the other lenses.
fn lens_dir(p: vec2<f32>) -> vec3<f32> {
    if (params.lens == LENS_EQUIRECTANGULAR) {
        // lens.rs `Lens::equirectangular`.
        let f = p / vec2<f32>(params.size);
        let azimuth = 2.0 * HALF_TURN * (f.x - 0.5);
        let elevation = HALF_TURN * (0.5 - f.y);
        return vec3<f32>(cos(elevation) * sin(azimuth), -sin(elevation), cos(elevation) * cos(azimuth));
    }
    let xy = vec2<f32>((p.x - params.intrinsics.z) / params.intrinsics.x, (p.y - params.intrinsics.w) / params.intrinsics.y);
    if (params.lens == LENS_PINHOLE) {
        return vec3<f32>(xy, 1.0);
    }
    let u = undistort(xy);
    if (params.lens == LENS_PERSPECTIVE) {
        return normalize(vec3<f32>(u, 1.0));
    }
    let theta = length(u);
    if (theta > 0.0) {
        return vec3<f32>(u * (sin(theta) / theta), cos(theta));
    }
    return vec3<f32>(0.0, 0.0, 1.0);
}

// camera.rs `Camera::project`: the pixel of camera-space point c through the lens in xy, and
// in z 1 where the lens sees it, 0 where it does not (behind a perspective lens).
fn lens_project(c: vec3<f32>) -> vec3<f32> {
    if (params.lens == LENS_EQUIRECTANGULAR) {
        // lens.rs `Lens::equirectangular_position`.
        let horizontal = length(c.xz);
        let azimuth = atan2(c.x, c.z);
        let elevation = atan2(-c.y, horizontal);
        let f = vec2<f32>(azimuth / (2.0 * HALF_TURN) + 0.5, 0.5 - elevation / HALF_TURN);
        return vec3<f32>(f * vec2<f32>(params.size), select(0.0, 1.0, horizontal + abs(c.y) > 0.0));
    }
    var u = vec2<f32>(0.0);
    if (params.lens == LENS_FISHEYE) {
        let r = length(c.xy);
        if (r > 0.0) {
            u = c.xy * (atan2(r, c.z) / r);
        } else if (!(c.z > 0.0)) {
            return vec3<f32>(0.0);
        }
    } else {
        if (!(c.z > 0.0)) {
            return vec3<f32>(0.0);
        }
        u = c.xy / c.z;
    }
    if (params.lens != LENS_PINHOLE) {
        u += distortion_at(u).d;
    }
    return vec3<f32>(params.intrinsics.xy * u + params.intrinsics.zw, 1.0);
}
