//! `raster-sorted` renders each trainer's captures as the trainer does. With the default `3dgs`
//! extent it equals an independent forward pass of diff-gaussian-rasterization
//! (`splat_tests::inria`) to float tolerance, on a fixture of SH degree 0 and one of degree 3,
//! with and without the reference's early stop; with each trainer's preset (gsplat's classic
//! and antialiased modes, Mip-Splatting's 2D Mip filter) it equals the same pass with that
//! trainer's `computeCov2D` and, for gsplat, its footprint (every pixel above the alpha cull,
//! where the INRIA rasterizer draws whole tiles) and near plane. The controls: the √8σ extent, another trainer's filter
//! or footprint, a filter variance 1 % off, and opacities 2 % high are each rejected by the
//! same comparison.

use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, Response, SplatExtent, render_raster};
use splat_core::stats::rmse;
use splat_core::trainer::Preset;
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

/// Each trainer's forward pass and the preset that names it.
const TRAINERS: [(Preset, Forward); 4] = [
    (Preset::ThreeDgs, Forward::Inria),
    (Preset::Gsplat, Forward::GSPLAT_CLASSIC),
    (Preset::GsplatAntialiased, Forward::GSPLAT_ANTIALIASED),
    (Preset::MipSplatting, Forward::MIP_SPLATTING),
];

/// A trainer's screen filter and splat extent.
fn of(preset: Preset) -> (ScreenFilter, RasterSettings) {
    let filter = preset.screen_filter().expect("a rasterizing trainer");
    (filter, RasterSettings { extent: preset.extent(), ..RasterSettings::default() })
}

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

/// Each trainer's preset (its screen filter and splat extent) is its trainer's `computeCov2D`
/// and footprint, and no other: a capture rendered through another trainer's filter, through
/// its own with the variance 1 % off, or with the other footprint (the 3DGS tiles for gsplat's
/// alpha-cull bounds and back) is rejected by the parity tolerance.
///
/// The filters differ only on splats of a few pixels (ρ = σ² / (σ² + s) for a round one), so the
/// capture is the cloud (σ from 0.6 to 3 px at 128 × 96), also seen from twice as far (at
/// 64 × 48, the zoomed-out view where Mip-Splatting's filter matters most).
#[test]
fn each_trainers_preset_equals_its_forward_pass() {
    for (width, height) in [(128, 96), (64, 48)] {
        let name = format!("cloud at {width} × {height}");
        let (scene, camera) = fixture("cloud", width, height);
        for (preset, forward) in TRAINERS {
            let (filter, raster) = of(preset);
            let capture = trained(&scene, filter);
            let (worst, rmse) = against(&capture, &camera, raster, Blend::Under, &reference(forward));
            eprintln!("{name} {preset:?}: max {worst:.2e}, RMSE {rmse:.2e}");
            assert!(worst < MAX_TOLERANCE && rmse < RMSE_TOLERANCE, "{name} {preset:?}: max {worst}, RMSE {rmse}");
            // Another filter (gsplat's classic mode has 3DGS's: the footprint tells them
            // apart, below).
            for other_filter in ScreenFilter::ALL.into_iter().filter(|&f| f != filter) {
                let (worst, rmse) =
                    against(&trained(&scene, other_filter), &camera, raster, Blend::Under, &reference(forward));
                eprintln!("  control {other_filter:?} on a {preset:?} capture: max {worst:.2e}, RMSE {rmse:.2e}");
                assert!(worst > 1e-2 && rmse > 1e-3, "{name}: {other_filter:?} passes for {preset:?}: max {worst}");
            }
            let swapped = match raster.extent {
                SplatExtent::AlphaCull => SplatExtent::ThreeDgs,
                _ => SplatExtent::AlphaCull,
            };
            let control = RasterSettings { extent: swapped, ..raster };
            let (worst, rmse) = against(&capture, &camera, control, Blend::Under, &reference(forward));
            eprintln!("  control {swapped:?} footprint on a {preset:?} capture: max {worst:.2e}, RMSE {rmse:.2e}");
            assert!(worst > MAX_TOLERANCE, "{name}: the {swapped:?} footprint passes for {preset:?}: max {worst}");
        }
        let off = [Forward::GsplatAntialiased { eps2d: 0.3 * 1.01 }, Forward::MipSplatting { kernel_size: 0.1 * 1.01 }];
        for (preset, forward) in [Preset::GsplatAntialiased, Preset::MipSplatting].into_iter().zip(off) {
            let (filter, raster) = of(preset);
            let (worst, _) = against(&trained(&scene, filter), &camera, raster, Blend::Under, &reference(forward));
            eprintln!("  control {forward:?}: max {worst:.2e}");
            assert!(worst > MAX_TOLERANCE, "{name}: a 1 % error in the filter variance passes ({worst})");
        }
    }
}

