//! Every COLMAP camera model renders as COLMAP projects. A model is written as a user's
//! `cameras.txt` and read by `splat_io::colmap`; each pixel's ray from `splat_core`'s camera
//! (through the inverted distortion) is handed to an independent port of COLMAP's
//! `ImgFromCam` (`splat_tests::colmap_models`), which must put it back on the pixel. The
//! control: the same port with one distortion coefficient 1 % off (the focal length for the
//! models without one) misplaces the rays by far more than the tolerance.

use glam::{Vec2, Vec3};
use splat_core::Camera;
use splat_tests::colmap_models::{img_from_cam, typical};

const WIDTH: u32 = 64;
const HEIGHT: u32 = 48;
/// Largest distance, in pixels, between a pixel and where COLMAP puts its ray: the ray's f32
/// direction costs about f × 1e-7 px (f ≈ 50 px here).
const TOLERANCE_PX: f64 = 1e-4;

/// `model` with `params` as COLMAP's text files give it, posed away from the axes.
fn read(model: &str, params: &[f64]) -> Camera {
    let params: Vec<String> = params.iter().map(|p| format!("{p:?}")).collect();
    let cameras = format!("1 {model} {WIDTH} {HEIGHT} {}\n", params.join(" "));
    let images = "1 0.9238795 0.2209424 -0.3050190 0.0566511 0.3 -0.2 4.0 1 view.png\n\n";
    let views = splat_io::colmap::parse_colmap(cameras.as_bytes(), images.as_bytes(), false)
        .unwrap_or_else(|e| panic!("{model}: {e}"));
    views[0].camera
}

/// The largest distance from a pixel position to where the port projects its ray, over a grid
/// of positions covering the image to its edges; and how many rays the port refuses (a
/// fisheye's past 90°, which COLMAP cannot project).
fn worst(camera: &Camera, model: &str, params: &[f64]) -> (f64, usize) {
    let (mut worst, mut refused) = (0.0f64, 0);
    for y in 0..=HEIGHT {
        for x in 0..=WIDTH {
            if model == "EQUIRECTANGULAR" && y == HEIGHT {
                continue; // the bottom edge is the pole, every azimuth the same direction
            }
            // Inside each pixel, and on the image's far edges.
            let (px, py) = (x.min(WIDTH - 1), y.min(HEIGHT - 1));
            let offset = Vec2::new(if x == WIDTH { 1.0 } else { 0.37 }, if y == HEIGHT { 1.0 } else { 0.61 });
            let d: Vec3 = camera.rotation * camera.ray(px, py, offset).dir;
            let target = [f64::from(px) + f64::from(offset.x), f64::from(py) + f64::from(offset.y)];
            match img_from_cam(model, params, d.as_dvec3().to_array()) {
                Some(p) => {
                    // The equirectangular image wraps around: its left and right edges meet.
                    let dx = (p[0] - target[0]).abs();
                    let dx = if model == "EQUIRECTANGULAR" { dx.min(f64::from(WIDTH) - dx) } else { dx };
                    worst = worst.max(dx.hypot(p[1] - target[1]));
                }
                None => refused += 1,
            }
        }
    }
    (worst, refused)
}

#[test]
fn each_pixels_ray_lands_on_its_pixel_through_colmaps_model() {
    for (model, params) in typical(WIDTH, HEIGHT) {
        let camera = read(model, &params);
        assert!(!camera.is_pinhole(), "{model}");
        let (error, refused) = worst(&camera, model, &params);
        // The control: the first distortion coefficient 1 % off, or the focal length.
        let mut off = params.clone();
        let first = match model {
            "SIMPLE_FISHEYE" | "FISHEYE" | "EQUIRECTANGULAR" => 0,
            "SIMPLE_RADIAL" | "RADIAL" | "SIMPLE_RADIAL_FISHEYE" | "RADIAL_FISHEYE" => 3,
            _ => 4,
        };
        off[first] *= 1.01;
        let (control, _) = worst(&camera, model, &off);
        eprintln!(
            "{model}: max {error:.1e} px ({refused} rays past 90° not projectable); parameter {first} × 1.01: {control:.1e} px"
        );
        assert!(error < TOLERANCE_PX, "{model}: a ray lands {error} px from its pixel");
        assert!(control > 10.0 * TOLERANCE_PX, "{model}: a 1 % error passes ({control} px)");
        assert!(refused == 0 || model.contains("FISHEYE"), "{model}: {refused} rays refused");
    }
}

/// A perspective lens with zero distortion gives the pinhole's rays, to f32 rounding.
#[test]
fn a_lens_without_distortion_is_the_pinhole() {
    let pinhole = Camera::look_at(Vec3::new(0.3, -0.2, 4.0), Vec3::ZERO, Vec3::Y, 50.0, WIDTH, HEIGHT).unwrap();
    let lens = splat_core::camera::Lens::Perspective(Default::default());
    let distorted = pinhole.with_lens(lens).unwrap();
    for (x, y) in [(0, 0), (31, 20), (63, 47)] {
        let (a, b) = (pinhole.pixel_ray(x, y), distorted.pixel_ray(x, y));
        assert!((a.dir - b.dir).length() < 1e-6, "{x}, {y}");
    }
}

