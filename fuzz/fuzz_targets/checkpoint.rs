//! Fuzz the checkpoint reader (gsplat's and Nerfstudio's: Zip64 archives, the pickle machine,
//! tensor layouts): no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::torch::parse_checkpoint(data);
});
