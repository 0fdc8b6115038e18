//! Fuzz the glTF 2.0 (`.gltf` JSON and `.glb`) mesh reader: no input may panic. External
//! buffers resolve inside an empty folder, so only embedded data is ever read.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::mesh::parse_gltf(data, std::path::Path::new("/nonexistent"));
});
