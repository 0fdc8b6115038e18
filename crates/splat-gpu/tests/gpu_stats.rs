//! Statistical proof of the GPU kernels against `splat-core` (on lavapipe in CI): per-pixel
//! z-tests against the core's exact image with the biased control rejected, and the power
//! study of docs/power.md (`common::z_tests_and_power`). One fixture per test binary, so one
//! process each: lavapipe keeps about 3 MB per dispatch until the process ends. Convergence
//! and the two-sample test are in `gpu_convergence.rs`.

mod common;

use common::{context, fixture, z_tests_and_power};

#[test]
fn gpu_methods_pass_the_z_test_on_layers() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 64, 48);
    z_tests_and_power(ctx, "layers", &scene, &camera, true);
}
