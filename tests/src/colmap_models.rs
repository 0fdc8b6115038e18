//! An independent port of COLMAP's camera models (`src/colmap/sensor/models.h`: each model's
//! `ImgFromCam`, with `FisheyeFromNormal` and its `Distortion`), written from COLMAP's source in
//! its own terms — a model name and its parameter list — in f64, sharing no code with
//! `splat_core::lens`. It projects a camera-space point to the image; the tests trace a pixel's
//! ray through `splat_core` and ask this port where that ray lands.

/// Where COLMAP's `ImgFromCam` puts camera-space point (u, v, w) for `model` with `params`, or
/// `None` where the model refuses it (a perspective point at w ≤ 0) or the model is not ported.
pub fn img_from_cam(model: &str, params: &[f64], [u, v, w]: [f64; 3]) -> Option<[f64; 2]> {
    let perspective = |f1: f64, f2: f64, c1: f64, c2: f64, extra: &[f64], distortion: Distortion| {
        if w <= f64::EPSILON {
            return None;
        }
        let (uu, vv) = (u / w, v / w);
        let (du, dv) = distortion(extra, uu, vv);
        Some([f1 * (uu + du) + c1, f2 * (vv + dv) + c2])
    };
    let fisheye = |f1: f64, f2: f64, c1: f64, c2: f64, extra: &[f64], distortion: Distortion| {
        // COLMAP refuses w ≤ 0 here too (HasProjectableDepth) and maps (u/w, v/w) through atan;
        // for w > 0 that is θ = atan2(√(u² + v²), w).
        if w <= f64::EPSILON {
            return None;
        }
        let (mut uu, mut vv) = (u / w, v / w);
        let r = (uu * uu + vv * vv).sqrt();
        if r > f64::EPSILON {
            let theta = r.atan();
            uu *= theta / r;
            vv *= theta / r;
        }
        let (du, dv) = distortion(extra, uu, vv);
        Some([f1 * (uu + du) + c1, f2 * (vv + dv) + c2])
    };
    match (model, params) {
        ("SIMPLE_RADIAL", &[f, c1, c2, ref extra @ ..]) => perspective(f, f, c1, c2, extra, simple_radial),
        ("RADIAL", &[f, c1, c2, ref extra @ ..]) => perspective(f, f, c1, c2, extra, radial),
        ("OPENCV", &[f1, f2, c1, c2, ref extra @ ..]) => perspective(f1, f2, c1, c2, extra, opencv),
        ("FULL_OPENCV", &[f1, f2, c1, c2, ref extra @ ..]) => perspective(f1, f2, c1, c2, extra, full_opencv),
        ("OPENCV_FISHEYE", &[f1, f2, c1, c2, ref extra @ ..]) => fisheye(f1, f2, c1, c2, extra, opencv_fisheye),
        ("SIMPLE_RADIAL_FISHEYE", &[f, c1, c2, ref extra @ ..]) => fisheye(f, f, c1, c2, extra, simple_radial),
        ("RADIAL_FISHEYE", &[f, c1, c2, ref extra @ ..]) => fisheye(f, f, c1, c2, extra, radial),
        ("THIN_PRISM_FISHEYE", &[f1, f2, c1, c2, ref extra @ ..]) => fisheye(f1, f2, c1, c2, extra, thin_prism),
        ("SIMPLE_FISHEYE", &[f, c1, c2]) => fisheye(f, f, c1, c2, &[], |_, _, _| (0.0, 0.0)),
        ("FISHEYE", &[f1, f2, c1, c2]) => fisheye(f1, f2, c1, c2, &[], |_, _, _| (0.0, 0.0)),
        ("EQUIRECTANGULAR", &[width, height]) => {
            let horizontal = (u * u + w * w).sqrt();
            if horizontal + v.abs() < f64::EPSILON {
                return None;
            }
            let theta = u.atan2(w);
            let phi = (-v).atan2(horizontal);
            Some([(theta / (2.0 * std::f64::consts::PI) + 0.5) * width, (0.5 - phi / std::f64::consts::PI) * height])
        }
        _ => None,
    }
}

