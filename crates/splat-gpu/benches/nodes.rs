//! `cargo bench -p splat-gpu --bench nodes`: encoding a BVH's wide nodes for the GPU (8-bit
//! planes, `splat_gpu::node`) in nodes per second, as the upload does it (`bvh_nodes`, on every
//! core) against one core, in the same run, on the tree of 2²¹ random boxes (about a million
//! nodes; a 32 M-splat scene has 16 times as many).

use divan::counter::ItemsCount;
use splat_core::bvh::Bvh4;
use splat_core::particle::Aabb;
use splat_core::rng::SplitMix64;
use splat_gpu::node::{GpuNode, bvh_nodes};
use std::sync::LazyLock;

fn main() {
    divan::main();
}

static TREE: LazyLock<Bvh4> = LazyLock::new(|| {
    let mut rng = SplitMix64::new(3);
    let boxes = (0..1 << 21)
        .map(|_| {
            let c = glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 100.0;
            Aabb { min: c, max: c + glam::Vec3::splat(0.05 + 0.1 * rng.next_f32()) }
        })
        .collect();
    Bvh4::build(boxes, "boxes").expect("a tree of the boxes").0
});

#[divan::bench(sample_count = 5)]
fn every_core(bencher: divan::Bencher) {
    bencher.counter(ItemsCount::new(TREE.nodes().len())).bench(|| bvh_nodes(&TREE, 0));
}

#[divan::bench(sample_count = 5)]
fn one_core(bencher: divan::Bencher) {
    bencher
        .counter(ItemsCount::new(TREE.nodes().len()))
        .bench(|| TREE.nodes().iter().map(|n| GpuNode::new(n, 0)).collect::<Vec<_>>());
}
