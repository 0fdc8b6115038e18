//! Fuzz the Wavefront `.obj` mesh reader: no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::mesh::parse_obj(data);
});
