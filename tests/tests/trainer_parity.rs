//! `raster-sorted` renders each trainer's captures as the trainer does. With the default `3dgs`
//! extent it equals an independent forward pass of diff-gaussian-rasterization
//! (`splat_tests::inria`) to float tolerance, on a fixture of SH degree 0 and one of degree 3,
//! with and without the reference's early stop; with a scene's screen filter set to gsplat's
//! antialiased mode or Mip-Splatting's 2D Mip filter it equals the same pass with that trainer's
//! `computeCov2D`. The controls: the √8σ extent, another trainer's filter, a filter variance
//! 1 % off, and opacities 2 % high are each rejected by the same comparison.

use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, SplatExtent, render_raster};
use splat_core::stats::rmse;
use splat_core::{Camera, Frames, RenderSettings, Scene, ScreenFilter};
use splat_tests::harness::fixture;
use splat_tests::inria::{self, Forward};

/// The tolerance of parity: largest |difference| and RMSE over the image.
const MAX_TOLERANCE: f32 = 1e-4;
const RMSE_TOLERANCE: f64 = 1e-5;

/// Largest |difference| and RMSE of CPU `raster-sorted` (`blend`) against the reference.
fn against(scene: &Scene, camera: &Camera, raster: RasterSettings, blend: Blend, reference: &Options) -> (f32, f64) {
    let settings =
        RenderSettings { background: glam::Vec3::from_array(reference.background), ..RenderSettings::default() };
    let r = Rasterizer::new(scene, camera, settings, raster).unwrap();
    let ours = render_raster(&r, &RasterMethod::Sorted { blend }, &Frames::default(), &|_| {}).unwrap();
    let options = inria::Options { early_stop: raster.early_stop, ..*reference };
    let reference: Vec<f32> = inria::render(scene, camera, &options).concat();
    let worst = ours.mean.data().iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    (worst, rmse(ours.mean.data(), &reference))
}

type Options = inria::Options<'static>;

fn reference(forward: Forward) -> Options {
    Options { background: [0.1, 0.2, 0.3], forward, ..Options::default() }
}

/// `scene` as a capture of the trainer with `filter`.
fn trained(scene: &Scene, filter: ScreenFilter) -> Scene {
    Scene { screen_filter: filter, ..scene.clone() }
}

/// Each trainer's forward pass and the filter that names it.
const TRAINERS: [(ScreenFilter, Forward); 3] = [
    (ScreenFilter::Dilation, Forward::Inria),
    (ScreenFilter::Antialiased, Forward::GSPLAT_ANTIALIASED),
    (ScreenFilter::Mip, Forward::MIP_SPLATTING),
];

#[test]
fn raster_sorted_equals_the_3dgs_forward_pass() {
    for (name, degree) in [("layers", 0), ("cloud", 3)] {
        let (scene, camera) = fixture(name, 128, 96);
        assert_eq!(scene.sh_degree, degree, "{name}");
        for early_stop in [false, true] {
            for blend in [Blend::Under, Blend::Over] {
                let raster = RasterSettings { early_stop, ..RasterSettings::default() };
                let (worst, rmse) = against(&scene, &camera, raster, blend, &reference(Forward::Inria));
                eprintln!("{name} {blend:?} early stop {early_stop}: max {worst:.2e}, RMSE {rmse:.2e}");
                assert!(
                    worst < MAX_TOLERANCE && rmse < RMSE_TOLERANCE,
                    "{name} {blend:?} early stop {early_stop}: max {worst}, RMSE {rmse}"
                );
            }
        }
    }
}

/// Each screen filter is its trainer's `computeCov2D`, and no other: a capture rendered
/// through another trainer's filter, or through its own with the variance 1 % off, is
/// rejected by the parity tolerance.
///
/// The filters differ only on splats of a few pixels (ρ = σ² / (σ² + s) for a round one), so the
/// capture is the cloud (σ from 0.6 to 3 px at 128 × 96), also seen from twice as far (at
/// 64 × 48, the zoomed-out view where Mip-Splatting's filter matters most).
#[test]
fn each_screen_filter_equals_its_trainers_forward_pass() {
    for (width, height) in [(128, 96), (64, 48)] {
        let name = format!("cloud at {width} × {height}");
        let (scene, camera) = fixture("cloud", width, height);
        let raster = RasterSettings::default();
        for (filter, forward) in TRAINERS {
            let capture = trained(&scene, filter);
            let (worst, rmse) = against(&capture, &camera, raster, Blend::Under, &reference(forward));
            eprintln!("{name} {filter:?}: max {worst:.2e}, RMSE {rmse:.2e}");
            assert!(worst < MAX_TOLERANCE && rmse < RMSE_TOLERANCE, "{name} {filter:?}: max {worst}, RMSE {rmse}");
            for (other, _) in TRAINERS.into_iter().filter(|&(f, _)| f != filter) {
                let (worst, rmse) =
                    against(&trained(&scene, other), &camera, raster, Blend::Under, &reference(forward));
                eprintln!("  control {other:?} on a {filter:?} capture: max {worst:.2e}, RMSE {rmse:.2e}");
                assert!(worst > 1e-2 && rmse > 1e-3, "{name}: {other:?} passes for {filter:?}: max {worst}");
            }
        }
        let off = [Forward::GsplatAntialiased { eps2d: 0.3 * 1.01 }, Forward::MipSplatting { kernel_size: 0.1 * 1.01 }];
        for (filter, forward) in [ScreenFilter::Antialiased, ScreenFilter::Mip].into_iter().zip(off) {
            let (worst, _) = against(&trained(&scene, filter), &camera, raster, Blend::Under, &reference(forward));
            eprintln!("  control {forward:?}: max {worst:.2e}");
            assert!(worst > MAX_TOLERANCE, "{name}: a 1 % error in the filter variance passes ({worst})");
        }
    }
}

/// The control: the √8σ quads of vk_gaussian_splatting miss the rims of the reference's box.
#[test]
fn the_sqrt8_extent_is_not_the_3dgs_forward_pass() {
    for name in ["layers", "cloud"] {
        let (scene, camera) = fixture(name, 128, 96);
        let raster = RasterSettings { extent: SplatExtent::Sqrt8, ..RasterSettings::default() };
        let (worst, rmse) = against(&scene, &camera, raster, Blend::Under, &reference(Forward::Inria));
        eprintln!("{name} √8σ against the 3DGS reference: max {worst:.2e}, RMSE {rmse:.2e}");
        assert!(worst > 1e-2 && rmse > 1e-3, "{name}: the √8σ extent passes as 3DGS: max {worst}, RMSE {rmse}");
    }
}

/// The comparison's power: a renderer whose opacities are 2 % high (the reference fed the
/// scaled scene, our renderer the true one) is rejected by the tolerance of the parity test.
#[test]
fn a_two_percent_opacity_bias_is_rejected() {
    for name in ["layers", "cloud"] {
        let (scene, camera) = fixture(name, 128, 96);
        let mut biased = scene.clone();
        for p in &mut biased.particles {
            p.opacity = (p.opacity * 1.02).min(1.0);
        }
        let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
        let ours = render_raster(&r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {});
        let options = inria::Options { background: [0.0; 3], ..Options::default() };
        let reference: Vec<f32> = inria::render(&biased, &camera, &options).concat();
        let ours = ours.unwrap();
        let worst = ours.mean.data().iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        eprintln!("{name}, opacity × 1.02: max {worst:.2e}");
        assert!(worst > 1e-3, "{name}: a 2 % opacity bias passes the parity tolerance ({worst})");
    }
}
