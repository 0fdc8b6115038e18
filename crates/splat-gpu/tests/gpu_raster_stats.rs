//! Statistical proof of GPU StochasticSplats against the CPU raster oracle (sorted splatting,
//! on lavapipe in CI): the per-pixel z-test of ARCHITECTURE.md with F = 256 frames (variance
//! from 1024 independent ones) and its biased control, and the convergence slope. A binary of
//! its own, since lavapipe leaks memory per submission and each test binary is a process.

mod common;

use common::{context, fixture};
use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster};
use splat_core::render::RenderSettings;
use splat_core::stats::ZTest;
use splat_core::trace::{Frames, TraceOutput};
use splat_core::{Camera, Scene};
use splat_gpu::{GpuContext, GpuRasterizer, RasterPipelines, RasterScene};
use splat_tests::method;

const F: u32 = 256;

/// The CPU raster oracle: sorted splatting, one sample per pixel.
fn oracle(scene: &Scene, camera: &Camera) -> TraceOutput {
    let r = Rasterizer::new(scene, camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    render_raster(&r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap().frames
}

/// GPU StochasticSplats frames of `scene` as a [`TraceOutput`] (no depth or normal images).
fn gpu_frames(raster: &GpuRasterizer, frames: Frames) -> TraceOutput {
    let out = raster.render(&RasterMethod::StochasticSplat, &frames).unwrap();
    let empty = splat_core::image::Image::from_data(1, 1, 1, vec![0.0]).unwrap();
    TraceOutput { mean: out.mean, variance: out.variance, alpha: out.alpha, depth: empty.clone(), normal: empty }
}

/// The z-test of GPU StochasticSplats on `scene` against the oracle of `truth`.
fn z_test(ctx: &GpuContext, pipes: &RasterPipelines, scene: &Scene, truth: &Scene, camera: &Camera) -> ZTest {
    let gpu_scene = RasterScene::new(ctx, scene, &RenderSettings::default()).unwrap();
    let raster = GpuRasterizer::new(ctx, pipes, &gpu_scene, camera).unwrap();
    method::z_test(
        &oracle(truth, camera),
        |f| gpu_frames(&raster, f),
        Frames { count: F, seed: 31, ..Frames::default() },
    )
}

/// Every opacity scaled by `factor`: a renderer whose alphas are biased.
fn scaled(scene: &Scene, factor: f32) -> Scene {
    let mut s = scene.clone();
    for p in &mut s.particles {
        p.opacity *= factor;
    }
    s
}

/// GPU StochasticSplats passes the z-test against CPU sorted splatting on two fixtures; the
/// same test with the same budget rejects GPU frames whose opacities are 10 % low (3 % is caught on `layers` but not on `cloud`, whose colours lie close to the background).
#[test]
fn gpu_stochastic_splat_is_unbiased_and_the_control_is_rejected() {
    let Some(ctx) = context() else { return };
    let pipes = RasterPipelines::new(ctx).unwrap();
    for name in ["layers", "cloud"] {
        let (scene, camera) = fixture(name, 40, 30);
        let z = z_test(ctx, &pipes, &scene, &scene, &camera);
        eprintln!("{name} GPU stochastic-splat: {z:?}");
        assert!(z.passes(), "{name}: GPU stochastic-splat fails the z-test: {z:?}");
        let control = z_test(ctx, &pipes, &scaled(&scene, 0.9), &scene, &camera);
        eprintln!("{name} control (opacity × 0.9): {control:?}");
        assert!(!control.passes(), "{name}: the biased control passes: {control:?}");
    }
}

/// RMSE against the oracle at 1 … 256 spp (three seeds) falls with slope in [−0.58, −0.42].
#[test]
fn gpu_stochastic_splat_converges_at_the_monte_carlo_rate() {
    let Some(ctx) = context() else { return };
    let pipes = RasterPipelines::new(ctx).unwrap();
    let (scene, camera) = fixture("cloud", 32, 24);
    let gpu_scene = RasterScene::new(ctx, &scene, &RenderSettings::default()).unwrap();
    let raster = GpuRasterizer::new(ctx, &pipes, &gpu_scene, &camera).unwrap();
    let (slope, table) = method::convergence(&oracle(&scene, &camera), |f| gpu_frames(&raster, f), 256, 3);
    eprintln!("GPU stochastic-splat: slope {slope:.3} {table:?}");
    assert!((-0.58..=-0.42).contains(&slope), "slope {slope}");
}
