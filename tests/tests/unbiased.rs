//! Statistical proof of the ray-tracing estimators (docs/architecture.md, "How correctness is
//! proven"): per-pixel z-tests against exact on two fixtures and a crop of the bonsai capture,
//! and log–log convergence slopes. The biased control, 3DGRT depth sampling, must fail the same
//! test with the same budget, and so must every method with a 2 % error injected (the power
//! study of docs/power.md).

use splat_core::catalogue::Family;
use splat_core::rng::RngScheme;
use splat_core::trace::render_frames;
use splat_core::trace::{Method, TraceScene};
use splat_core::{Camera, Frames, RenderSettings, Scene};
use splat_tests::harness::{FAULTS, MONTE_CARLO_SLOPE, StatTest, assert_covers_the_catalogue, assert_power, fixture};

/// Frames of the mean run (the variance run has 4×).
const F: u32 = 256;

/// The unbiased methods with the hash generator. The trig hash of Sun et al. Eqs. 8–10 is left
/// out: in f32 its u is quantised (see `rng::tests::trig_hash_is_quantised_in_f32`) and the
/// bonsai crop shows the resulting bias at this budget (global 2.8–4.4 over six seeds).
fn unbiased_methods() -> Vec<(&'static str, Method)> {
    vec![
        ("stochastic", Method::Stochastic),
        ("stochastic-n 2×4", Method::StochasticN { m: 2, n: 4 }),
        ("stochastic-pass", Method::StochasticPass { k: 4, max_passes: 200 }),
    ]
}

/// A new unbiased ray-tracing estimator in the catalogue joins these z-tests.
#[test]
fn every_unbiased_estimator_of_the_catalogue_is_tested() {
    assert_covers_the_catalogue(
        "the CPU ray-tracing z-tests",
        Family::Trace,
        unbiased_methods().iter().map(|(_, m)| m.id()),
    );
}

fn check(fixture_name: &str, scene: &Scene, camera: &Camera) {
    let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
    let base = Frames { count: F, seed: 7, rng: RngScheme::Hash, ..Frames::default() };
    for (name, method) in unbiased_methods() {
        StatTest::trace(format!("{fixture_name} {name}"), &trace, camera, method).assert_unbiased(base);
    }
    let exact = render_frames(&trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    for (name, method) in unbiased_methods() {
        assert_power(&format!("cpu-ray {fixture_name} {name}"), &FAULTS, |fault| {
            let faulty = fault.scene(scene);
            let faulty = TraceScene::new(&faulty, RenderSettings::default()).unwrap();
            let run = |f: Frames| render_frames(&faulty, camera, &method, &f, &|_| {}).unwrap();
            let expectation = render_frames(&faulty, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
            StatTest::new(name, exact.clone(), run).z_test_with_expectation(fault.frames(base), &expectation)
        });
    }
    for k in [1, 3] {
        let control = Method::DepthSampling { k };
        StatTest::trace(format!("{fixture_name} depth-sampling-{k}"), &trace, camera, control).assert_rejected(base);
    }
}

#[test]
fn z_test_on_layers() {
    let (scene, camera) = fixture("layers", 64, 48);
    check("layers", &scene, &camera);
}

#[test]
fn z_test_on_cloud() {
    let (scene, camera) = fixture("cloud", 40, 30);
    check("cloud", &scene, &camera);
}

#[test]
fn z_test_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    check("bonsai", &scene, &camera);
}

#[test]
fn convergence_slopes_are_monte_carlo() {
    let (scene, camera) = fixture("cloud", 32, 24);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    for (name, method) in unbiased_methods() {
        StatTest::trace(format!("cloud {name}"), &trace, &camera, method).assert_converges(256, 3);
    }
    let control = StatTest::trace("cloud depth-sampling-1", &trace, &camera, Method::DepthSampling { k: 1 });
    let (slope, table) = control.convergence(256, 3);
    assert!(slope > *MONTE_CARLO_SLOPE.end(), "the biased control converges like an unbiased one: {slope} {table:?}");
}

/// The measurement behind the README's note on the trig hash of Sun et al. Eqs. 8–10 (whose
/// f32 u fails the uniformity test of `rng`): `stochastic` with each generator on the bonsai
/// crop, three seeds, F = 256 and 1024. A report, not a pass/fail test (minutes of CPU):
/// `cargo test --release -p splat-tests --test unbiased -- --ignored --nocapture trig_hash`.
#[test]
#[ignore]
fn trig_hash_bias_on_the_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    for count in [256u32, 1024] {
        for seed in [7u32, 8, 9] {
            for rng in [RngScheme::Hash, RngScheme::Trig] {
                let frames = Frames { count, seed, rng, ..Frames::default() };
                let z = StatTest::trace("stochastic", &trace, &camera, Method::Stochastic).z_test(frames);
                eprintln!("F = {count}, seed {seed}, {rng:?}: {z:?}, passes {}", z.passes());
            }
        }
    }
}
