//! The BVH tracer's `exact` equals the brute-force oracle, and the k-buffer with enough passes
//! equals both, on a fixture and on a crop of the bonsai capture, with each hit distance
//! convention (the BVH bounds each particle by what its convention can hit: the icosahedron
//! proxy's crossings lie outside the visible ellipsoid, up to its circumradius).

use splat_core::oracle::{oracle_ray, render_oracle};
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, Scene};
use splat_core::{Frames, RenderSettings};

fn compare(scene: &Scene, camera: &Camera) {
    for hit_distance in splat_core::HitDistance::ALL {
        compare_with(scene, camera, hit_distance);
    }
}

fn compare_with(scene: &Scene, camera: &Camera, hit_distance: splat_core::HitDistance) {
    let settings = RenderSettings { background: glam::Vec3::new(0.05, 0.1, 0.2), hit_distance, ..Default::default() };
    let oracle = render_oracle(scene, camera, &settings, &splat_core::Frames::default(), &|_| {}).unwrap();
    let trace = TraceScene::new(scene, settings).unwrap();
    let exact = render_frames(&trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    let kbuffer = Method::KBuffer { k: 7, max_passes: 100_000, min_transmittance: 0.0 };
    let kbuf = render_frames(&trace, camera, &kbuffer, &Frames::default(), &|_| {}).unwrap();
    let worst = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    let name = hit_distance.name();
    assert!(worst(oracle.mean.data(), exact.mean.data()) < 1e-6, "{name}: exact vs oracle");
    assert!(worst(oracle.alpha.data(), exact.alpha.data()) < 1e-6, "{name}: alpha");
    assert!(worst(exact.mean.data(), kbuf.mean.data()) < 1e-6, "{name}: kbuffer vs exact");
    // The iso depth is the same hit: equal bits or both absent.
    for (a, b) in oracle.depth.data().iter().zip(exact.depth.data()) {
        assert!(a == b || (a.is_nan() && b.is_nan()), "{name}: depth {a} vs {b}");
    }
    // And a few pixels against the plain brute force over every particle.
    for (x, y) in [(0, 0), (camera.width / 2, camera.height / 2), (camera.width - 1, camera.height - 1)] {
        let c = oracle_ray(scene, camera.pixel_ray(x, y), &settings).unwrap().color_over(settings.background);
        let px = exact.mean.pixel(x, y);
        assert!((0..3).all(|k| (px[k] - c[k] as f32).abs() < 1e-6), "{name}: pixel ({x}, {y})");
    }
}

#[test]
fn exact_through_the_bvh_equals_the_oracle_on_the_cloud() {
    let (scene, camera) = splat_core::scenes::cloud();
    compare(&scene, &camera.rescaled(64, 48).unwrap());
}

#[test]
fn exact_through_the_bvh_equals_the_oracle_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    compare(&scene, &splat_tests::bonsai_camera().crop(540, 160, 48, 36).unwrap());
}
