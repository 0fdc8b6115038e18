//! The Monte Carlo path tracer (docs/architecture.md, "The path tracer"): furnace tests of its
//! light transport, and two unbiased estimators of the same image that must agree — Algorithm 1
//! at every segment (and its N-samples extension) against exact compositing of every Gaussian
//! hit at every segment — with biased controls the test rejects; convergence at the Monte Carlo
//! rate, Sobol runs that average to the same image, and one image whatever the thread count.

use glam::Vec3;
use splat_core::camera_sampling::{CameraSampling, ThinLens};
use splat_core::frame::RenderOutput;
use splat_core::lighting::{Light, LightKind, Lighting, Material, Shadows};
use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
use splat_core::path::sampler::SamplerKind;
use splat_core::path::{Environment, GaussianEstimator, PathSettings, PathTracer};
use splat_core::stats::{ZTest, log_log_slope, rmse};
use splat_core::trace::TraceScene;
use splat_core::{Camera, Frames, RenderSettings, Scene};
use splat_tests::path_worlds::{glass_world, lambert, lit_world, trace_scene};
use splat_tests::placed;

/// The injected error of the acceptance controls: each decision u < α + 0.02.
const BIASED: f32 = 0.02;

fn quad(center: Vec3, normal: Vec3, half: f32) -> TriangleMesh {
    placed(TriangleMesh::plane(), half, normal, center)
}

fn sphere(center: Vec3, radius: f32) -> TriangleMesh {
    placed(TriangleMesh::sphere(32, 16), radius, Vec3::Y, center)
}

fn render(trace: &TraceScene, camera: &Camera, settings: PathSettings, frames: Frames) -> RenderOutput {
    PathTracer::new(trace, settings).unwrap().render(camera, &frames, &|_| {}).unwrap()
}

fn hash_frames(count: u32, seed: u32) -> Frames {
    Frames { count, seed, ..Frames::default() }
}

/// The z-test of a mean image against a constant, with the variance of an independent run.
fn z_against_constant(mean: &RenderOutput, variance: &RenderOutput, value: f32, frames: u32) -> ZTest {
    let expected = vec![value; mean.mean.data().len()];
    ZTest::new(mean.mean.data(), &expected, variance.variance.data(), frames, 3)
}

/// A closed room: inside a cube of albedo ρ emitting Lₑ (both sides), every path sees
/// L = Lₑ / (1 − ρ) (the Neumann series Σ ρᵏ Lₑ). Paths meet emission both by BSDF sampling and
/// by emitter sampling, so the multiple importance sampling weights must sum to one. (Flat
/// faces: interpolated shading normals do not conserve energy, and a smooth sphere room loses
/// 0.13 % of its light, which 16,384 frames detect.)
fn closed_room(albedo: f32) -> (Meshes, Camera) {
    room(room_walls(0.5, albedo))
}

/// Walls that emit `emitted` and scatter with Lambertian albedo `albedo`.
fn room_walls(emitted: f32, albedo: f32) -> MeshMaterial {
    MeshMaterial {
        color: Vec3::ONE,
        shading: Material {
            emissive: Vec3::splat(emitted),
            ambient: Vec3::ZERO,
            diffuse: Vec3::splat(albedo),
            ..Material::DIFFUSE
        },
        ..MeshMaterial::default()
    }
}

/// A cube room of half-width 3 with walls of `material`, and a camera inside it.
fn room(material: MeshMaterial) -> (Meshes, Camera) {
    let meshes = Meshes::new(&[(placed(TriangleMesh::cube(), 3.0, Vec3::Y, Vec3::ZERO), material)]).unwrap();
    let camera = Camera::look_at(Vec3::new(0.3, 0.2, 1.0), Vec3::new(0.0, -0.5, -1.0), Vec3::Y, 70.0, 16, 12).unwrap();
    (meshes, camera)
}

