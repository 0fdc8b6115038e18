//! `cargo bench -p splat-gpu`: the GPU radix sort in keys per second against the CPU mirror and
//! the standard library's sort, in the same run, on 2¹⁸ random 32-bit keys with values (a depth
//! sort of the bonsai capture's 272,956 splats is about this size). Upload and readback are
//! included in the GPU figure; `splat bench --methods raster-sorted` times the sort pass alone.

use divan::counter::ItemsCount;
use splat_core::rng::SplitMix64;
use splat_gpu::sort::{cpu_radix_sort, sort_pairs};
use splat_gpu::{GpuContext, RasterPipelines};
use std::sync::LazyLock;

fn main() {
    divan::main();
}

const N: usize = 1 << 18;

static KEYS: LazyLock<Vec<u32>> = LazyLock::new(|| {
    let mut rng = SplitMix64::new(1);
    (0..N).map(|_| rng.next_u64() as u32).collect()
});

static GPU: LazyLock<Option<(GpuContext, RasterPipelines)>> = LazyLock::new(|| {
    let ctx = GpuContext::new().map_err(|e| eprintln!("no GPU sort benchmark: {e}")).ok()?;
    let pipes = RasterPipelines::new(&ctx).expect("the sort kernels compile");
    eprintln!("GPU: {}", ctx.describe());
    Some((ctx, pipes))
});

#[divan::bench(sample_count = 5)]
fn gpu_radix_sort(bencher: divan::Bencher) {
    let Some((ctx, pipes)) = GPU.as_ref() else { return };
    let vals: Vec<u32> = (0..N as u32).collect();
    bencher.counter(ItemsCount::new(N)).bench(|| sort_pairs(ctx, pipes.sort(), &KEYS, &vals, 32).expect("sort"));
}

#[divan::bench(sample_count = 5)]
fn cpu_radix_sort_mirror(bencher: divan::Bencher) {
    bencher.counter(ItemsCount::new(N)).bench(|| {
        let (mut k, mut v) = (KEYS.clone(), (0..N as u32).collect());
        cpu_radix_sort(&mut k, &mut v, 32);
        (k, v)
    });
}

#[divan::bench(sample_count = 5)]
fn std_stable_sort(bencher: divan::Bencher) {
    bencher.counter(ItemsCount::new(N)).bench(|| {
        let mut pairs: Vec<(u32, u32)> = KEYS.iter().copied().zip(0..).collect();
        pairs.sort_by_key(|p| p.0);
        pairs
    });
}
