//! Golden images: what `cargo xtask bless` renders and the golden test compares.

use splat_core::raster::{Blend, RasterMethod, RasterSettings};
use splat_core::trace::Method;
use splat_core::{Algorithm, Frames, RenderSettings};

/// Fixtures with golden images.
pub const FIXTURES: [&str; 3] = ["layers", "ramp", "cloud"];
/// Fixtures of the stratification report (`splat stratify`), rendered with kernel degree
/// [`splat_core::scenes::PLATE_KERNEL_DEGREE`].
pub const STRATIFICATION_FIXTURES: [&str; 2] = ["plates", "cloth"];

/// The methods rendered for every fixture: (file suffix, case, frames), stochastic ones
/// with seed 1.
pub fn cases() -> Vec<(&'static str, Algorithm, Frames)> {
    let f = |count| Frames { count, seed: 1, ..Frames::default() };
    let s4 = RasterSettings { samples: 4, ..RasterSettings::default() };
    vec![
        ("oracle", Algorithm::Oracle, f(1)),
        ("kbuffer", Algorithm::Trace(Method::KBUFFER), f(1)),
        ("stochastic", Algorithm::Trace(Method::Stochastic), f(4)),
        ("stochastic-n", Algorithm::Trace(Method::StochasticN { m: 1, n: 4 }), f(1)),
        ("stochastic-pass", Algorithm::Trace(Method::STOCHASTIC_PASS), f(4)),
        ("depth-sampling-k", Algorithm::Trace(Method::DepthSampling { k: 2 }), f(4)),
        (
            "raster-sorted",
            Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Over }, RasterSettings::default()),
            f(1),
        ),
        ("stochastic-splat", Algorithm::Raster(RasterMethod::StochasticSplat, s4), f(2)),
        ("enderton", Algorithm::Raster(RasterMethod::Enderton, s4), f(2)),
        ("stratified", Algorithm::Raster(RasterMethod::Stratified { scramble: true }, s4), f(2)),
    ]
}

/// Render one golden case of one fixture, read through the file formats, as 8-bit RGB.
pub fn render(fixture: &str, algorithm: &Algorithm, frames: &Frames) -> image::RgbImage {
    let dir = super::root().join("fixtures");
    let scene = splat_io::ply::read_ply(&dir.join(format!("{fixture}.ply"))).expect("fixture");
    let camera = splat_io::cameras::read_cameras(&dir.join(format!("{fixture}.cameras.json"))).expect("camera")[0];
    let out = algorithm.render(&scene, &camera, &RenderSettings::default(), frames, &|_| {}).expect("render");
    splat_io::image::to_rgba8(&out.mean).to_rgb8()
}

/// Path of a golden image.
pub fn path(fixture: &str, suffix: &str) -> std::path::PathBuf {
    super::root().join("fixtures/golden").join(format!("{fixture}-{suffix}.png"))
}

/// The lit world of the golden images: the built-in demo under a spot light with soft
/// stochastic shadows on its floor, and a fill light.
pub const LIT_WORLD: &str = "fixtures/worlds/demo-lit.toml";

/// The lit cases: each family's look (surface, volumetric samples, the pass) on the lit
/// world at 160 × 120, seed 1 (the shadows and the area light draw even for `exact`).
pub fn lit_cases() -> Vec<(&'static str, Algorithm, Frames)> {
    let f = |count| Frames { count, seed: 1, ..Frames::default() };
    let s4 = RasterSettings { samples: 4, ..RasterSettings::default() };
    vec![
        ("exact", Algorithm::Trace(Method::Exact), f(4)),
        ("stochastic", Algorithm::Trace(Method::Stochastic), f(4)),
        ("stochastic-pass", Algorithm::Trace(Method::STOCHASTIC_PASS), f(4)),
        ("raster-sorted", Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Under }, s4), f(1)),
        ("stochastic-splat", Algorithm::Raster(RasterMethod::StochasticSplat, s4), f(2)),
    ]
}

/// The world of the mesh golden images: the lit demo on a pedestal, with a mirror and a
/// glass sphere.
pub const MESH_WORLD: &str = "fixtures/worlds/demo-meshes.toml";