/// Each trainer's near plane: a small particle 0.1 in front of the camera is culled by the
/// INRIA rasterizer (`in_frustum`, 0.2) and drawn by gsplat (`near_plane` 0.01); with each
/// preset's settings raster-sorted equals that trainer's pass, and gsplat's pass drawn with the
/// 3DGS near plane (the control) is rejected.
#[test]
fn each_trainers_near_plane() {
    let (mut scene, camera) = fixture("cloud", 128, 96);
    let near = camera.center() + 0.1 * camera.forward();
    scene.particles.push(splat_core::Particle::with_rgb(
        near,
        glam::Vec3::splat(0.0008),
        glam::Quat::IDENTITY,
        0.9,
        glam::Vec3::new(1.0, 0.2, 0.1),
    ));
    for (preset, forward) in [
        (Preset::ThreeDgs, Forward::Inria),
        (Preset::Gsplat, Forward::GSPLAT_CLASSIC),
        (Preset::GsplatAntialiased, Forward::GSPLAT_ANTIALIASED),
    ] {
        let (filter, raster) = of(preset);
        let capture = trained(&scene, filter);
        let reference: Vec<f32> = inria::render(&capture, &camera, &reference(forward)).concat();
        let render = |near: f32| {
            let settings =
                RenderSettings { near, background: glam::Vec3::new(0.1, 0.2, 0.3), ..RenderSettings::default() };
            let r = Rasterizer::new(&capture, &camera, settings, raster).unwrap();
            let out = render_raster(&r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {});
            worst(out.unwrap().mean.data(), &reference)
        };
        let d = render(preset.near());
        eprintln!("{preset:?}: near plane {}, max {d:.1e}", preset.near());
        assert!(d < MAX_TOLERANCE, "{preset:?}: {d} from its trainer's pass with the near particle");
        if preset.near() != Preset::ThreeDgs.near() {
            let control = render(Preset::ThreeDgs.near());
            eprintln!("control: {preset:?}'s capture at the 3DGS near plane, max {control:.1e}");
            assert!(control > 1e-2, "the 3DGS near plane passes for {preset:?} ({control})");
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

/// The surfel equation of 2DGS (Huang et al. 2024 §4.2), evaluated directly in f64 for the pixel
/// centres of `camera`: each ray meets each surfel's plane at t = (μ − o)·n / (d·n), the
/// in-plane coordinates there are u = (x − μ)·t_u / s_u and v = (x − μ)·t_v / s_v (t_u, t_v, n
/// the columns of the surfel's rotation), α = min(0.99, o e^{−(u² + v²)/2}) within the 3σ disc
/// and above 1/255, composited front to back by t.
fn surfel_image(scene: &Scene, camera: &Camera) -> Vec<f32> {
    composite(scene, camera, |p, origin, dir| {
        let (t, rho2) = surfel_hit(p, origin, dir);
        let alpha = (f64::from(p.opacity) * (-0.5 * rho2).exp()).min(0.99);
        (t > 0.0 && rho2 <= 9.0 && alpha >= 1.0 / 255.0).then_some((t, alpha))
    })
}

/// Where the ray o + t d meets a surfel's plane: t = (μ − o)·n / (d·n), and u² + v² there, with
/// u = (x − μ)·t_u / s_u and v = (x − μ)·t_v / s_v (t_u, t_v, n the columns of its rotation).
fn surfel_hit(p: &splat_core::Particle, origin: glam::DVec3, dir: glam::DVec3) -> (f64, f64) {
    let m = glam::DMat3::from_quat(p.rotation.as_dquat());
    let (tu, tv, n) = (m.x_axis, m.y_axis, m.z_axis);
    let mean = p.mean.as_dvec3();
    let t = (mean - origin).dot(n) / dir.dot(n);
    let at = origin + t * dir - mean;
    let (u, v) = (at.dot(tu) / f64::from(p.scale.x), at.dot(tv) / f64::from(p.scale.y));
    (t, u * u + v * v)
}

/// The image of `camera`'s pixel-centre rays (in f64, from the intrinsics): each pixel the hits
/// `hit(particle, origin, direction)` gives as (t, α), each of its particle's degree-0 SH
/// colour, composited front to back by t (Eq. 3).
fn composite(
    scene: &Scene,
    camera: &Camera,
    hit: impl Fn(&splat_core::Particle, glam::DVec3, glam::DVec3) -> Option<(f64, f64)>,
) -> Vec<f32> {
    let r = camera.rotation.as_dmat3();
    let origin = camera.center().as_dvec3();
    let mut image = Vec::new();
    for y in 0..camera.height {
        for x in 0..camera.width {
            let d_cam = glam::DVec3::new(
                (f64::from(x) + 0.5 - f64::from(camera.cx)) / f64::from(camera.fx),
                (f64::from(y) + 0.5 - f64::from(camera.cy)) / f64::from(camera.fy),
                1.0,
            );
            let dir = (r.transpose() * d_cam).normalize();
            let rgb = |p: &splat_core::Particle| {
                (p.sh[0].as_dvec3() * f64::from(splat_core::sh::SH_C0) + glam::DVec3::splat(0.5)).max(glam::DVec3::ZERO)
            };
            let mut hits: Vec<(f64, f64, glam::DVec3)> = scene
                .particles
                .iter()
                .filter_map(|p| hit(p, origin, dir).map(|(t, alpha)| (t, alpha, rgb(p))))
                .collect();
            hits.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (mut c, mut transmittance) = (glam::DVec3::ZERO, 1.0);
            for (_, alpha, rgb) in hits {
                c += transmittance * alpha * rgb;
                transmittance *= 1.0 - alpha;
            }
            image.extend(c.as_vec3().to_array());
        }
    }
    image
}

/// A 2DGS capture (a `.ply` with two scales, as the 2DGS trainer writes it, read back) of the
/// layers' particles turned so that a `width` × `height` view meets the surfels obliquely; the
/// same particles as 3D Gaussians (their third scale kept); the camera.
fn surfel_capture(width: u32, height: u32) -> (Scene, Scene, Camera) {
    let (gaussians, camera) = fixture("layers", width, height);
    // The 2DGS file: the layers' particles written without scale_2, turned so that the view
    // meets the surfels obliquely.
    let mut turned = gaussians.clone();
    for (i, p) in turned.particles.iter_mut().enumerate() {
        p.rotation = (glam::Quat::from_rotation_x(0.5 + 0.3 * i as f32) * p.rotation).normalize();
    }
    let surfels = splat_io::ply::parse_ply(splat_tests::two_dgs_ply(&turned).as_bytes(), Default::default()).unwrap();
    (surfels, turned, camera)
}

/// A 2DGS capture (a `.ply` with two scales, as the 2DGS trainer writes it) renders with the ray
/// tracer as the surfel equation says, from any side and obliquely: `exact` on the read file
/// equals [`surfel_image`] of the same surfels. The control: the same particles as 3D
/// Gaussians (their third scale kept) are rejected; splatting, which projects a surfel as a flat
/// ellipse by EWA's affine approximation, is measured against it for the record.
#[test]
fn a_2dgs_capture_renders_as_the_surfel_equation() {
    use splat_core::trace::{Method, TraceScene, render_frames};
    let (surfels, turned, camera) = surfel_capture(96, 72);
    let reference = surfel_image(&surfels, &camera);
    let traced = |scene: &Scene| {
        let trace = TraceScene::new(scene, RenderSettings::default()).unwrap();
        render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap().mean.data().to_vec()
    };
    let worst = |image: &[f32]| image.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let ours = traced(&surfels);
    let control = traced(&turned);
    let r = Rasterizer::new(&surfels, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    let splatted =
        render_raster(&r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap();
    eprintln!(
        "2DGS: exact max {:.1e}; as 3D Gaussians max {:.1e} (RMSE {:.1e}); raster-sorted max {:.1e} (RMSE {:.1e})",
        worst(&ours),
        worst(&control),
        rmse(&control, &reference),
        worst(splatted.mean.data()),
        rmse(splatted.mean.data(), &reference)
    );
    assert!(worst(&ours) < MAX_TOLERANCE, "the ray tracer is {} from the surfel equation", worst(&ours));
    assert!(worst(&control) > 1e-2, "3D Gaussians pass as surfels ({})", worst(&control));
}

/// A ray in a particle's frame scaled by 1/s, as 3dgrut's `densityHit` takes it (gro, grdu):
/// the squared distance of its line to the centre, grayDist = |normalize(grdu) × gro|², and the
/// distance of the point of maximum response, t = −gro·grdu / |grdu|².
fn grut_ray(p: &splat_core::Particle, origin: glam::DVec3, dir: glam::DVec3) -> (f64, f64) {
    let rot = glam::DMat3::from_quat(p.rotation.as_dquat());
    let inv_scale = glam::DVec3::ONE / p.scale.as_dvec3();
    let gro = inv_scale * (rot.transpose() * (origin - p.mean.as_dvec3()));
    let grdu = inv_scale * (rot.transpose() * dir);
    (grdu.normalize().cross(gro).length_squared(), -gro.dot(grdu) / grdu.length_squared())
}

/// 3DGRT's `processHit` in f64 for the pixel centres of `camera` (3dgrut
/// `threedgrt_tracer/.../gaussianParticles.cuh`): in the particle's frame scaled by 1/s, the
/// squared distance of the ray's line to the centre, grayDist = |grd × gro|², the response
/// exp(−4.5/3ⁿ · grayDistⁿᐟ²), α = min(0.99, response × density), kept when the response exceeds
/// 0.0113 and α exceeds 1/255; hits at their point of maximum response, composited front to back.
fn grt_image(scene: &Scene, camera: &Camera, degree: i32) -> Vec<f32> {
    composite(scene, camera, |p, origin, dir| {
        let (gray_dist, t) = grut_ray(p, origin, dir);
        let gres = (-4.5 / 3f64.powi(degree) * gray_dist.powf(f64::from(degree) / 2.0)).exp();
        let alpha = (gres * f64::from(p.opacity)).min(0.99);
        (t > 0.0 && gres > 0.0113 && alpha > 1.0 / 255.0).then_some((t, alpha))
    })
}

/// A 3DGRT capture renders with `--preset 3dgrt` (kernel degree 4, the cutoff of 3DGRT's minimum
/// response) as 3DGRT's own hit evaluation does, composited without its early stop; the 3DGS
/// preset's Gaussian kernel on the same capture is rejected, and so is degree 4 cut at 3σ
/// rather than at 3DGRT's minimum response.
#[test]
fn the_3dgrt_preset_renders_as_3dgrt() {
    use splat_core::trace::{Method, TraceScene, render_frames};
    let (scene, camera) = fixture("layers", 96, 72);
    let reference = grt_image(&scene, &camera, 4);
    let traced = |degree: u32, cutoff: f32| {
        let kernel = splat_core::KernelParams { degree, cutoff, ..Default::default() };
        let trace = TraceScene::new(&scene, RenderSettings { kernel, ..RenderSettings::default() }).unwrap();
        render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap().mean.data().to_vec()
    };
    let worst = |image: &[f32]| image.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let preset = |p: Preset| traced(p.kernel_degree(), p.cutoff());
    let (ours, control) = (preset(Preset::ThreeDgrt), preset(Preset::ThreeDgs));
    let full_cutoff = traced(4, 3.0);
    eprintln!(
        "3DGRT: --preset 3dgrt max {:.1e}; --preset 3dgs max {:.1e}; degree 4 cut at 3σ max {:.1e}",
        worst(&ours),
        worst(&control),
        worst(&full_cutoff)
    );
    assert!(worst(&ours) < MAX_TOLERANCE, "the 3dgrt preset is {} from 3DGRT", worst(&ours));
    assert!(worst(&control) > 1e-2, "the Gaussian kernel passes for 3DGRT's ({})", worst(&control));
    assert!(worst(&full_cutoff) > MAX_TOLERANCE, "the 3σ cutoff passes for 3DGRT's minimum response");
}

/// The image of `camera`'s pixel-centre rays with each particle's (α, hit) from `hit`, composited
/// front to back in the global order of the particles' view depths (ties by index): what a
/// rasterizer that evaluates in 3D (3DGUT's `GlobalZOrder`, 2DGS) blends.
fn in_centre_depth_order(
    scene: &Scene,
    camera: &Camera,
    hit: impl Fn(&splat_core::Particle, glam::DVec3, glam::DVec3) -> Option<f64>,
) -> Vec<f32> {
    let rotation = camera.rotation.as_dmat3();
    let origin = camera.center().as_dvec3();
    let view_z = |p: &splat_core::Particle| (rotation * (p.mean.as_dvec3() - origin)).z;
    composite(scene, camera, |p, o, d| (view_z(p) > 0.2).then(|| hit(p, o, d)).flatten().map(|a| (view_z(p), a)))
}

/// 3DGUT's forward pass in f64 (3dgrut `configs/render/3dgut.yaml` with
/// `gutKBufferRenderer.cuh` at k = 0 and `GlobalZOrder`): every particle evaluated on each
/// pixel's ray as 3DGRT's `densityHit` does (the squared distance of the ray's line to the
/// centre in the particle's frame scaled by 1/s, the response exp(−½ d²), kept above 0.0113,
/// α = min(0.99, o × response) kept above 1/255, its hit distance positive), composited in the
/// global order of the centres' view depths. No tile bound: every particle, every pixel.
fn gut_image(scene: &Scene, camera: &Camera, opacity_scale: f64) -> Vec<f32> {
    in_centre_depth_order(scene, camera, |p, origin, dir| {
        let (gray_dist, t) = grut_ray(p, origin, dir);
        let response = (-0.5 * gray_dist).exp();
        let alpha = (response * f64::from(p.opacity) * opacity_scale).min(0.99);
        (t > 0.0 && response > 0.0113 && alpha > 1.0 / 255.0).then_some(alpha)
    })
}

/// `exact` (the ray tracer: each ray's hits in their own order) of `scene` with a preset's kernel.
fn traced(scene: &Scene, camera: &Camera, preset: Preset) -> Vec<f32> {
    use splat_core::trace::{Method, TraceScene, render_frames};
    let kernel =
        splat_core::KernelParams { degree: preset.kernel_degree(), cutoff: preset.cutoff(), ..Default::default() };
    let trace = TraceScene::new(scene, RenderSettings { kernel, ..RenderSettings::default() }).unwrap();
    render_frames(&trace, camera, &Method::Exact, &Frames::default(), &|_| {}).unwrap().mean.data().to_vec()
}

/// `raster-sorted` of `scene` with a preset's kernel, extent and response.
fn splatted(scene: &Scene, camera: &Camera, preset: Preset, response: Response) -> Vec<f32> {
    let kernel =
        splat_core::KernelParams { degree: preset.kernel_degree(), cutoff: preset.cutoff(), ..Default::default() };
    let settings = RenderSettings { kernel, ..RenderSettings::default() };
    let raster = RasterSettings { extent: preset.extent(), response, ..RasterSettings::default() };
    let r = Rasterizer::new(scene, camera, settings, raster).unwrap();
    let out = render_raster(&r, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {}).unwrap();
    out.mean.data().to_vec()
}

fn worst(image: &[f32], reference: &[f32]) -> f32 {
    image.iter().zip(reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max)
}

/// A 3DGUT capture splats with `--preset 3dgut` as 3DGUT renders it: each particle evaluated in
/// 3D along the pixel's ray, in the global depth order of the centres, equals [`gut_image`] (which
/// bounds no particle by tiles). The controls: the projected 2D Gaussians of 3DGS
/// (`--response projected`), and the reference with opacities 2 % high, are rejected.
#[test]
fn the_3dgut_preset_splats_as_3dgut() {
    let (scene, camera) = fixture("layers", 96, 72);
    let reference = gut_image(&scene, &camera, 1.0);
    let ours = splatted(&scene, &camera, Preset::ThreeDgut, Preset::ThreeDgut.response());
    let projected = splatted(&scene, &camera, Preset::ThreeDgut, Response::Projected);
    let biased = gut_image(&scene, &camera, 1.02);
    let (d, control, power) = (worst(&ours, &reference), worst(&projected, &reference), worst(&ours, &biased));
    let exact = traced(&scene, &camera, Preset::ThreeDgut);
    eprintln!(
        "3DGUT: along the ray max {d:.1e}; projected max {control:.1e}; reference × 1.02 max {power:.1e}; \
         the ray tracer (hits in ray order) RMSE {:.1e}, max {:.1e}",
        rmse(&exact, &reference),
        worst(&exact, &reference)
    );
    assert!(d < MAX_TOLERANCE, "the 3dgut preset splats {d} from 3DGUT");
    assert!(control > MAX_TOLERANCE, "projected 2D Gaussians pass for 3DGUT ({control})");
    assert!(power > MAX_TOLERANCE, "a 2 % opacity bias passes ({power})");
}

/// 2DGS's rasterizer (diff-surfel-rasterization `renderCUDA`) in f64: each pixel's ray meets each
/// surfel's plane (ρ_3D = u² + v² there, as [`surfel_image`]), its low-pass ρ_2D = 2 ‖x − c‖²
/// about the projected centre c (`FilterInvSquare`), α = min(0.99, o e^{−min(ρ_3D, ρ_2D)/2})
/// above 1/255, no cutoff, composited in the global order of the centres' view depths;
/// `low_pass: false` drops ρ_2D (the control).
fn surfel_raster_image(scene: &Scene, camera: &Camera, low_pass: bool) -> Vec<f32> {
    let rotation = camera.rotation.as_dmat3();
    let origin = camera.center().as_dvec3();
    let (fx, fy, cx, cy) = (f64::from(camera.fx), f64::from(camera.fy), f64::from(camera.cx), f64::from(camera.cy));
    in_centre_depth_order(scene, camera, |p, o, dir| {
        let (t, rho2) = surfel_hit(p, o, dir);
        let rho_3d = if t > 0.0 { rho2 } else { f64::INFINITY };
        let c = rotation * (p.mean.as_dvec3() - origin);
        let centre = glam::DVec2::new(fx * c.x / c.z + cx, fy * c.y / c.z + cy);
        let d_cam = rotation * dir;
        let pixel = glam::DVec2::new(fx * d_cam.x / d_cam.z + cx, fy * d_cam.y / d_cam.z + cy);
        let rho_2d = if low_pass { 2.0 * (pixel - centre).length_squared() } else { f64::INFINITY };
        let alpha = (f64::from(p.opacity) * (-0.5 * rho_3d.min(rho_2d)).exp()).min(0.99);
        (alpha >= 1.0 / 255.0).then_some(alpha)
    })
}

/// A 2DGS capture splats as 2DGS's rasterizer renders it, without a flag (a file of 2D Gaussians
/// takes `--response along-ray`; the 2dgs preset's kernel has no cutoff): equal to
/// [`surfel_raster_image`] at 96 × 72 and zoomed out to 32 × 24, where surfels are a few pixels
/// and the low-pass decides. The controls: the projected (EWA) ellipses, and (zoomed out, where
/// it acts) 2DGS without its low-pass, are rejected.
#[test]
fn a_2dgs_capture_splats_as_2dgs() {
    for (width, height) in [(96, 72), (32, 24)] {
        let (surfels, _, camera) = surfel_capture(width, height);
        let reference = surfel_raster_image(&surfels, &camera, true);
        let ours = splatted(&surfels, &camera, Preset::TwoDgs, Preset::TwoDgs.response());
        let projected = splatted(&surfels, &camera, Preset::TwoDgs, Response::Projected);
        let unfiltered = surfel_raster_image(&surfels, &camera, false);
        let (d, control, low_pass) =
            (worst(&ours, &reference), worst(&projected, &reference), worst(&ours, &unfiltered));
        let exact = traced(&surfels, &camera, Preset::TwoDgs);
        eprintln!(
            "2DGS at {width} × {height}: along the ray max {d:.1e}; projected max {control:.1e}; without the low-pass \
             max {low_pass:.1e}; the ray tracer (ray order, no low-pass) RMSE {:.1e}, max {:.1e}",
            rmse(&exact, &reference),
            worst(&exact, &reference)
        );
        assert!(d < MAX_TOLERANCE, "{width} × {height}: 2DGS splats {d} from its rasterizer");
        assert!(control > MAX_TOLERANCE, "{width} × {height}: projected ellipses pass for 2DGS ({control})");
        if width < 96 {
            assert!(low_pass > MAX_TOLERANCE, "{width} × {height}: 2DGS without its low-pass passes ({low_pass})");
        }
    }
}
