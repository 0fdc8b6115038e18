//! Shared helpers of the GPU test binaries.
#![allow(dead_code)]

use splat_core::{Camera, Scene};
use splat_gpu::GpuContext;
use std::sync::OnceLock;

/// The shared context; `None` (with the reason printed) when there is no adapter, except under
/// `CI=true`, where a missing adapter fails the test.
pub fn context() -> Option<&'static GpuContext> {
    static CTX: OnceLock<Result<GpuContext, String>> = OnceLock::new();
    match CTX.get_or_init(|| GpuContext::new().map_err(|e| e.to_string())) {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            assert!(std::env::var("CI").is_err(), "CI=true and no GPU adapter: {e}");
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

pub fn fixture(name: &str, width: u32, height: u32) -> (Scene, Camera) {
    let (scene, camera) = splat_core::scenes::by_name(name).unwrap();
    (scene, camera.rescaled(width, height).unwrap())
}
