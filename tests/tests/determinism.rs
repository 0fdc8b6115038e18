//! The same scene and settings give the bit-identical image whatever the thread count.

use splat_core::render::{RenderSettings, render_exact};
use splat_core::scenes;

fn render_with_threads(threads: usize) -> Vec<f32> {
    let (scene, camera) = scenes::cloud();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let out = pool
        .install(|| render_exact(&scene, &camera, &RenderSettings::default(), &|_| {}).unwrap());
    [out.radiance, out.alpha, out.depth, out.normal]
        .iter()
        .flat_map(|i| i.data().to_vec())
        .collect()
}

#[test]
fn image_is_identical_for_one_two_and_three_threads() {
    let one = render_with_threads(1);
    for threads in [2, 3] {
        let other = render_with_threads(threads);
        assert!(
            one.iter()
                .zip(&other)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{threads} threads differ"
        );
    }
}
