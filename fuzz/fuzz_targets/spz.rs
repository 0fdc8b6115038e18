//! Fuzz the `.spz` reader (versions 2–4): no input may panic. The first byte picks the axes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use splat_io::spz::{SpzAxes, parse_spz};

fuzz_target!(|data: &[u8]| {
    let axes = if data.first().is_some_and(|b| b & 1 == 1) { SpzAxes::Rub } else { SpzAxes::AsStored };
    let _ = parse_spz(data.get(1..).unwrap_or_default(), axes);
});