#[test]
fn a_closed_emitting_room_returns_le_over_one_minus_albedo() {
    let scene = Scene::default();
    let settings =
        PathSettings { max_depth: 40, roulette_depth: 2, sampler: SamplerKind::Hash, ..PathSettings::default() };
    let frames = 2048;
    let z_for = |albedo: f32| {
        let (meshes, camera) = closed_room(albedo);
        let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap().with_meshes(meshes);
        let a = render(&trace, &camera, settings, hash_frames(frames, 1));
        let b = render(&trace, &camera, settings, hash_frames(frames, 2));
        z_against_constant(&a, &b, 1.0, frames)
    };
    let z = z_for(0.5);
    assert!(z.passes(), "the room (Lₑ 0.5, ρ 0.5) is not 1: {z:?}");
    // ρ = 0.51 makes the room 0.5 / 0.49 = 1.0204: a 2 % error.
    let control = z_for(0.51);
    eprintln!("closed room: {z:?}; ρ 0.51: {control:?}");
    assert!(!control.passes(), "a 2 % brighter room passes: {control:?}");
}

/// A room of transparent walls: inside a cube whose walls have opacity α, emit Lₑ (both sides)
/// and scatter with albedo ρ, under a constant environment E, a ray stops at a wall with
/// probability α (Lₑ plus ρ times the room's radiance) and otherwise leaves the convex room for
/// the environment, so every path sees L = (α Lₑ + (1 − α) E) / (1 − α ρ). The walls are found
/// both by BSDF sampling and by emitter sampling, whose samples must carry α Lₑ for the weights
/// to add up. An acceptance error of 0.01 (α 0.51 for 0.5: L 1.5 % brighter) is rejected.
#[test]
fn a_room_of_transparent_walls_balances_its_layers() {
    let scene = Scene::default();
    let (alpha, emitted, albedo, environment) = (0.5, 0.5, 0.5, 0.2);
    let (meshes, camera) = room(MeshMaterial { opacity: alpha, ..room_walls(emitted, albedo) });
    let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap().with_meshes(meshes);
    let settings = PathSettings {
        max_depth: 40,
        roulette_depth: 2,
        sampler: SamplerKind::Hash,
        environment: Environment::Constant(Vec3::splat(environment)),
        ..PathSettings::default()
    };
    let expected = (alpha * emitted + (1.0 - alpha) * environment) / (1.0 - alpha * albedo);
    let frames = 2048;
    let z_for = |u_shift: f32| {
        let run = |seed: u32| render(&trace, &camera, settings, Frames { u_shift, ..hash_frames(frames, seed) });
        z_against_constant(&run(1), &run(2), expected, frames)
    };
    let z = z_for(0.0);
    assert!(z.passes(), "the transparent room is not {expected}: {z:?}");
    let control = z_for(0.01);
    eprintln!("transparent room ({expected}): {z:?}; u < α + 0.01: {control:?}");
    assert!(!control.passes(), "an acceptance error of 0.01 passes: {control:?}");
}

/// The white furnace: a convex albedo-1 Lambertian sphere, a cube and a smooth glass sphere under
/// a uniform environment vanish (every pixel is the environment), since none absorbs.
#[test]
fn the_white_furnace_hides_lossless_surfaces() {
    let scene = Scene::default();
    let camera = Camera::look_at(Vec3::new(0.0, 0.3, 3.2), Vec3::new(0.0, 0.0, 0.0), Vec3::Y, 40.0, 24, 18).unwrap();
    let world = |albedo: f32| {
        let cube = placed(TriangleMesh::cube(), 0.4, Vec3::Y, Vec3::new(0.9, 0.0, -0.5));
        let glass = MeshMaterial { transmission: 1.0, ior: 1.5, ..MeshMaterial::default() };
        Meshes::new(&[
            (sphere(Vec3::new(-0.6, 0.0, 0.0), 0.7), lambert(Vec3::splat(albedo))),
            (cube, lambert(Vec3::splat(albedo))),
            (sphere(Vec3::new(0.3, -0.2, 1.2), 0.45), glass),
        ])
        .unwrap()
    };
    let settings = PathSettings {
        max_depth: 64,
        roulette_depth: 1,
        sampler: SamplerKind::Hash,
        environment: Environment::Constant(Vec3::ONE),
        ..PathSettings::default()
    };
    let frames = 2048;
    let z_for = |albedo: f32| {
        let trace = TraceScene::new(&scene, RenderSettings::default()).unwrap().with_meshes(world(albedo));
        let a = render(&trace, &camera, settings, hash_frames(frames, 1));
        let b = render(&trace, &camera, settings, hash_frames(frames, 2));
        z_against_constant(&a, &b, 1.0, frames)
    };
    let z = z_for(1.0);
    assert!(z.passes(), "the furnace is not uniform: {z:?}");
    let control = z_for(0.98);
    eprintln!("white furnace: {z:?}; albedo 0.98: {control:?}");
    assert!(!control.passes(), "albedo 0.98 passes the furnace: {control:?}");
}

