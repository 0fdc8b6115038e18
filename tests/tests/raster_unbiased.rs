//! Statistical proof of the raster estimators (ARCHITECTURE.md, "How correctness is proven"):
//! per-pixel z-tests of StochasticSplats, Enderton and Laine–Karras stratified against sorted
//! splatting with the same samples, on two fixtures and a crop of the bonsai capture, and
//! convergence slopes. The negative control, stratified without the scramble of Figure 4, must
//! fail the same test on overlapping layers.

use splat_core::raster::{FragmentDepth, RasterMethod, RasterSettings, Rasterizer};
use splat_core::render::RenderSettings;
use splat_core::trace::Frames;
use splat_core::{Camera, Scene};
use splat_tests::raster_stat::{convergence, z_test};

/// Frames of the mean run (the variance run has 4×).
const F: u32 = 256;

fn fixture(name: &str, width: u32, height: u32) -> (Scene, Camera) {
    let (scene, camera) = splat_core::scenes::by_name(name).unwrap();
    (scene, camera.rescaled(width, height).unwrap())
}

const UNBIASED: [(&str, RasterMethod); 3] = [
    ("stochastic-splat", RasterMethod::StochasticSplat),
    ("enderton", RasterMethod::Enderton),
    ("stratified", RasterMethod::Stratified { scramble: true }),
];

fn check(scene: &Scene, camera: &Camera, raster: RasterSettings) {
    let r = Rasterizer::new(scene, camera, RenderSettings::default(), raster).unwrap();
    let mut report = Vec::new();
    for (name, method) in UNBIASED {
        let z = z_test(&r, &method, Frames { count: F, seed: 7, ..Frames::default() });
        report.push(format!("{name} {raster:?}: {z:?}"));
        assert!(z.passes(), "{name} fails the z-test: {z:?}\n{}", report.join("\n"));
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
fn z_test_on_layers() {
    let (scene, camera) = fixture("layers", 40, 30);
    for samples in [1, 4] {
        check(&scene, &camera, RasterSettings { samples, ..RasterSettings::default() });
    }
    let plane = RasterSettings { samples: 1, fragment_depth: FragmentDepth::MaxDensityPlane };
    check(&scene, &camera, plane);
}

#[test]
fn z_test_on_cloud() {
    let (scene, camera) = fixture("cloud", 40, 30);
    check(&scene, &camera, RasterSettings { samples: 4, ..RasterSettings::default() });
}

#[test]
fn z_test_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    check(&scene, &camera, RasterSettings { samples: 4, ..RasterSettings::default() });
}

/// Without the scramble, the surfaces of a pixel get nearly the same reference values, so a
/// sample rejected by the nearest layer is rejected by the others of equal or lower alpha:
/// overlapping layers come out too transparent, and the z-test says so.
#[test]
fn unscrambled_stratified_is_rejected() {
    let (scene, camera) = fixture("layers", 40, 30);
    for samples in [1, 4] {
        let r = Rasterizer::new(
            &scene,
            &camera,
            RenderSettings::default(),
            RasterSettings { samples, ..RasterSettings::default() },
        )
        .unwrap();
        let method = RasterMethod::Stratified { scramble: false };
        let z = z_test(&r, &method, Frames { count: F, seed: 7, ..Frames::default() });
        eprintln!("unscrambled stratified, {samples} spp: {z:?}");
        assert!(!z.passes(), "the correlated sequence passes: {z:?}");
    }
}

#[test]
fn convergence_slopes_are_monte_carlo() {
    let (scene, camera) = fixture("cloud", 32, 24);
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    for (name, method) in UNBIASED {
        let (slope, table) = convergence(&r, &method, 256, 3);
        eprintln!("{name}: slope {slope:.3} {table:?}");
        if name == "stratified" {
            // Laine–Karras may converge faster than 1/√spp; only a plateau (bias) is refused.
            assert!(slope < -0.42, "{name}: slope {slope} {table:?}");
        } else {
            assert!((-0.58..=-0.42).contains(&slope), "{name}: slope {slope} {table:?}");
        }
    }
    let (slope, table) = convergence(&r, &RasterMethod::Stratified { scramble: false }, 256, 3);
    eprintln!("unscrambled stratified: slope {slope:.3} {table:?}");
}
