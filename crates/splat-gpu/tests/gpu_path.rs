//! The path tracer on the GPU (`shaders/path.wgsl`) against the core's
//! (`splat_core::path::PathTracer`): the same seed gives the same paths, frame for frame, with
//! every Gaussian estimator and both samplers.

mod common;

use common::{context, tracer};
use splat_core::camera_sampling::{CameraSampling, ThinLens};
use splat_core::frame::{Frames, RenderOutput};
use splat_core::path::sampler::SamplerKind;
use splat_core::path::{Environment, GaussianEstimator, PathSettings, PathTracer};
use splat_gpu::GpuError;
use splat_tests::path_worlds::{glass_world, lit_world, trace_scene, trace_scene_with, veiled_world};

fn settings(gaussians: GaussianEstimator, sampler: SamplerKind) -> PathSettings {
    PathSettings {
        gaussians,
        sampler,
        max_depth: 5,
        environment: Environment::Gradient {
            horizon: glam::Vec3::new(0.35, 0.3, 0.25),
            zenith: glam::Vec3::new(0.2, 0.3, 0.5),
            up: glam::Vec3::Y,
        },
        ..PathSettings::default()
    }
}

/// Pixels whose colour differs by more than 10⁻³, and the mean absolute difference.
fn differences(a: &RenderOutput, b: &RenderOutput) -> (usize, f64) {
    let pixels = a.mean.data().chunks(3).zip(b.mean.data().chunks(3));
    let worst: Vec<f32> =
        pixels.map(|(p, q)| p.iter().zip(q).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max)).collect();
    let mean = a.mean.data().iter().zip(b.mean.data()).map(|(x, y)| f64::from((x - y).abs())).sum::<f64>()
        / a.mean.data().len() as f64;
    (worst.iter().filter(|&&w| w.is_nan() || w > 1e-3).count(), mean)
}

/// Four frames of each estimator and sampler on three worlds (the third with transparent
/// meshes): the GPU's paths are the CPU's.
/// A path may part where a decision falls within f32 rounding of its threshold (a BSDF
/// direction a few ulps apart meets a different Gaussian or triangle edge); at most 2 % of the
/// pixels may differ, and the mean difference stays below 10⁻³.
#[test]
fn gpu_paths_are_the_cpu_paths() {
    let Some(ctx) = context() else { return };
    for (name, world) in [("lit layers", lit_world()), ("glass", glass_world()), ("veiled", veiled_world())] {
        // Through a thin lens: the settings' lens is the path tracer's.
        let lens = Some(ThinLens { aperture: 0.03, focus_distance: 3.0 });
        let with_lens = splat_core::RenderSettings {
            sampling: CameraSampling { lens, ..Default::default() },
            ..Default::default()
        };
        let (trace, camera) = (trace_scene_with(&world, with_lens), &world.1);
        let gpu = tracer(ctx, &trace);
        for sampler in [SamplerKind::Sobol, SamplerKind::Hash] {
            for gaussians in
                [GaussianEstimator::Stochastic, GaussianEstimator::StochasticN { n: 3 }, GaussianEstimator::Exact]
            {
                let s = settings(gaussians, sampler);
                let frames = Frames { count: 4, seed: 9, ..Frames::default() };
                let cpu = PathTracer::new(&trace, s).unwrap().render(camera, &frames, &|_| {}).unwrap();
                let out = gpu.render_path(camera, &s, &frames).expect("GPU path render").0;
                let (differ, mean) = differences(&cpu, &out);
                let share = differ as f64 / f64::from(camera.width * camera.height);
                eprintln!("{name}, {gaussians:?}, {sampler:?}: {differ} pixels differ, mean |Δ| {mean:.2e}");
                assert!(share <= 0.02 && mean < 1e-3, "{name} {gaussians:?} {sampler:?}: {differ} pixels, mean {mean}");
            }
        }
    }
}

/// What the kernel does not run is refused with the reason.
#[test]
fn depth_sampling_stays_on_the_cpu() {
    let Some(ctx) = context() else { return };
    let world = lit_world();
    let trace = trace_scene(&world);
    let gpu = tracer(ctx, &trace);
    let s = settings(GaussianEstimator::DepthSampling { k: 2 }, SamplerKind::Hash);
    match gpu.render_path(&world.1, &s, &Frames::default()) {
        Err(e @ GpuError::Refused { .. }) => {
            assert!(e.to_string().contains("CPU only") && e.remedies() == [splat_gpu::Remedy::Cpu], "{e}")
        }
        other => panic!("depth sampling was not refused: {:?}", other.map(|_| ())),
    }
}
