//! Fuzz the glTF `KHR_gaussian_splatting` splat reader (`.gltf` JSON and `.glb`): no input may
//! panic. External buffers resolve inside a folder that does not exist, so only embedded data
//! is ever read.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_io::gltf_splats::parse_gltf_splats(data, std::path::Path::new("/nonexistent"));
});
