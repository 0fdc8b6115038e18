//! Shared helpers of the GPU test binaries: the adapter (or the loud skip), the compiled trace
//! kernel, and GPU samplers for the statistical harness of `splat-tests`.
#![allow(dead_code)]

#[allow(unused_imports)] // not every test binary uses every helper
pub use splat_tests::harness::fixture;

use glam::Vec3;
use splat_core::frame::{Frames, RenderOutput};
use splat_core::lighting::{Light, LightKind, Lighting, Look, Material, Shadows};
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, RenderSettings, Scene};
use splat_gpu::{GpuContext, GpuTracer, PartBindings, TracePipeline};
use splat_tests::harness::{FAULTS, StatTest, assert_power, full_power_study};
use std::sync::OnceLock;

/// The shared context; `None` when there is no adapter, the test recorded as skipped
/// ([`splat_tests::skip`]), except under `CI=true`, where a missing adapter fails the test.
pub fn context() -> Option<&'static GpuContext> {
    static CTX: OnceLock<Result<GpuContext, String>> = OnceLock::new();
    match CTX.get_or_init(|| GpuContext::new().map_err(|e| e.to_string())) {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            splat_tests::skip(&splat_tests::current_test(), &format!("no GPU adapter ({e})"));
            None
        }
    }
}

/// Contexts that bind split arrays' parts each way this machine can test, made by `limits`
/// from a fresh context (binding limits small enough to split a fixture): as binding arrays
/// (`PartBindings::Array`) where the adapter has them, and one binding each
/// (`PartBindings::Each`, every adapter). An adapter without binding arrays is recorded as a
/// skip of that half ([`splat_tests::skip`]: a failure under `CI=true`, whose lavapipe has them).
pub fn part_binding_contexts(limits: impl Fn(GpuContext) -> GpuContext) -> Vec<(PartBindings, GpuContext)> {
    let arrays = limits(GpuContext::new().unwrap());
    let each = (PartBindings::Each, limits(GpuContext::new().unwrap()).with_binding_array_elements(0));
    if arrays.binding_array_elements_per_stage() == 0 {
        let reason = format!(
            "{} has no binding arrays of storage buffers: split arrays tested one binding a part only",
            arrays.describe()
        );
        splat_tests::skip(&splat_tests::current_test(), &reason);
        return vec![each];
    }
    vec![(PartBindings::Array, arrays), each]
}

/// The ray-tracing kernels, each compiled once per test binary (on the first tracer of its split).
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

/// Frames of the mean run of the GPU z-tests (the variance run has 4×): the CPU suites'
/// budget.
pub const F: u32 = 256;

/// The GPU z-tests of one fixture: every unbiased method passes, `depth-sampling-1` is
/// rejected, and the power study (docs/power.md) of every unbiased method with `all_methods`
/// or in the full study ([`full_power_study`]), else of `stochastic` alone (on lavapipe the full
/// study's test takes 204 s on the cloud and 245 s on the bonsai crop, 114 s on `layers`:
/// `cargo xtask power` at 699d157).
pub fn z_tests_and_power(
    ctx: &'static GpuContext,
    fixture_name: &str,
    scene: &Scene,
    camera: &Camera,
    all_methods: bool,
) {
    let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
    let gpu = tracer(ctx, &trace);
    let base = Frames { count: F, seed: 21, ..Frames::default() };
    for (name, method) in unbiased() {
        gpu_stat(format!("GPU {fixture_name} {name}"), &gpu, &trace, camera, method).assert_unbiased(base);
    }
    let control = Method::DepthSampling { k: 1 };
    gpu_stat(format!("GPU {fixture_name} depth-sampling-1"), &gpu, &trace, camera, control).assert_rejected(base);
    let exact = |trace: &TraceScene| render_frames(trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    let oracle = exact(&trace);
    let methods = if all_methods || full_power_study() { unbiased() } else { vec![("stochastic", Method::Stochastic)] };
    for (name, method) in methods {
        assert_power(&format!("gpu-ray {fixture_name} {name}"), &FAULTS, |fault| {
            let faulty = fault.scene(scene);
            let faulty = TraceScene::new(&faulty, RenderSettings::default()).unwrap();
            let gpu = tracer(ctx, &faulty);
            let test = StatTest::new(name, oracle.clone(), |f| gpu_run(&gpu, camera, &method, f));
            test.z_test_with_expectation(fault.frames(base), &exact(&faulty))
        });
    }
}

/// The lit world of the GPU tests on the fixtures: every material term, a soft spot light (its
/// samples drawn per pixel and frame) and a directional light, with the given shadows and look.
pub fn lighting(shadows: Shadows, look: Look) -> Lighting {
    let material = Material {
        emissive: Vec3::splat(0.05),
        ambient: Vec3::splat(0.1),
        diffuse: Vec3::new(0.9, 0.8, 0.7),
        specular: Vec3::splat(0.3),
        shininess: 16.0,
    };
    let lights = vec![
        Light {
            kind: LightKind::Spot {
                position: Vec3::new(1.5, 1.5, 2.5),
                direction: Vec3::new(-1.5, -1.5, -2.5).normalize(),
                inner_deg: 15.0,
                outer_deg: 30.0,
            },
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 8.0,
            radius: 0.1,
        },
        Light {
            kind: LightKind::Directional { direction: Vec3::new(0.4, -0.6, -1.0).normalize() },
            color: Vec3::new(0.4, 0.5, 1.0),
            intensity: 0.6,
            radius: 0.0,
        },
    ];
    Lighting { look, shadow_offset: 0.02, ..Lighting::single(material, lights, shadows) }
}
