//! Fuzz the GaussianSplats3D `.ksplat` reader (headers, sections, buckets, f16 and 8-bit
//! values): no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::ksplat::parse_ksplat(data);
});