fn world_settings(gaussians: GaussianEstimator) -> PathSettings {
    PathSettings {
        gaussians,
        sampler: SamplerKind::Hash,
        max_depth: 6,
        environment: Environment::Gradient {
            horizon: Vec3::new(0.35, 0.3, 0.25),
            zenith: Vec3::new(0.2, 0.3, 0.5),
            up: Vec3::Y,
        },
        ..PathSettings::default()
    }
}

/// Two independent runs (mean and variance) of one estimator.
struct Runs {
    mean: RenderOutput,
    variance: RenderOutput,
}

/// Seeds differ between the estimators compared, so that their means are independent (the same
/// seed would share pixel positions and light and BSDF samples, and the difference would vary
/// less than the variances say).
fn runs(trace: &TraceScene, camera: &Camera, settings: PathSettings, frames: u32, u_shift: f32, seed: u32) -> Runs {
    let run = |seed: u32| render(trace, camera, settings, Frames { u_shift, ..hash_frames(frames, seed) });
    Runs { mean: run(seed), variance: run(seed + 1) }
}

/// The two-sample per-pixel z-test: se² = (var_a + var_b) / F, each variance from a run
/// independent of both means.
fn two_sample(a: &Runs, b: &Runs, frames: u32) -> ZTest {
    let var: Vec<f32> = a.variance.variance.data().iter().zip(b.variance.variance.data()).map(|(x, y)| x + y).collect();
    ZTest::new(a.mean.mean.data(), b.mean.mean.data(), &var, frames, 3)
}

/// Stochastic and stochastic-n agree with exact compositing at every segment; depth sampling at
/// secondary segments and a 2 % acceptance error are rejected.
#[test]
fn gaussians_inside_the_path_tracer_are_unbiased() {
    let frames = 512;
    for (name, world) in [("lit layers", lit_world()), ("glass", glass_world())] {
        let (trace, camera) = (trace_scene(&world), &world.1);
        let exact = runs(&trace, camera, world_settings(GaussianEstimator::Exact), frames, 0.0, 100);
        let stochastic = world_settings(GaussianEstimator::Stochastic);
        for (label, settings) in
            [("stochastic", stochastic), ("stochastic-n 4", world_settings(GaussianEstimator::StochasticN { n: 4 }))]
        {
            let z = two_sample(&runs(&trace, camera, settings, frames, 0.0, 200), &exact, frames);
            eprintln!("{name}, {label}: {z:?}");
            assert!(z.passes(), "{name}: {label} differs from exact compositing: {z:?}");
        }
        let depth = world_settings(GaussianEstimator::DepthSampling { k: 1 });
        let z = two_sample(&runs(&trace, camera, depth, frames, 0.0, 300), &exact, frames);
        eprintln!("{name}, depth sampling at secondary segments: {z:?}");
        assert!(!z.passes(), "{name}: depth sampling at secondary segments passes: {z:?}");
        let z = two_sample(&runs(&trace, camera, stochastic, frames, BIASED, 400), &exact, frames);
        eprintln!("{name}, u < α + {BIASED}: {z:?}");
        assert!(!z.passes(), "{name}: a 2 % acceptance error passes: {z:?}");
    }
}

