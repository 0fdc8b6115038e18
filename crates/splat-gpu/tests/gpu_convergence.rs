//! Convergence of the GPU kernels and a Welch t-test against the CPU (on lavapipe in CI). A
//! binary of its own: lavapipe leaks about 2 MB per dispatch, and each test binary is a process
//! that returns its memory when it ends.

mod common;

use common::{context, fixture, gpu_run, gpu_stat, tracer, unbiased};
use splat_core::stats::welch_t;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Frames, RenderSettings};

/// RMSE of GPU means against exact at spp 1 … 64 (three seeds each) falls as a power law
/// with slope in [−0.58, −0.42].
#[test]
fn gpu_convergence_slopes() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 24, 18);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    for (name, method) in unbiased() {
        gpu_stat(format!("GPU cloud {name}"), &tracer, &trace, &camera, method).assert_converges(64, 3);
    }
}

/// Welch t-test per pixel-channel between GPU and CPU `stochastic` means over independent
/// seeds: the two backends estimate the same expectation (at most 3 % of |t| above the 1 %
/// two-sided critical value, and a mean t near 0). A GPU kernel with a 2 % brighter background
/// is rejected by the same test.
#[test]
fn welch_t_test_between_backends() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 32, 24);
    let n = 256u32;
    let with_background =
        |gain: f32| RenderSettings { background: glam::Vec3::splat(0.5 * gain), ..Default::default() };
    let cpu_trace = TraceScene::new(&scene, with_background(1.0)).unwrap();
    let frames = |seed| Frames { count: n, seed, ..Frames::default() };
    let cpu = render_frames(&cpu_trace, &camera, &Method::Stochastic, &frames(31), &|_| {}).unwrap();
    let run_t = |background_gain: f32| {
        let gpu_trace = TraceScene::new(&scene, with_background(background_gain)).unwrap();
        let gpu = gpu_run(&tracer(ctx, &gpu_trace), &camera, &Method::Stochastic, frames(32));
        let ts: Vec<f64> = (0..cpu.mean.data().len())
            .map(|i| {
                welch_t(
                    f64::from(gpu.mean.data()[i]),
                    f64::from(gpu.variance.data()[i]),
                    u64::from(n),
                    f64::from(cpu.mean.data()[i]),
                    f64::from(cpu.variance.data()[i]),
                    u64::from(n),
                )
            })
            .filter(|t| t.is_finite())
            .collect();
        let outliers = ts.iter().filter(|t| t.abs() > 2.576).count() as f64 / ts.len() as f64;
        let mean_t = ts.iter().sum::<f64>() / ts.len() as f64;
        (outliers, mean_t, ts.len())
    };
    let (outliers, mean_t, count) = run_t(1.0);
    eprintln!("Welch: {count} pixel-channels, {:.2} % with p < 0.01, mean t {mean_t:.3}", 100.0 * outliers);
    assert!(
        outliers <= 0.03 && mean_t.abs() < 4.0 / (count as f64).sqrt() + 0.2,
        "outliers {outliers}, mean t {mean_t}"
    );
    let (outliers, mean_t, _) = run_t(1.02);
    eprintln!("Welch, 2 % brighter background on the GPU: {:.2} % with p < 0.01, mean t {mean_t:.3}", 100.0 * outliers);
    assert!(outliers > 0.03 || mean_t > 0.2, "a biased GPU kernel passes the Welch test");
}
