//! The GPU statistics of `gpu_stats.rs` on the `cloud` fixture, in a process of its own.

mod common;

use common::{context, fixture, z_tests_and_power};

#[test]
fn gpu_methods_pass_the_z_test_on_cloud() {
    let Some(ctx) = context() else { return };
    let (scene, camera) = fixture("cloud", 32, 24);
    z_tests_and_power(ctx, "cloud", &scene, &camera, false);
}
