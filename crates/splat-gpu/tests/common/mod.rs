//! Shared helpers of the GPU test binaries: the adapter (or the loud skip), the compiled trace
//! kernel, and GPU samplers for the statistical harness of `splat-tests`.
#![allow(dead_code)]

pub use splat_tests::harness::fixture;

use splat_core::Camera;
use splat_core::frame::{Frames, RenderOutput};
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_gpu::{GpuContext, GpuTracer, TracePipeline};
use splat_tests::harness::StatTest;
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

/// The ray-tracing kernel, compiled once per test binary.
pub fn trace_pipeline(ctx: &'static GpuContext) -> &'static TracePipeline {
    static PIPELINE: OnceLock<TracePipeline> = OnceLock::new();
    PIPELINE.get_or_init(|| TracePipeline::new(ctx).expect("the trace kernel compiles"))
}

/// `trace` uploaded for ray tracing on `ctx`.
pub fn tracer<'a>(ctx: &'static GpuContext, trace: &'a TraceScene<'a>) -> GpuTracer<'a> {
    GpuTracer::new(ctx, trace_pipeline(ctx), trace).expect("the scene fits")
}

/// GPU images of `frames` frames of `method`.
pub fn gpu_run(tracer: &GpuTracer, camera: &Camera, method: &Method, frames: Frames) -> RenderOutput {
    tracer.render(camera, method, &frames).expect("GPU render").0
}

/// The statistical test of the GPU `method` against the core's `exact` image.
pub fn gpu_stat<'a>(
    name: impl Into<String>,
    tracer: &'a GpuTracer<'a>,
    trace: &TraceScene,
    camera: &'a Camera,
    method: Method,
) -> StatTest<'a> {
    let exact = render_frames(trace, camera, &Method::Exact, &Frames::default(), &|_| {}).expect("render");
    StatTest::new(name, exact, move |f| gpu_run(tracer, camera, &method, f))
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
