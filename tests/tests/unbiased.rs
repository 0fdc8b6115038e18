//! Statistical proof of the ray-tracing estimators (ARCHITECTURE.md, "How correctness is
//! proven"): per-pixel z-tests against exact on two fixtures and a crop of the bonsai capture,
//! and log–log convergence slopes. The biased control, 3DGRT depth sampling, must fail the same
//! test with the same budget.

use splat_core::render::RenderSettings;
use splat_core::rng::RngScheme;
use splat_core::trace::{Frames, Method, TraceScene};
use splat_core::{Camera, Scene};
use splat_tests::stat::{convergence, z_test};

/// Frames of the mean run (the variance run has 4×).
const F: u32 = 256;

fn fixture(name: &str, width: u32, height: u32) -> (Scene, Camera) {
    let (scene, camera) = splat_core::scenes::by_name(name).unwrap();
    (scene, camera.rescaled(width, height).unwrap())
}

/// The unbiased methods with the hash generator. The trig hash of Sun et al. Eqs. 8–10 is left
/// out: in f32 its u is quantised (see `rng::tests::trig_hash_is_quantised_in_f32`) and the
/// bonsai crop shows the resulting bias at this budget (global 2.8–4.4 over six seeds).
fn unbiased_methods() -> Vec<(&'static str, Method, RngScheme)> {
    vec![
        ("stochastic", Method::Stochastic, RngScheme::Hash),
        ("stochastic-n 2×4", Method::StochasticN { m: 2, n: 4 }, RngScheme::Hash),
        ("stochastic-pass", Method::StochasticPass { k: 4, max_passes: 200 }, RngScheme::Hash),
    ]
}

fn check(scene: &Scene, camera: &Camera) {
    let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
    let mut report = Vec::new();
    for (name, method, rng) in unbiased_methods() {
        let z = z_test(&trace, camera, &method, Frames { count: F, seed: 7, rng });
        report.push(format!("{name}: {z:?}"));
        assert!(z.passes(), "{name} fails the z-test: {z:?}\n{}", report.join("\n"));
    }
    for k in [1, 3] {
        let z =
            z_test(&trace, camera, &Method::DepthSampling { k }, Frames { count: F, seed: 7, rng: RngScheme::Hash });
        report.push(format!("depth-sampling-{k}: {z:?}"));
        assert!(!z.passes(), "the biased control depth-sampling-{k} passes: {z:?}");
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
fn z_test_on_layers() {
    let (scene, camera) = fixture("layers", 40, 30);
    check(&scene, &camera);
}

#[test]
fn z_test_on_cloud() {
    let (scene, camera) = fixture("cloud", 40, 30);
    check(&scene, &camera);
}

#[test]
fn z_test_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    check(&scene, &camera);
}

#[test]
fn convergence_slopes_are_monte_carlo() {
    let (scene, camera) = fixture("cloud", 32, 24);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    for (name, method, _) in unbiased_methods() {
        let (slope, table) = convergence(&trace, &camera, &method, 256, 3);
        eprintln!("{name}: slope {slope:.3} {table:?}");
        assert!((-0.58..=-0.42).contains(&slope), "{name}: slope {slope} {table:?}");
    }
    let (slope, table) = convergence(&trace, &camera, &Method::DepthSampling { k: 1 }, 256, 3);
    eprintln!("depth-sampling-1: slope {slope:.3} {table:?}");
    assert!(slope > -0.42, "the biased control converges like an unbiased one: {slope} {table:?}");
}
