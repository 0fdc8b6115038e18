//! The statistical harness itself: a failing z-test panics with the statistics and writes the
//! per-pixel z-map beside the fixtures, and the same estimator that fails `assert_unbiased`
//! passes `assert_rejected`.

use splat_core::trace::{Method, TraceScene};
use splat_core::{Frames, RenderSettings};
use splat_tests::harness::{StatTest, fixture};
use splat_tests::root;
use std::panic::{AssertUnwindSafe, catch_unwind};

#[test]
fn a_failing_z_test_writes_its_z_map() {
    let (scene, camera) = fixture("layers", 40, 30);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let name = "harness-self-test depth-sampling-1";
    let test = StatTest::trace(name, &trace, &camera, Method::DepthSampling { k: 1 });
    let path = root().join("fixtures/harness-self-test_depth-sampling-1-zmap.png");
    let _ = std::fs::remove_file(&path);
    let base = Frames { count: 256, seed: 7, ..Frames::default() };
    let failed = catch_unwind(AssertUnwindSafe(|| test.assert_unbiased(base)));
    let message = failed.expect_err("a biased estimator passed assert_unbiased");
    let message = message.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(message.contains("fails the z-test") && message.contains("zmap.png"), "{message}");
    let map = image::open(&path).expect("the z-map was written").to_rgb8();
    assert_eq!(map.dimensions(), (camera.width, camera.height));
    // Grey is z = 0; a biased estimator leaves covered pixels far from it.
    assert!(map.pixels().any(|p| p[0].abs_diff(128) > 64), "the z-map shows no bias");
    std::fs::remove_file(&path).unwrap();
    test.assert_rejected(base);
}

/// The control's sequential test goes on to the full budget when its first stage does not
/// reject, and there an unbiased estimator passes: it is not taken for a biased control.
#[test]
fn an_unbiased_estimator_fails_assert_rejected_at_both_stages() {
    let (scene, camera) = fixture("layers", 40, 30);
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap();
    let test = StatTest::trace("harness-self-test stochastic", &trace, &camera, Method::Stochastic);
    let base = Frames { count: 256, seed: 7, ..Frames::default() };
    let failed = catch_unwind(AssertUnwindSafe(|| test.assert_rejected(base)));
    let message = failed.expect_err("an unbiased estimator was rejected as a control");
    let message = message.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(message.contains("passes the z-test"), "{message}");
}
