//! Golden images: every method on every fixture, read through the file formats, against
//! the committed PNGs in `fixtures/golden/` (`cargo xtask bless` rewrites them).

use splat_core::{RenderSettings, render_oracle};
use splat_io::image::to_rgba8;
use splat_tests::{compare_golden, golden, root};

/// 8-bit units of tolerance: one unit for rounding differences of libm across platforms.
const TOLERANCE: u8 = 1;

fn render_fixture(name: &str, settings: &RenderSettings) -> image::RgbImage {
    let dir = root().join("fixtures");
    let scene = splat_io::ply::read_ply(&dir.join(format!("{name}.ply"))).unwrap();
    let camera = splat_io::cameras::read_cameras(&dir.join(format!("{name}.cameras.json"))).unwrap()[0];
    let out = render_oracle(&scene, &camera, settings, &splat_core::Frames::default(), &|_| {}).unwrap();
    to_rgba8(&out.mean).to_rgb8()
}

#[test]
fn every_method_matches_its_golden_images() {
    let mut failures = Vec::new();
    for fixture in golden::FIXTURES {
        for (suffix, case, frames) in golden::cases() {
            let image = golden::render(fixture, &case, &frames);
            if let Err(e) = compare_golden(&golden::path(fixture, suffix), &image, TOLERANCE) {
                failures.push(e);
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The lit demo world, every family's look: with the default emissive material the images
/// above are unchanged; these prove the lit ones stay as blessed.
#[test]
fn lit_world_matches_its_golden_images() {
    let mut failures = Vec::new();
    for (suffix, case, frames) in golden::lit_cases() {
        let image = golden::render_lit(&case, &frames);
        if let Err(e) = compare_golden(&golden::path("demo-lit", suffix), &image, TOLERANCE) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The demo among meshes by each pipeline: ray tracing (splats in front of meshes, shadows,
/// mirror and glass bounces), raster three-pass compositing and the hybrid.
#[test]
fn mesh_world_matches_its_golden_images() {
    let mut failures = Vec::new();
    for (suffix, case, frames) in golden::mesh_cases() {
        let image = golden::render_meshes(&case, &frames);
        if let Err(e) = compare_golden(&golden::path("demo-meshes", suffix), &image, TOLERANCE) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The comparison can fail: a render with another background differs from the golden image.
#[test]
fn golden_comparison_rejects_a_different_image() {
    let settings = RenderSettings { background: glam::Vec3::new(0.0, 0.0, 0.05), ..Default::default() };
    let dir = std::env::temp_dir().join(format!("splat-golden-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let golden = dir.join("layers-oracle.png");
    std::fs::copy(root().join("fixtures/golden/layers-oracle.png"), &golden).unwrap();
    let err = compare_golden(&golden, &render_fixture("layers", &settings), TOLERANCE).unwrap_err();
    assert!(err.contains("differ"), "{err}");
    assert!(dir.join("layers-oracle-diff.png").exists());
    assert!(dir.join("layers-oracle-actual.png").exists());
}

/// The path tracer on the mesh world: Algorithm 1, stochastic-n and exact compositing of the
/// Gaussians at every segment, 16 Sobol samples (shadows, glossy and glass bounces, the lights).
#[test]
fn path_traced_mesh_world_matches_its_golden_images() {
    let mut failures = Vec::new();
    for (suffix, gaussians, frames) in golden::path_cases() {
        let image = golden::render_path(gaussians, &frames);
        if let Err(e) = compare_golden(&golden::path("demo-meshes", suffix), &image, TOLERANCE) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
