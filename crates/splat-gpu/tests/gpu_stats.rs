//! Statistical proof of the GPU kernels against `splat-core` (on lavapipe in CI): per-pixel
//! z-tests against the core's exact image with the biased control rejected (convergence and the
//! Welch t-test are in `gpu_convergence.rs`). lavapipe renders one frame per dispatch and leaks about
//! 2 MB per dispatch, so these use 64 frames for the mean (256 for the variance): a 2 % bias is
//! still caught (ARCHITECTURE.md's budget of 256 frames catches 1 %).

mod common;

use common::{context, fixture, gpu_run, unbiased};
use splat_core::render::RenderSettings;
use splat_core::stats::ZTest;
use splat_core::trace::{Frames, Method, TraceScene, render_frames};
use splat_core::{Camera, Scene};
use splat_gpu::{GpuContext, GpuScene};

/// Frames of the mean run.
const F: u32 = 64;

/// The z-test of a GPU method against the core's exact image over covered pixel-channels.
fn gpu_z_test(ctx: &GpuContext, scene: &Scene, camera: &Camera, method: &Method, f: u32) -> ZTest {
    let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
    let gpu_scene = GpuScene::new(ctx, &trace).unwrap();
    let exact = render_frames(&trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    let mask: Vec<bool> = exact.alpha.data().iter().flat_map(|&a| [a > 1e-4; 3]).collect();
    let keep = |v: &[f32]| v.iter().zip(&mask).filter(|(_, m)| **m).map(|(v, _)| *v).collect::<Vec<_>>();
    let mean = gpu_run(ctx, &gpu_scene, &trace, camera, method, Frames { count: f, seed: 21, ..Frames::default() });
    let var = gpu_run(ctx, &gpu_scene, &trace, camera, method, Frames { count: 4 * f, seed: 22, ..Frames::default() });
    ZTest::new(&keep(mean.mean.data()), &keep(exact.mean.data()), &keep(var.variance.data()), f, 3)
}

fn check_z(ctx: &GpuContext, scene: &Scene, camera: &Camera) {
    for (name, method) in unbiased() {
        let z = gpu_z_test(ctx, scene, camera, &method, F);
        eprintln!("GPU {name}: {z:?}");
        assert!(z.passes(), "GPU {name} fails the z-test: {z:?}");
    }
    let z = gpu_z_test(ctx, scene, camera, &Method::DepthSampling { k: 1 }, F);
    eprintln!("GPU depth-sampling-1: {z:?}");
    assert!(!z.passes(), "the biased control passes on the GPU: {z:?}");
}

#[test]
fn gpu_methods_pass_the_z_test_on_layers() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 32, 24);
    check_z(ctx, &scene, &camera);
}

#[test]
fn gpu_methods_pass_the_z_test_on_cloud() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 32, 24);
    check_z(ctx, &scene, &camera);
}

#[test]
fn gpu_methods_pass_the_z_test_on_a_bonsai_crop() {
    let Some(ctx) = context() else { return };
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 24, 16).unwrap();
    check_z(ctx, &scene, &camera);
}
