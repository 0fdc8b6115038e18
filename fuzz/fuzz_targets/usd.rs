//! Fuzz the OpenUSD `.usda` reader (the lexer, prims, values, xformOps and the splats' checks):
//! no input may panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::usd::parse_usda(data);
});
