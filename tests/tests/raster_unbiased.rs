//! Statistical proof of the raster estimators (docs/architecture.md, "How correctness is
//! proven"): per-pixel z-tests of StochasticSplats, Enderton and Laine–Karras stratified against
//! sorted splatting with the same samples, on two fixtures and a crop of the bonsai capture, and
//! convergence slopes. The negative control, stratified without the scramble of Figure 4, must
//! fail the same test on overlapping layers, and every method with a 2 % error injected must
//! fail it everywhere (the power study of docs/power.md).

use splat_core::catalogue::Family;
use splat_core::raster::{Blend, render_raster};
use splat_core::raster::{FragmentDepth, RasterMethod, RasterSettings, Rasterizer};
use splat_core::{Camera, Frames, RenderSettings, Scene};
use splat_tests::harness::{FAULTS, MONTE_CARLO_SLOPE, StatTest, assert_covers_the_catalogue, assert_power, fixture};

/// Frames of the mean run (the variance run has 4×).
const F: u32 = 256;

const UNBIASED: [(&str, RasterMethod); 3] = [
    ("stochastic-splat", RasterMethod::StochasticSplat),
    ("enderton", RasterMethod::Enderton),
    ("stratified", RasterMethod::Stratified { scramble: true }),
];

/// A new unbiased splatting estimator in the catalogue joins these z-tests.
#[test]
fn every_unbiased_estimator_of_the_catalogue_is_tested() {
    assert_covers_the_catalogue("the CPU splatting z-tests", Family::Raster, UNBIASED.iter().map(|(_, m)| m.id()));
}

fn base() -> Frames {
    Frames { count: F, seed: 7, ..Frames::default() }
}

fn check(fixture_name: &str, scene: &Scene, camera: &Camera, raster: RasterSettings) {
    let r = Rasterizer::new(scene, camera, RenderSettings::default(), raster).unwrap();
    for (name, method) in UNBIASED {
        let label = format!("{fixture_name} {name} S={} {:?}", raster.samples, raster.fragment_depth);
        StatTest::raster(label, &r, method).assert_unbiased(base());
    }
}

/// The power study of one fixture: each method with each fault against the true oracle.
fn power(fixture_name: &str, scene: &Scene, camera: &Camera, raster: RasterSettings) {
    let r = Rasterizer::new(scene, camera, RenderSettings::default(), raster).unwrap();
    let sorted = RasterMethod::Sorted { blend: Blend::Under };
    let oracle = render_raster(&r, &sorted, &Frames::default(), &|_| {}).unwrap();
    for (name, method) in UNBIASED {
        assert_power(&format!("cpu-raster {fixture_name} {name} S={}", raster.samples), &FAULTS, |fault| {
            let faulty = fault.scene(scene);
            let faulty = Rasterizer::new(&faulty, camera, RenderSettings::default(), raster).unwrap();
            let run = |f: Frames| render_raster(&faulty, &method, &f, &|_| {}).unwrap();
            let expectation = render_raster(&faulty, &sorted, &Frames::default(), &|_| {}).unwrap();
            StatTest::new(name, oracle.clone(), run).z_test_with_expectation(fault.frames(base()), &expectation)
        });
    }
}

#[test]
fn z_test_on_layers() {
    let (scene, camera) = fixture("layers", 64, 48);
    for samples in [1, 4] {
        check("layers", &scene, &camera, RasterSettings { samples, ..RasterSettings::default() });
    }
    let plane =
        RasterSettings { samples: 1, fragment_depth: FragmentDepth::MaxDensityPlane, ..RasterSettings::default() };
    check("layers", &scene, &camera, plane);
    power("layers", &scene, &camera, RasterSettings { samples: 4, ..RasterSettings::default() });
}

#[test]
fn z_test_on_cloud() {
    let (scene, camera) = fixture("cloud", 40, 30);
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    check("cloud", &scene, &camera, raster);
    power("cloud", &scene, &camera, raster);
}

#[test]
fn z_test_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    check("bonsai", &scene, &camera, raster);
    power("bonsai", &scene, &camera, raster);
}

/// Without the scramble, the surfaces of a pixel get nearly the same reference values, so a
/// sample rejected by the nearest layer is rejected by the others of equal or lower alpha:
/// overlapping layers come out too transparent, and the z-test says so.
#[test]
fn unscrambled_stratified_is_rejected() {
    let (scene, camera) = fixture("layers", 40, 30);
    for samples in [1, 4] {
        let raster = RasterSettings { samples, ..RasterSettings::default() };
        let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
        let method = RasterMethod::Stratified { scramble: false };
        StatTest::raster(format!("layers unscrambled stratified S={samples}"), &r, method).assert_rejected(base());
    }
}

#[test]
fn convergence_slopes_are_monte_carlo() {
    let (scene, camera) = fixture("cloud", 32, 24);
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    for (name, method) in UNBIASED {
        let test = StatTest::raster(format!("cloud {name}"), &r, method);
        if name == "stratified" {
            // Laine–Karras may converge faster than 1/√spp; only a plateau (bias) is refused.
            let (slope, table) = test.convergence(256, 3);
            assert!(slope < *MONTE_CARLO_SLOPE.end(), "{name}: slope {slope} {table:?}");
        } else {
            test.assert_converges(256, 3);
        }
    }
    // The biased control plateaus where its layers overlap.
    let (scene, camera) = fixture("layers", 32, 24);
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    let control = StatTest::raster("layers unscrambled stratified", &r, RasterMethod::Stratified { scramble: false });
    let (slope, table) = control.convergence(256, 3);
    assert!(slope > *MONTE_CARLO_SLOPE.end(), "the biased control converges like an unbiased one: {slope} {table:?}");
}
