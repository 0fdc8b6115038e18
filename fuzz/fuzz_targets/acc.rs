//! Fuzz the accumulation-file (`.acc`) reader: no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::accumulation::parse(data);
});