/// The RMSE of Algorithm 1 inside the path tracer against a long exact-compositing render falls
/// as spp^−½ (the slope of log RMSE against log spp, over 16 … 256 frames, four seeds each).
#[test]
fn the_stochastic_path_tracer_converges_at_the_monte_carlo_rate() {
    let world = lit_world();
    let trace = trace_scene(&world);
    let camera = &world.1;
    let reference = render(&trace, camera, world_settings(GaussianEstimator::Exact), hash_frames(8192, 77));
    let spp = [16u32, 32, 64, 128, 256];
    let errors: Vec<f64> = spp
        .iter()
        .map(|&n| {
            let settings = world_settings(GaussianEstimator::Stochastic);
            let e: f64 = (0..4)
                .map(|seed| {
                    rmse(
                        render(&trace, camera, settings, hash_frames(n, 1000 + seed)).mean.data(),
                        reference.mean.data(),
                    )
                    .powi(2)
                })
                .sum();
            (e / 4.0).sqrt()
        })
        .collect();
    let x: Vec<f64> = spp.iter().map(|&n| f64::from(n)).collect();
    let slope = log_log_slope(&x, &errors);
    eprintln!("RMSE by spp {spp:?}: {errors:?}; slope {slope:.3}");
    assert!((-0.6..=-0.4).contains(&slope), "slope {slope} is not −0.5");
}

/// Sobol runs are unbiased: the mean of 64 independent Owen-scrambled runs of 16 samples agrees
/// with a long exact-compositing render (se from the spread of the run means and the
/// reference's variance), and the same runs with the 2 % acceptance error are rejected. Over
/// the same samples per pixel, Sobol has the smaller RMSE.
#[test]
fn sobol_paths_are_unbiased_and_converge_faster_than_hashed_ones() {
    let world = lit_world();
    let trace = trace_scene(&world);
    let camera = &world.1;
    let ref_frames = 8192;
    let reference = render(&trace, camera, world_settings(GaussianEstimator::Exact), hash_frames(ref_frames, 5));
    let (runs, spp) = (64u32, 16u32);
    let sobol = PathSettings { sampler: SamplerKind::Sobol, ..world_settings(GaussianEstimator::Stochastic) };
    let z_for = |u_shift: f32| {
        let means: Vec<RenderOutput> =
            (0..runs).map(|seed| render(&trace, camera, sobol, Frames { u_shift, ..hash_frames(spp, seed) })).collect();
        let n = reference.mean.data().len();
        let (mut mean, mut var) = (vec![0.0f32; n], vec![0.0f32; n]);
        for i in 0..n {
            let mut w = splat_core::stats::Welford::default();
            means.iter().for_each(|m| w.push(f64::from(m.mean.data()[i])));
            mean[i] = w.mean as f32;
            // se² = var(run means) / runs + var(reference frames) / ref_frames.
            var[i] = (w.variance() + f64::from(reference.variance.data()[i]) * f64::from(runs) / f64::from(ref_frames))
                as f32;
        }
        (ZTest::new(&mean, reference.mean.data(), &var, runs, 3), means)
    };
    let (z, sobol_runs) = z_for(0.0);
    assert!(z.passes(), "Sobol runs differ from exact compositing: {z:?}");
    let (control, _) = z_for(BIASED);
    eprintln!("Sobol: {z:?}; u < α + {BIASED}: {control:?}");
    assert!(!control.passes(), "a 2 % acceptance error passes with Sobol: {control:?}");
    let hash = world_settings(GaussianEstimator::Stochastic);
    let rmse_of = |outs: &[RenderOutput]| {
        (outs.iter().map(|o| rmse(o.mean.data(), reference.mean.data()).powi(2)).sum::<f64>() / outs.len() as f64)
            .sqrt()
    };
    let hash_runs: Vec<RenderOutput> =
        (0..runs).map(|seed| render(&trace, camera, hash, hash_frames(spp, 500 + seed))).collect();
    let (s, h) = (rmse_of(&sobol_runs), rmse_of(&hash_runs));
    eprintln!("RMSE at {spp} spp: Sobol {s:.5}, hash {h:.5} ({:.2}×)", h / s);
    assert!(s < h, "Sobol ({s}) is not better than the hash ({h})");
}

