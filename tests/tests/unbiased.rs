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

/// Camera rays drawn per frame through a box pixel filter and a thin lens
/// (`splat_core::camera_sampling`, a circle of confusion of about 5 px on the layers):
/// `stochastic` and StochasticSplats converge to the oracle integrated over the same frames
/// (the filtered oracle: exact through each frame's camera, frame by frame), and each with a
/// 2 % acceptance error is rejected. The z-test's variance includes the camera's own (the
/// spread of the exact image over the pixel and the lens), which the paired oracle removes
/// from the difference, so the test is conservative there. The layers, not the cloud: at the
/// cloud's faint fringe a pixel sees a particle in a few frames out of 256, a Poisson count of
/// about 3 accepted hits that the normal approximation of the z-test does not fit (measured:
/// 214 hits against 228.4 expected over 64 seeds at one such pixel, unbiased, yet |z| up to
/// 100 for a seed that drew none).
#[test]
fn z_test_through_a_box_filter_and_a_thin_lens() {
    use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
    use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster_frames};
    use splat_tests::harness::assert_unbiased_and_shift_rejected;
    let (scene, camera) = fixture("layers", 64, 48);
    let sampling =
        CameraSampling { filter: PixelFilter::Box, lens: Some(ThinLens { aperture: 0.3, focus_distance: 2.0 }) };
    let settings = RenderSettings { sampling, ..RenderSettings::default() };
    let base = Frames { count: F, seed: 7, ..Frames::default() };
    let filtered = splat_core::render_oracle(&scene, &camera, &settings, &base, &|_| {}).unwrap();
    let trace = TraceScene::new(&scene, settings).unwrap();
    let run = |f: Frames| render_frames(&trace, &camera, &Method::Stochastic, &f, &|_| {}).unwrap();
    assert_unbiased_and_shift_rejected("layers stochastic, box filter and lens", &filtered, base, 0.02, run);

    let build = |c: &Camera| Rasterizer::new(&scene, c, settings, RasterSettings::default());
    let raster = |method: RasterMethod, f: Frames| {
        render_raster_frames(&camera, &sampling, &method, &f, &|_| {}, build).unwrap()
    };
    let sorted = raster(RasterMethod::Sorted { blend: Blend::Under }, base);
    let splats = |f: Frames| raster(RasterMethod::StochasticSplat, f);
    assert_unbiased_and_shift_rejected("layers StochasticSplats, box filter and lens", &sorted, base, 0.02, splats);
}

/// vk_gaussian_splatting's advice on its accumulation formats (FP16 by default, FP32 past
/// 150–200 frames), measured on the renderer itself: `stochastic` on the cloud with the running
/// mean stored in f16 and in 8-bit unorm departs from the full-precision mean of the very same
/// frames, and the departure is compared with the noise of the mean (the RMS standard error
/// √(var / F)). f16 stays within the noise for the first hundreds of frames and passes it
/// by 1024 (measured: 6.78e-3 against 6.48e-3 there; at 2048, 1.8e-2 against 4.6e-3); 8-bit
/// passes it sooner (at 128); full precision never moves.
#[test]
fn accumulation_formats_drift_as_vk_warns() {
    use splat_core::frame::AccumulationFormat;
    let (scene, camera) = fixture("cloud", 40, 30);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let render = |count: u32, accumulation| {
        let frames = Frames { count, seed: 3, accumulation, ..Frames::default() };
        render_frames(&trace, &camera, &Method::Stochastic, &frames, &|_| {}).unwrap()
    };
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mut first_past = [None; 3];
    for count in [16u32, 64, 128, 256, 512, 1024] {
        let full = render(count, AccumulationFormat::F32);
        let noise: Vec<f64> = full.variance.data().iter().map(|&v| (f64::from(v) / f64::from(count)).sqrt()).collect();
        let noise = rms(&noise);
        let mut line = format!("{count:>5} frames: noise {noise:.2e}");
        for (k, format) in AccumulationFormat::ALL.into_iter().enumerate() {
            let out = render(count, format);
            let drift: Vec<f64> = out.mean.data().iter().zip(full.mean.data()).map(|(a, b)| f64::from(a - b)).collect();
            let drift = rms(&drift);
            line += &format!(", {} {drift:.2e}", format.name());
            if drift > noise && first_past[k].is_none() {
                first_past[k] = Some(count);
            }
        }
        eprintln!("{line}");
    }
    eprintln!("first frame count past the noise (f32, f16, unorm8): {first_past:?}");
    assert_eq!(first_past[0], None, "full precision drifted");
    assert!(first_past[1].is_some_and(|n| (256..=1024).contains(&n)), "f16: {first_past:?}");
    assert!(first_past[2].is_some_and(|n| n < first_past[1].unwrap()), "unorm8: {first_past:?}");
}
