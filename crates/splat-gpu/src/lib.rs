//! `splat-gpu`: wgpu kernels for transparent 3D Gaussians, tested against `splat-core`.
//!
//! Two renderers of the same shape (docs/architecture.md, "Backends"): compiled kernels, a scene
//! on the device, and `render`, which returns the core's [`RenderOutput`] plus [`GpuStats`]:
//!
//! - [`GpuTracer`] ([`trace`]): compute ray tracing of every method of
//!   [`splat_core::trace`], through the BVH the core builds;
//! - [`GpuRasterizer`] ([`raster`]): sorted splatting and StochasticSplats in a render
//!   pipeline, with the GPU radix [`sort`].
//!
//! For interactive viewers, [`ProgressiveTrace`] keeps a ray-traced view's accumulation on the
//! device between steps and draws it into the caller's texture ([`display`]), and
//! [`GpuContext::from_device`] runs the kernels on a device the caller made (a window's).
//!
//! Each backend decides in one place which methods it runs ([`GpuTracer::supports`],
//! [`GpuRasterizer::supports`]).

mod accumulate;
pub mod backend;
mod context;
pub mod display;
mod error;
mod layout;
pub mod node;
pub mod progressive;
pub mod raster;
mod reflect;
pub mod sort;
mod split;
mod timing;
pub mod trace;

pub use wgpu;

pub use accumulate::{AccumulationFormat, Accumulator};
pub use backend::{Extras, GpuViewRenderer, render, render_views, supports, supports_meshes};
pub use context::{GpuContext, GpuCounters, quiet_device_select};
pub use display::{DisplayMode, DisplayTransform, PixelState, Rgba8Readback, read_rgba8};
pub use error::{GpuError, Remedy};
pub use layout::{GpuFirstHit, GpuFragment, GpuParticle, Params, PassState, PathParams};
pub use progressive::ProgressiveTrace;
pub use raster::{
    DepthPick, FirstHits, GpuRasterizer, GpuSplat, RasterPipelines, RasterScene, RasterSplit, RasterTimings,
};
pub use sort::RadixSort;
pub use split::{PartBindings, Split};
pub use trace::{
    DISPATCHES_PER_SUBMIT, FRAMES_PER_DISPATCH, GpuTracer, LOOP_BUDGET, MAX_LAYERED_BOUNCES, MethodParams, TRACE_WGSL,
    TracePipeline, TraceSplit,
};

use splat_core::Camera;
use splat_core::frame::RenderOutput;
use std::time::Duration;

/// How a GPU render went, beside its images.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuStats {
    /// Most loop iterations one invocation ran in one dispatch (lavapipe's budget is 65535).
    pub loop_iterations: u32,
    /// The ray tracer's loop iterations a pixel, in its busiest dispatch, averaged over the
    /// pixels: traversal steps and particle visits, a work counter of the kernel itself (one
    /// frame's at one frame a dispatch; 0 for the splatting path).
    pub mean_loop_iterations: f64,
    /// Frames per dispatch the render settled on.
    pub frames_per_dispatch: u32,
    /// Whether rays ran one pass per dispatch (multi-pass methods over lavapipe's loop budget).
    pub pass_per_dispatch: bool,
    /// GPU time of the dispatches (timestamp queries when available, else wall time around
    /// submit and poll).
    pub gpu_time: Duration,
    /// Whether `gpu_time` comes from timestamp queries.
    pub timestamps: bool,
}

/// Images from per-pixel Welford state (mean RGBA, M2 RGB) of `count` frames, and the stats
/// of a render that took `gpu_time`.
pub(crate) fn output(
    camera: &Camera,
    mean: &[f32],
    m2: &[f32],
    count: u32,
    gpu_time: Duration,
    timestamps: bool,
) -> (RenderOutput, GpuStats) {
    let n = f64::from(count);
    let image = |channels, value: &dyn Fn(usize) -> f32| context::rgba_image(camera, channels, value);
    let images = RenderOutput::colour_only(
        image(3, &|i| mean[i]),
        image(3, &|i| if count > 1 { (f64::from(m2[i]) / (n - 1.0)) as f32 } else { 0.0 }),
        image(1, &|i| mean[i - i % 4 + 3]),
    );
    let stats = GpuStats {
        loop_iterations: 0,
        mean_loop_iterations: 0.0,
        frames_per_dispatch: 1,
        pass_per_dispatch: false,
        gpu_time,
        timestamps,
    };
    (images, stats)
}
