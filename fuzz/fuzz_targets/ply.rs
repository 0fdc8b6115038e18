//! Fuzz the `.ply` reader: no input may panic. The first byte picks the leniency option.
#![no_main]
use libfuzzer_sys::fuzz_target;
use splat_io::ply::{PlyOptions, parse_ply};

fuzz_target!(|data: &[u8]| {
    let allow_unknown_properties = data.first().is_some_and(|b| b & 1 == 1);
    let _ = parse_ply(data.get(1..).unwrap_or_default(), PlyOptions { allow_unknown_properties });
});
