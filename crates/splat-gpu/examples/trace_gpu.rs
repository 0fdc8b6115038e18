//! Trace a scene on the GPU with stochastic any-hit (Algorithm 1 of Sun et al. 2025) and check
//! it against the CPU's exact image:
//!
//! ```sh
//! cargo run --release -p splat-gpu --example trace_gpu -- gpu.png    # WGPU_BACKEND=vulkan etc.
//! ```
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Frames, RenderSettings, scenes, stats::rmse};
use splat_gpu::{GpuContext, GpuTracer, TracePipeline};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // SAFETY: the first statement of main, before any thread starts.
    #[allow(unsafe_code)]
    unsafe {
        splat_gpu::quiet_device_select()
    };
    let output = std::env::args().nth(1).unwrap_or_else(|| "trace_gpu.png".into());
    let (scene, camera) = scenes::cloud();
    let camera = camera.rescaled(64, 48)?;
    let trace = TraceScene::new(&scene, RenderSettings::default())?;
    let ctx = GpuContext::new()?; // a typed error naming what to install when there is no adapter
    let pipeline = TracePipeline::new(&ctx)?;
    let tracer = GpuTracer::new(&ctx, &pipeline, &trace)?;
    let frames = Frames { count: 64, seed: 1, ..Frames::default() };
    let (out, _stats) = tracer.render(&camera, &Method::Stochastic, &frames)?;
    let exact = render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {})?;
    let error = rmse(out.mean.data(), exact.mean.data());
    println!("{}: 64 frames of stochastic any-hit, RMSE {error:.4} against the CPU's exact image", ctx.describe());
    splat_io::image::write_image(output.as_ref(), &out.mean)?;
    Ok(())
}
