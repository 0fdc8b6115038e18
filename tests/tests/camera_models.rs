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