/// The same seed gives the same image bit for bit on one thread and on two, with a thin lens.
#[test]
fn path_traced_images_do_not_depend_on_the_thread_count() {
    let world = glass_world();
    let lens = Some(ThinLens { aperture: 0.08, focus_distance: 3.0 });
    let trace = splat_tests::path_worlds::trace_scene_with(
        &world,
        RenderSettings { sampling: CameraSampling { lens, ..Default::default() }, ..Default::default() },
    );
    let settings = world_settings(GaussianEstimator::StochasticN { n: 3 });
    let frames = Frames { count: 16, seed: 3, ..Frames::default() };
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render(&trace, &world.1, PathSettings { sampler: SamplerKind::Sobol, ..settings }, frames))
    };
    let (one, two) = (on(1), on(2));
    assert_eq!(one.mean.data(), two.mean.data());
    assert_ne!(one.mean.data(), render(&trace, &world.1, settings, Frames { seed: 4, ..frames }).mean.data());
}

/// A Gaussian inside the path tracer is lit exactly as the ray tracer lights it: with every hit
/// composited (exact), no meshes and a hard point light, a path through a pixel centre is the
/// ray tracer's exact volumetric sample with exact shadows (Σ Tᵢ αᵢ Lit(xᵢ) + T · background).
#[test]
fn gaussians_are_lit_as_the_ray_tracer_lights_them() {
    use splat_core::lighting::Look;
    use splat_core::path::sampler::PathSampler;
    use splat_core::trace::{Method, render_frames};
    let (scene, camera, _, lighting) = lit_world();
    let lighting = Lighting { look: Look::Volumetric, shadows: Shadows::Exact, ..lighting };
    let background = Vec3::new(0.1, 0.2, 0.3);
    let settings = RenderSettings { background, ..RenderSettings::default() };
    let trace = TraceScene::new(&scene, settings).unwrap().with_lighting(lighting).unwrap();
    let rt = render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap();
    let path_settings = PathSettings {
        gaussians: GaussianEstimator::Exact,
        environment: Environment::Constant(background),
        ..PathSettings::default()
    };
    let tracer = PathTracer::new(&trace, path_settings).unwrap();
    let mut worst = 0.0f32;
    for y in 0..camera.height {
        for x in 0..camera.width {
            let s = PathSampler::new(SamplerKind::Hash, x, y, 0, 0);
            let l = tracer.radiance(trace.clip(camera.pixel_ray(x, y)), &s);
            let expected = Vec3::from_slice(rt.mean.pixel(x, y));
            worst = worst.max((l - expected).abs().max_element());
        }
    }
    assert!(worst < 1e-5, "the path tracer's lit Gaussians differ from the ray tracer's by {worst}");
}

/// Next-event estimation of a point light on a Lambertian floor, by hand: one bounce, no
/// randomness left, L = ρ/π · I cos θ / d².
#[test]
fn a_point_light_on_a_lambertian_floor_by_hand() {
    let scene = Scene::default();
    let albedo = 0.6;
    let meshes = Meshes::new(&[(quad(Vec3::ZERO, Vec3::Y, 10.0), lambert(Vec3::splat(albedo)))]).unwrap();
    let position = Vec3::new(0.3, 2.0, -0.4);
    let light = Light { kind: LightKind::Point { position }, color: Vec3::ONE, intensity: 5.0, radius: 0.0 };
    let lighting = Lighting::single(Material::EMISSIVE, vec![light], Shadows::Stochastic);
    let trace = TraceScene::new(&scene, RenderSettings::default())
        .unwrap()
        .with_lighting(lighting)
        .unwrap()
        .with_meshes(meshes);
    let tracer = PathTracer::new(&trace, PathSettings { max_depth: 1, ..PathSettings::default() }).unwrap();
    let s = splat_core::path::sampler::PathSampler::new(SamplerKind::Sobol, 0, 0, 0, 0);
    for target in [Vec3::ZERO, Vec3::new(1.5, 0.0, 0.7), Vec3::new(-2.0, 0.0, -3.0)] {
        let eye = Vec3::new(0.0, 1.0, 4.0);
        let ray = trace.clip(splat_core::Ray::new(eye, (target - eye).normalize()));
        let to_light = position - target;
        let d2 = to_light.length_squared();
        let expected = albedo / std::f32::consts::PI * 5.0 * (to_light.y / d2.sqrt()) / d2;
        let l = tracer.radiance(ray, &s);
        assert!((l.x - expected).abs() < 1e-5 * expected.max(1.0), "{target}: {l} vs {expected}");
    }
}