/// The mesh cases: each pipeline (rt, raster, hybrid) on [`MESH_WORLD`] at 160 × 120, seed 1.
pub fn mesh_cases() -> Vec<(&'static str, Algorithm, Frames)> {
    let f = |count| Frames { count, seed: 1, ..Frames::default() };
    let s4 = RasterSettings { samples: 4, ..RasterSettings::default() };
    let under = RasterMethod::Sorted { blend: Blend::Under };
    vec![
        ("rt-exact", Algorithm::Trace(Method::Exact), f(4)),
        ("rt-stochastic", Algorithm::Trace(Method::Stochastic), f(4)),
        ("raster-sorted", Algorithm::Raster(under, s4), f(1)),
        ("raster-stochastic-splat", Algorithm::Raster(RasterMethod::StochasticSplat, s4), f(2)),
        ("hybrid", Algorithm::Hybrid(under, s4, Method::Exact), f(4)),
    ]
}

/// Render one case of [`MESH_WORLD`] as 8-bit RGB.
pub fn render_meshes(algorithm: &Algorithm, frames: &Frames) -> image::RgbImage {
    let world = splat_io::world::read_world(&super::root().join(MESH_WORLD)).expect("the mesh world");
    let camera = world.camera.expect("the world's camera").rescaled(160, 120).expect("a valid size");
    let meshes = splat_core::mesh::Meshes::new(&world.meshes).expect("valid meshes");
    let settings = RenderSettings {
        background: world.background.unwrap_or_default(),
        max_bounces: world.max_bounces.unwrap_or(splat_core::settings::DEFAULT_MAX_BOUNCES),
        ..RenderSettings::default()
    };
    let out = algorithm
        .render_world(
            &splat_core::Shot {
                scene: &world.scene,
                meshes: &meshes,
                lighting: &world.lighting,
                camera: &camera,
                settings: &settings,
            },
            frames,
            &|_| {},
        )
        .expect("render");
    splat_io::image::to_rgba8(&out.mean).to_rgb8()
}

/// The path-tracer cases: the Gaussian estimators inside the path tracer on [`MESH_WORLD`]
/// at 160 × 120, 16 Sobol samples per pixel, seed 1.
pub fn path_cases() -> Vec<(&'static str, splat_core::path::GaussianEstimator, Frames)> {
    use splat_core::path::GaussianEstimator;
    let f = Frames { count: 16, seed: 1, ..Frames::default() };
    vec![
        ("path-stochastic", GaussianEstimator::Stochastic, f),
        ("path-stochastic-n", GaussianEstimator::StochasticN { n: 4 }, f),
        ("path-exact", GaussianEstimator::Exact, f),
    ]
}

/// Render one path-tracer case of [`MESH_WORLD`] as 8-bit RGB (the environment is the
/// world's background).
pub fn render_path(gaussians: splat_core::path::GaussianEstimator, frames: &Frames) -> image::RgbImage {
    use splat_core::path::{Environment, PathSettings, PathTracer};
    let world = splat_io::world::read_world(&super::root().join(MESH_WORLD)).expect("the mesh world");
    let camera = world.camera.expect("the world's camera").rescaled(160, 120).expect("a valid size");
    let meshes = splat_core::mesh::Meshes::new(&world.meshes).expect("valid meshes");
    let trace = splat_core::trace::TraceScene::new(&world.scene, RenderSettings::default())
        .and_then(|t| t.with_lighting(world.lighting.clone()))
        .expect("a valid world")
        .with_meshes(meshes);
    let environment = Environment::Constant(world.background.unwrap_or_default());
    let settings = PathSettings { gaussians, environment, ..PathSettings::default() };
    let out = PathTracer::new(&trace, settings).and_then(|p| p.render(&camera, frames, &|_| {})).expect("render");
    splat_io::image::to_rgba8(&out.mean).to_rgb8()
}

/// Render one lit case of [`LIT_WORLD`] as 8-bit RGB.
pub fn render_lit(algorithm: &Algorithm, frames: &Frames) -> image::RgbImage {
    let world = splat_io::world::read_world(&super::root().join(LIT_WORLD)).expect("the lit world");
    let camera = world.camera.expect("the demo's camera").rescaled(160, 120).expect("a valid size");
    let settings = RenderSettings { background: world.background.unwrap_or_default(), ..RenderSettings::default() };
    let out = algorithm.render_lit(&world.scene, &camera, &settings, &world.lighting, frames, &|_| {}).expect("render");
    splat_io::image::to_rgba8(&out.mean).to_rgb8()
}
