//! The GPU statistics of `gpu_stats.rs` on a crop of the bonsai capture, in a process of its
//! own.

mod common;

use common::{context, z_tests_and_power};

#[test]
fn gpu_methods_pass_the_z_test_on_a_bonsai_crop() {
    let Some(ctx) = context() else { return };
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    z_tests_and_power(ctx, "bonsai", &scene, &camera, false);
}
