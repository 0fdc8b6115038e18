//! Statistical proof of the GPU kernels against `splat-core` (on lavapipe in CI): per-pixel
//! z-tests against the core's exact image with the biased control rejected (convergence and the
//! Welch t-test are in `gpu_convergence.rs`). lavapipe renders one frame per dispatch and leaks
//! about 2 MB per dispatch, so these use 64 frames for the mean (256 for the variance): a 2 %
//! bias is still caught (docs/architecture.md's budget of 256 frames catches 1 %).

mod common;

use common::{context, fixture, gpu_stat, tracer, unbiased};
use splat_core::trace::{Method, TraceScene};
use splat_core::{Camera, Frames, RenderSettings, Scene};
use splat_gpu::GpuContext;

/// Frames of the mean run.
const F: u32 = 64;

fn check_z(ctx: &'static GpuContext, fixture_name: &str, scene: &Scene, camera: &Camera) {
    let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
    let tracer = tracer(ctx, &trace);
    let base = Frames { count: F, seed: 21, ..Frames::default() };
    for (name, method) in unbiased() {
        gpu_stat(format!("GPU {fixture_name} {name}"), &tracer, &trace, camera, method).assert_unbiased(base);
    }
    let control = Method::DepthSampling { k: 1 };
    gpu_stat(format!("GPU {fixture_name} depth-sampling-1"), &tracer, &trace, camera, control).assert_rejected(base);
}

#[test]
fn gpu_methods_pass_the_z_test_on_layers() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 32, 24);
    check_z(ctx, "layers", &scene, &camera);
}

#[test]
fn gpu_methods_pass_the_z_test_on_cloud() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 32, 24);
    check_z(ctx, "cloud", &scene, &camera);
}

#[test]
fn gpu_methods_pass_the_z_test_on_a_bonsai_crop() {
    let Some(ctx) = context() else { return };
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 24, 16).unwrap();
    check_z(ctx, "bonsai", &scene, &camera);
}
