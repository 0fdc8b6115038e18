//! Shared helpers of the GPU test binaries.
#![allow(dead_code)]

use splat_core::trace::{Frames, Method, TraceScene};
use splat_core::{Camera, Scene};
use splat_gpu::{GpuContext, GpuScene};
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

/// GPU mean image (seed `seed`, `frames` frames).
pub fn gpu_run(
    ctx: &GpuContext,
    scene: &GpuScene,
    trace: &TraceScene,
    camera: &Camera,
    method: &Method,
    frames: Frames,
) -> splat_gpu::GpuOutput {
    splat_gpu::render(ctx, scene, trace, camera, method, &frames).unwrap()
}

/// The unbiased methods, with parameters whose rays stay within lavapipe's loop budget on the
/// test scenes (more hits per pass means fewer passes, hence fewer traversals per ray).
pub fn unbiased() -> Vec<(&'static str, Method)> {
    vec![
        ("stochastic", Method::Stochastic),
        ("stochastic-n 2×4", Method::StochasticN { m: 2, n: 4 }),
        ("stochastic-pass", Method::StochasticPass { k: 16, max_passes: 200 }),
    ]
}