/// 3DGUT's unscented transform (Wu et al. 2025; 3dgrut `gutProjector.cuh`,
/// `unscentedParticleProjection` with α = 1, β = 2, κ = 0), written here from that code around
/// the port of COLMAP's `ImgFromCam`: the projected mean and covariance (a, b, c) of a particle.
fn ut_port(p: &splat_core::Particle, camera: &Camera, model: &str, params: &[f64]) -> Option<([f64; 2], [f64; 3])> {
    let (alpha, beta, kappa, d) = (1.0f64, 2.0f64, 0.0f64, 3.0f64);
    let lambda = alpha * alpha * (d + kappa) - d;
    let delta = (alpha * alpha * (d + kappa)).sqrt();
    let rot = glam::DMat3::from_quat(p.rotation.as_dquat());
    let to_camera = |x: glam::DVec3| camera.rotation.as_dmat3() * x + camera.translation.as_dvec3();
    let project = |x: glam::DVec3| img_from_cam(model, params, to_camera(x).to_array());
    let mean = p.mean.as_dvec3();
    let mut points = vec![project(mean)?];
    for i in 0..3 {
        let delta_i = delta * f64::from(p.scale[i]) * rot.col(i);
        points.push(project(mean + delta_i)?);
        points.push(project(mean - delta_i)?);
    }
    let weight_i = 1.0 / (2.0 * (d + lambda));
    let mut centre = [0.0; 2];
    for (k, q) in points.iter().enumerate() {
        let w = if k == 0 { lambda / (d + lambda) } else { weight_i };
        centre = [centre[0] + w * q[0], centre[1] + w * q[1]];
    }
    let mut cov = [0.0; 3];
    for (k, q) in points.iter().enumerate() {
        let w = if k == 0 { lambda / (d + lambda) + (1.0 - alpha * alpha + beta) } else { weight_i };
        let (x, y) = (q[0] - centre[0], q[1] - centre[1]);
        cov = [cov[0] + w * x * x, cov[1] + w * x * y, cov[2] + w * y * y];
    }
    Some((centre, cov))
}

/// Splatting through a distorted lens projects each particle by 3DGUT's unscented transform:
/// `raster::project`'s mean and (filtered) covariance equal the port's for every particle of the
/// cloud seen through each model, and the pinhole's EWA of the same particles is far off.
#[test]
fn splatting_projects_through_the_lens_by_the_unscented_transform() {
    use splat_core::raster::{Response, SplatExtent, project};
    let (scene, _) = splat_tests::harness::fixture("cloud", WIDTH, HEIGHT);
    let kernel = splat_core::RenderSettings::default();
    for (model, params) in typical(WIDTH, HEIGHT) {
        let camera = read(model, &params);
        let pinhole = Camera { lens: splat_core::camera::Lens::Pinhole, ..camera };
        let (mut worst, mut ewa_worst, mut compared) = (0.0f64, 0.0f64, 0);
        for (i, p) in scene.particles.iter().enumerate() {
            let Some(splat) = project(&scene, i as u32, &camera, &kernel, SplatExtent::ThreeDgs, Response::Projected)
            else {
                continue;
            };
            let Some((mean, [a, b, c])) = ut_port(p, &camera, model, &params) else { continue };
            // The splat's conic is the inverse of Σ₂ + 0.3 I.
            let (a, c) = (a + 0.3, c + 0.3);
            let det = a * c - b * b;
            let conic = [c / det, -b / det, a / det];
            let ours = [splat.conic.x, splat.conic.y, splat.conic.z].map(f64::from);
            let scale = conic[0].abs().max(conic[2].abs());
            let error = (f64::from(splat.mean.x) - mean[0]).hypot(f64::from(splat.mean.y) - mean[1])
                + (0..3).map(|k| (ours[k] - conic[k]).abs() / scale).fold(0.0, f64::max);
            worst = worst.max(error);
            if let Some(e) = project(&scene, i as u32, &pinhole, &kernel, SplatExtent::ThreeDgs, Response::Projected) {
                ewa_worst = ewa_worst.max((f64::from(e.mean.x) - mean[0]).hypot(f64::from(e.mean.y) - mean[1]));
            }
            compared += 1;
        }
        eprintln!(
            "{model}: {compared} splats, max error {worst:.1e} (px + relative conic); pinhole EWA mean off by up to {ewa_worst:.1e} px"
        );
        assert!(compared > 100, "{model}: only {compared} splats compared");
        assert!(worst < 1e-3, "{model}: the unscented projection is {worst} from the port");
        assert!(ewa_worst > 0.1, "{model}: the pinhole projection passes for the lens ({ewa_worst} px)");
    }
}
