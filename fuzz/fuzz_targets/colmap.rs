//! Fuzz the COLMAP model reader: no input may panic. Byte 0 picks binary or text, bytes 1–2
//! where the cameras file ends and the images file begins.
#![no_main]
use libfuzzer_sys::fuzz_target;
use splat_io::colmap::parse_colmap;

fuzz_target!(|data: &[u8]| {
    if data.len() < 3 {
        return;
    }
    let binary = data[0] & 1 == 1;
    let rest = &data[3..];
    let split = (usize::from(u16::from_le_bytes([data[1], data[2]]))).min(rest.len());
    let _ = parse_colmap(&rest[..split], &rest[split..], binary);
});
