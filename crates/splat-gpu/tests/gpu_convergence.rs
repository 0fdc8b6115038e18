//! Convergence of the GPU kernels and a Welch t-test against the CPU (on lavapipe in CI). A
//! binary of its own: lavapipe leaks about 2 MB per dispatch, and each test binary is a process
//! that returns its memory when it ends.

mod common;

use common::{context, fixture, gpu_run, unbiased};
use splat_core::render::RenderSettings;
use splat_core::stats::{log_log_slope, rmse, welch_t};
use splat_core::trace::{Frames, Method, TraceScene, render_frames};
use splat_gpu::GpuScene;

/// RMSE of GPU means against exact at spp 1 … 64 (three seeds each) falls as a power law
/// with slope in [−0.58, −0.42].
#[test]
fn gpu_convergence_slopes() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 24, 18);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let gpu_scene = GpuScene::new(ctx, &trace).unwrap();
    let exact = render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    for (name, method) in unbiased() {
        let levels = [1u32, 2, 4, 8, 16, 32, 64];
        let errors: Vec<f64> = levels
            .iter()
            .map(|&spp| {
                (0..3)
                    .map(|s| {
                        let out = gpu_run(
                            ctx,
                            &gpu_scene,
                            &trace,
                            &camera,
                            &method,
                            Frames { count: spp, seed: 100 * spp + s, ..Frames::default() },
                        );
                        rmse(out.mean.data(), exact.mean.data())
                    })
                    .sum::<f64>()
                    / 3.0
            })
            .collect();
        let x: Vec<f64> = levels.iter().map(|&s| f64::from(s)).collect();
        let slope = log_log_slope(&x, &errors);
        eprintln!("GPU {name}: slope {slope:.3} {errors:?}");
        assert!((-0.58..=-0.42).contains(&slope), "GPU {name}: slope {slope}");
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
    let run_t = |background_gain: f32| {
        let settings = RenderSettings::default();
        let trace = TraceScene::new(&scene, settings).unwrap();
        let cpu = render_frames(
            &trace,
            &camera,
            &Method::Stochastic,
            &Frames { count: n, seed: 31, ..Frames::default() },
            &|_| {},
        )
        .unwrap();
        let gpu_settings = RenderSettings { background: glam::Vec3::splat(0.5 * background_gain), ..settings };
        let cpu_settings_bg = RenderSettings { background: glam::Vec3::splat(0.5), ..settings };
        let cpu_trace = TraceScene::new(&scene, cpu_settings_bg).unwrap();
        let cpu = render_frames(
            &cpu_trace,
            &camera,
            &Method::Stochastic,
            &Frames { count: n, seed: 31, ..Frames::default() },
            &|_| {},
        )
        .unwrap_or(cpu);
        let gpu_trace = TraceScene::new(&scene, gpu_settings).unwrap();
        let gpu_scene = GpuScene::new(ctx, &gpu_trace).unwrap();
        let gpu = gpu_run(
            ctx,
            &gpu_scene,
            &gpu_trace,
            &camera,
            &Method::Stochastic,
            Frames { count: n, seed: 32, ..Frames::default() },
        );
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
        outliers <= 0.03 && mean_t.abs() < 4.0 / (count as f64).sqrt() * 1.0 + 0.2,
        "outliers {outliers}, mean t {mean_t}"
    );
    let (outliers, mean_t, _) = run_t(1.02);
    eprintln!("Welch, 2 % brighter background on the GPU: {:.2} % with p < 0.01, mean t {mean_t:.3}", 100.0 * outliers);
    assert!(outliers > 0.03 || mean_t > 0.2, "a biased GPU kernel passes the Welch test");
}
