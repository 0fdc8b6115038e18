//! Fuzz the PlayCanvas SOG reader: a `.sog` bundle (the zip container, `meta.json`, the WebP
//! images and the splats they decode to); no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::sog::parse_sog_bundle(data);
});
