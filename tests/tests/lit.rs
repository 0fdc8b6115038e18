//! Statistical proof of the lit ray-tracing estimators (docs/architecture.md, "Lighting"):
//! per-pixel z-tests of `stochastic`, `stochastic-n` and `stochastic-pass` with the unbiased
//! stochastic shadow ray, against their exact expectations (the volumetric oracle with the
//! exact transmittance; the pass's own expectation), on two fixtures and a bonsai crop; the
//! stochastic shadow ray alone against the exact transmittance image; and the lit raster
//! estimators against lit sorted splatting. Each suite rejects a 2 % error injected into the
//! production estimator.

use glam::Vec3;
use splat_core::frame::RenderOutput;
use splat_core::image::Image;
use splat_core::lighting::{Light, LightKind, Lighting, Look, Material, Shadows};
use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster};
use splat_core::rng::{RayRng, RngScheme};
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, Frames, RenderSettings, Scene};
use splat_tests::harness::{StatTest, assert_unbiased_and_shift_rejected, fixture};

/// Frames of the mean run (the variance run has 4×).
const F: u32 = 256;
/// The injected error every suite must reject: each decision u < α + 0.02.
const BIASED: f32 = 0.02;

fn material() -> Material {
    Material {
        emissive: Vec3::splat(0.05),
        ambient: Vec3::splat(0.1),
        diffuse: Vec3::splat(0.8),
        specular: Vec3::splat(0.3),
        shininess: 16.0,
    }
}

/// The fill light's position on the fixtures: in front of them, up and to the right.
const FILL: Vec3 = Vec3::new(1.5, 1.5, 2.5);

/// A key light from the camera's upper left (its shadow rays cross the particles in front)
/// and a point fill light.
fn lights(fill: Vec3) -> Vec<Light> {
    vec![
        Light {
            kind: LightKind::Directional { direction: Vec3::new(0.4, -0.6, -1.0).normalize() },
            color: Vec3::new(1.0, 0.95, 0.9),
            intensity: 1.2,
            radius: 0.0,
        },
        Light {
            kind: LightKind::Point { position: fill },
            color: Vec3::new(0.5, 0.6, 1.0),
            intensity: 3.0,
            radius: 0.0,
        },
    ]
}

fn lighting(fill: Vec3, shadows: Shadows, look: Look) -> Lighting {
    Lighting { look, shadow_offset: 0.02, ..Lighting::single(material(), lights(fill), shadows) }
}

fn lit<'a>(scene: &'a Scene, lighting: Lighting) -> TraceScene<'a> {
    TraceScene::new(scene, RenderSettings::default()).unwrap().with_lighting(lighting).unwrap()
}

