//! Statistical proof of the GPU kernels against `splat-core` (on lavapipe in CI): per-pixel
//! z-tests against the core's exact image with the biased control rejected, and the power
//! study of docs/power.md (`common::z_tests_and_power`). One fixture per test binary, so one
//! process each: lavapipe keeps about 3 MB per dispatch until the process ends. Convergence
//! and the two-sample test are in `gpu_convergence.rs`.

mod common;

use common::{context, fixture, z_tests_and_power};
use splat_core::MethodId;
use splat_core::catalogue::Family;

/// A new unbiased ray-tracing estimator with a GPU kernel joins the GPU z-tests.
#[test]
fn every_unbiased_estimator_of_the_catalogue_is_tested() {
    let tested = common::unbiased().into_iter().map(|(_, m)| m.id());
    let cpu_only = MethodId::of(Family::Trace).filter(|m| !m.entry().gpu);
    splat_tests::harness::assert_covers_the_catalogue(
        "the GPU ray-tracing z-tests",
        Family::Trace,
        tested.chain(cpu_only),
    );
}

#[test]
fn gpu_methods_pass_the_z_test_on_layers() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("layers", 64, 48);
    z_tests_and_power(ctx, "layers", &scene, &camera, true);
}
