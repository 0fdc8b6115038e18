//! Fuzz the gsplat checkpoint reader (Zip64 archives, the pickle machine, tensor layouts): no
//! input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::torch::parse_gsplat_checkpoint(data);
});