fn exact(trace: &TraceScene, camera: &Camera) -> RenderOutput {
    render_frames(trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap()
}

/// The image of `expectation(ray)` at every pixel centre, as an oracle for [`StatTest`].
fn expectation_image(
    camera: &Camera,
    trace: &TraceScene,
    expectation: impl Fn(&splat_core::Ray) -> glam::DVec3,
) -> RenderOutput {
    let (w, h) = (camera.width, camera.height);
    let mut mean = Image::filled(w, h, 3, 0.0);
    for y in 0..h {
        for x in 0..w {
            let e = expectation(&trace.clip(camera.pixel_ray(x, y)));
            mean.pixel_mut(x, y).copy_from_slice(&e.as_vec3().to_array());
        }
    }
    RenderOutput::colour_only(mean, Image::filled(w, h, 3, 0.0), Image::filled(w, h, 1, 0.0))
}

/// An estimator and the same estimator with every decision biased by [`BIASED`]: the first
/// passes the z-test against `oracle`, the second is rejected.
fn assert_unbiased_and_control(name: &str, oracle: &RenderOutput, run: impl Fn(Frames) -> RenderOutput) {
    let base = Frames { count: F, seed: 11, rng: RngScheme::Hash, ..Frames::default() };
    assert_unbiased_and_shift_rejected(name, oracle, base, BIASED, run);
}

fn check(name: &str, scene: &Scene, camera: &Camera, fill: Vec3) {
    let oracle = exact(&lit(scene, lighting(fill, Shadows::Exact, Look::Volumetric)), camera);
    let trace = lit(scene, lighting(fill, Shadows::Stochastic, Look::Volumetric));
    for (label, method) in
        [("stochastic", Method::Stochastic), ("stochastic-n 2×4", Method::StochasticN { m: 2, n: 4 })]
    {
        let run = |f: Frames| render_frames(&trace, camera, &method, &f, &|_| {}).unwrap();
        assert_unbiased_and_control(&format!("lit {name} {label}"), &oracle, run);
    }
    let pass = Method::StochasticPass { k: 4, max_passes: 200 };
    let exact_shadows = lit(scene, lighting(fill, Shadows::Exact, Look::Surface));
    let no_decisions = RayRng::new(0, 0, 0, RngScheme::Hash);
    let pass_oracle = expectation_image(camera, &exact_shadows, |ray| {
        exact_shadows.stochastic_pass_expectation(ray, &no_decisions, 4, 200)
    });
    let run = |f: Frames| render_frames(&trace, camera, &pass, &f, &|_| {}).unwrap();
    assert_unbiased_and_control(&format!("lit {name} stochastic-pass"), &pass_oracle, run);
}

#[test]
fn lit_z_test_on_layers() {
    let (scene, camera) = fixture("layers", 32, 24);
    check("layers", &scene, &camera, FILL);
}

#[test]
fn lit_z_test_on_cloud() {
    let (scene, camera) = fixture("cloud", 32, 24);
    check("cloud", &scene, &camera, FILL);
}

#[test]
fn lit_z_test_on_a_bonsai_crop() {
    let Some(scene) = splat_tests::bonsai() else { return };
    let camera = splat_tests::bonsai_camera().crop(560, 180, 32, 24).unwrap();
    let fill = camera.center() + Vec3::new(0.5, 0.5, 0.0);
    check("bonsai", &scene, &camera, fill);
}

/// The stochastic shadow ray alone: `exact` in the surface look (a deterministic primary), the
/// diffuse light seen through one stochastic shadow ray per light against the same image with
/// the exact transmittance Π(1 − αᵢ); the 2 % decision error is rejected.
#[test]
fn stochastic_shadow_ray_z_test_against_the_exact_transmittance() {
    let (scene, camera) = fixture("layers", 32, 24);
    let oracle = exact(&lit(&scene, lighting(FILL, Shadows::Exact, Look::Surface)), &camera);
    let trace = lit(&scene, lighting(FILL, Shadows::Stochastic, Look::Surface));
    let run = |f: Frames| render_frames(&trace, &camera, &Method::Exact, &f, &|_| {}).unwrap();
    assert_unbiased_and_control("stochastic shadow ray", &oracle, run);
}

/// The lit raster estimators (each written sample lit at its billboard depth with its own
/// normal, no shadows: vk_gaussian_splatting Lighting §3) against lit sorted splatting in the
/// volumetric look, on S = 4 samples.
#[test]
fn lit_raster_z_tests() {
    let (scene, camera) = fixture("layers", 32, 24);
    let raster = RasterSettings { samples: 4, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    let r = r.with_lighting(lighting(FILL, Shadows::None, Look::Volumetric)).unwrap();
    let sorted = RasterMethod::Sorted { blend: Blend::Under };
    let oracle = render_raster(&r, &sorted, &Frames::default(), &|_| {}).unwrap();
    let methods = [
        ("stochastic-splat", RasterMethod::StochasticSplat),
        ("enderton", RasterMethod::Enderton),
        ("stratified", RasterMethod::Stratified { scramble: true }),
    ];
    for (name, method) in methods {
        let run = |f: Frames| render_raster(&r, &method, &f, &|_| {}).unwrap();
        assert_unbiased_and_control(&format!("lit raster {name}"), &oracle, run);
    }
}

/// The two looks differ where they must: lit, the surface look of `exact` is not the
/// volumetric oracle, and a pixel that never reaches the iso threshold shows the background.
#[test]
fn surface_and_volumetric_looks_differ() {
    let (scene, camera) = fixture("cloud", 32, 24);
    let surface = exact(&lit(&scene, lighting(FILL, Shadows::Exact, Look::Surface)), &camera);
    let volumetric = exact(&lit(&scene, lighting(FILL, Shadows::Exact, Look::Volumetric)), &camera);
    let rmse = splat_core::stats::rmse(surface.mean.data(), volumetric.mean.data());
    assert!(rmse > 0.01, "RMSE {rmse}");
    let thin = (0..camera.width * camera.height).find(|&i| {
        let a = volumetric.alpha.data()[i as usize];
        a > 0.05 && a < 0.25
    });
    let i = thin.expect("a faint pixel") as usize;
    assert_eq!(&surface.mean.data()[3 * i..3 * i + 3], &[0.0; 3], "below the iso threshold: the background");
}

/// Lit, with stochastic shadow rays and a soft light, the RMSE of `stochastic` against the
/// volumetric oracle falls at the Monte Carlo rate (slope −1/2 on log–log axes), as unlit.
#[test]
fn lit_convergence_slope_is_monte_carlo() {
    let (scene, camera) = fixture("cloud", 24, 18);
    let oracle = exact(&lit(&scene, lighting(FILL, Shadows::Exact, Look::Volumetric)), &camera);
    let trace = lit(&scene, lighting(FILL, Shadows::Stochastic, Look::Volumetric));
    let run = |f: Frames| render_frames(&trace, &camera, &Method::Stochastic, &f, &|_| {}).unwrap();
    StatTest::new("lit cloud stochastic", oracle, run).assert_converges(256, 3);
}