/// A model's `Distortion(extra_params, u, v) -> (du, dv)`.
type Distortion = fn(&[f64], f64, f64) -> (f64, f64);

/// SIMPLE_RADIAL (and SIMPLE_RADIAL_FISHEYE, whose θ² is u² + v² of the fisheye coordinates).
fn simple_radial(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let radial = p[0] * (u * u + v * v);
    (u * radial, v * radial)
}

/// RADIAL (and RADIAL_FISHEYE).
fn radial(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let r2 = u * u + v * v;
    let radial = p[0] * r2 + p[1] * r2 * r2;
    (u * radial, v * radial)
}

fn opencv(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let (k1, k2, p1, p2) = (p[0], p[1], p[2], p[3]);
    let (u2, uv, v2) = (u * u, u * v, v * v);
    let r2 = u2 + v2;
    let radial = k1 * r2 + k2 * r2 * r2;
    (u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2), v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2))
}

fn full_opencv(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let (k1, k2, p1, p2, k3, k4, k5, k6) = (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]);
    let (u2, uv, v2) = (u * u, u * v, v * v);
    let r2 = u2 + v2;
    let (r4, r6) = (r2 * r2, r2 * r2 * r2);
    let radial = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
    (u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) - u, v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) - v)
}

fn opencv_fisheye(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let theta2 = u * u + v * v;
    let (theta4, theta6, theta8) = (theta2 * theta2, theta2 * theta2 * theta2, theta2 * theta2 * theta2 * theta2);
    let radial = p[0] * theta2 + p[1] * theta4 + p[2] * theta6 + p[3] * theta8;
    (u * radial, v * radial)
}

fn thin_prism(p: &[f64], u: f64, v: f64) -> (f64, f64) {
    let (k1, k2, p1, p2, k3, k4, sx1, sy1) = (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]);
    let (u2, uv, v2) = (u * u, u * v, v * v);
    let r2 = u2 + v2;
    let (r4, r6, r8) = (r2 * r2, r2 * r2 * r2, r2 * r2 * r2 * r2);
    let radial = k1 * r2 + k2 * r4 + k3 * r6 + k4 * r8;
    (
        u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) + sx1 * r2,
        v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) + sy1 * r2,
    )
}

/// Every model the port holds, with parameters typical of a real camera at `width` × `height`
/// (the focal lengths in pixels, the principal point off centre, the coefficients of the size
/// COLMAP estimates for phone, action and fisheye cameras).
pub fn typical(width: u32, height: u32) -> Vec<(&'static str, Vec<f64>)> {
    let (w, h) = (f64::from(width), f64::from(height));
    let (f, cx, cy) = (0.8 * w, 0.52 * w, 0.47 * h);
    let fish = 0.45 * w;
    vec![
        ("SIMPLE_RADIAL", vec![f, cx, cy, -0.12]),
        ("RADIAL", vec![f, cx, cy, -0.18, 0.04]),
        ("OPENCV", vec![f, 1.02 * f, cx, cy, -0.21, 0.05, 1.2e-3, -8e-4]),
        ("FULL_OPENCV", vec![f, 1.02 * f, cx, cy, -0.3, 0.09, 1e-3, -5e-4, -0.01, 0.05, -0.02, 0.004]),
        ("OPENCV_FISHEYE", vec![fish, 1.01 * fish, cx, cy, 0.04, -0.012, 0.003, -4e-4]),
        ("SIMPLE_RADIAL_FISHEYE", vec![fish, cx, cy, 0.03]),
        ("RADIAL_FISHEYE", vec![fish, cx, cy, 0.03, -0.006]),
        ("THIN_PRISM_FISHEYE", vec![fish, 1.01 * fish, cx, cy, 0.04, -0.01, 6e-4, -3e-4, 0.002, -3e-4, 4e-4, -2e-4]),
        ("SIMPLE_FISHEYE", vec![fish, cx, cy]),
        ("FISHEYE", vec![fish, 1.01 * fish, cx, cy]),
        ("EQUIRECTANGULAR", vec![w, h]),
    ]
}
