//! Fuzz the `transforms.json` reader (NeRF-synthetic, Nerfstudio): no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::transforms::parse_transforms(data, None);
});
