//! Deterministic tests of the raster reference: over = under, agreement with the ray-traced
//! oracle where the projection is exact, and the stratification properties of Laine & Karras
//! §4 (the expectations of the stochastic methods are enumerated in `enumeration.rs`).

use super::*;
use crate::particle::Particle;
use crate::scenes;
use approx::assert_relative_eq;
use glam::Quat;

fn sorted(blend: Blend) -> RasterMethod {
    RasterMethod::Sorted { blend }
}

fn render(r: &Rasterizer, method: &RasterMethod, count: u32) -> RenderOutput {
    render_raster(r, method, &Frames { count, seed: 3, ..Frames::default() }, &|_| {}).unwrap()
}

/// Back-to-front over and front-to-back under give the same image, for every sample count and
/// both fragment depths, on two fixtures.
#[test]
fn over_equals_under() {
    for (scene, camera) in [scenes::layers(), scenes::cloud()] {
        let camera = camera.rescaled(40, 30).unwrap();
        for samples in [1, 4] {
            for fragment_depth in [FragmentDepth::Center, FragmentDepth::MaxDensityPlane] {
                let raster = RasterSettings { samples, fragment_depth, ..RasterSettings::default() };
                let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
                let over = render(&r, &sorted(Blend::Over), 1);
                let under = render(&r, &sorted(Blend::Under), 1);
                for (a, b) in over.mean.data().iter().zip(under.mean.data()) {
                    assert_relative_eq!(a, b, epsilon = 1e-6);
                }
                assert_eq!(over.alpha, under.alpha);
                assert!(under.alpha.data().iter().any(|&a| a > 0.5), "the fixture is visible");
            }
        }
    }
}

/// A large isotropic particle seen head-on: the projection is then nearly exact, and sorted
/// splatting reproduces the ray-traced oracle (max response along the ray) to the size of
/// the 0.3 px² dilation once both cut at √8σ.
#[test]
fn sorted_splatting_matches_the_ray_traced_oracle_where_ewa_is_exact() {
    let p = Particle::with_rgb(Vec3::ZERO, Vec3::splat(0.3), Quat::IDENTITY, 0.9, Vec3::new(1.0, 0.5, 0.2));
    let scene = Scene::new(vec![p], 0);
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 20.0), Vec3::ZERO, Vec3::Y, 10.0, 48, 48).unwrap();
    let mut settings = RenderSettings::default();
    settings.kernel.cutoff = project::EXTENT_SQ.sqrt();
    let sqrt8 = RasterSettings { extent: SplatExtent::Sqrt8, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, settings, sqrt8).unwrap();
    let raster = render(&r, &sorted(Blend::Under), 1);
    let exact = crate::oracle::render_oracle(&scene, &camera, &settings, &Frames::default(), &|_| {}).unwrap();
    // Inside the footprint (away from the √8σ rim, where the dilated and undilated ellipses
    // cut different pixels) the alphas differ by the dilation's effect only: σ′² = σ² + 0.3 with
    // σ ≈ 4.1 px widens the Gaussian by k = 1.78 %, and max over x of o (e^(−x/(1+k)) − e^(−x))
    // ≈ o k / e ≈ 0.0059 for o = 0.9.
    let mut worst = 0.0f32;
    for (a, b) in raster.alpha.data().iter().zip(exact.alpha.data()) {
        if *b > 0.05 {
            worst = worst.max((a - b).abs());
        }
    }
    assert!(worst < 0.0065, "largest alpha difference {worst}");
    let rmse = crate::stats::rmse(raster.alpha.data(), exact.alpha.data());
    assert!(rmse < 0.002, "alpha RMSE {rmse}");
    assert!(raster.alpha.data().iter().any(|&a| a > 0.85));
}

/// A one-pixel camera looking at a stack of splats, with their fragments.
fn one_pixel(opacities: &[f32], samples: u32) -> (Scene, Camera) {
    let particles = opacities
        .iter()
        .enumerate()
        .map(|(i, &o)| {
            let rgb = Vec3::new(0.1 + 0.2 * i as f32, 0.9 - 0.15 * i as f32, (i % 2) as f32);
            let mean = Vec3::new(0.0, 0.0, -0.3 * i as f32);
            Particle::with_rgb(mean, Vec3::splat(1.0), Quat::IDENTITY, o, rgb)
        })
        .collect();
    let scene = Scene::new(particles, 0);
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 2.0, 1, 1).unwrap();
    assert!(SAMPLE_COUNTS.contains(&samples));
    (scene, camera)
}

/// Laine & Karras §4, Figure 5: two full-pixel surfaces of α = ½ at 16 samples. The nearest
/// covers exactly 8 samples whatever the order; the far one ends with exactly 4 visible when
/// drawn first (sorting by stored depth, Figure 5d) and when drawn last (early depth test,
/// Figure 5b). Enderton's method gets 4 only on average.
#[test]
fn stratified_covers_exact_sample_counts() {
    let (scene, camera) = one_pixel(&[0.5, 0.5], 16);
    let raster = RasterSettings { samples: 16, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    let px = r.pixel(0, 0);
    let near_to_far = r.fragments(&px);
    let far_to_near: Vec<Fragment> = near_to_far.iter().rev().copied().collect();
    let (near, far) = (scene.particles[0].sh[0], scene.particles[1].sh[0]);
    assert_ne!(near, far);
    let mut enderton_far = Vec::new();
    for key in 0..64 {
        for order in [&near_to_far, &far_to_near] {
            let rng = RayRng::new(0, 0, key, RngScheme::Hash);
            let buf = r.stratified(&px, order, &rng, key, true);
            let count = |k: u32| (0..16).filter(|&s| buf.splat[s] == k).count();
            let (n, f) = (near_to_far[0].source, near_to_far[1].source);
            assert_eq!((count(n), count(f)), (8, 4), "frame {key}");
            let e = r.enderton(&px, order, &rng);
            enderton_far.push((0..16).filter(|&s| e.splat[s] == f).count());
        }
    }
    assert!(enderton_far.iter().any(|&c| c != 4), "Enderton is not stratified across surfaces");
}

/// A surface of α = ¼ drawn as two fragments that split the samples (an edge inside the pixel)
/// still covers exactly a quarter of the samples: the second fragment continues the surface's
/// sequence (Figure 7, line 8) instead of restarting it.
#[test]
fn stratified_continues_a_surface_across_fragments() {
    let (scene, camera) = one_pixel(&[0.25, 0.25], 16);
    let raster = RasterSettings { samples: 16, ..RasterSettings::default() };
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    let px = r.pixel(0, 0);
    let mut frags = r.fragments(&px);
    // Make the two fragments one surface cut in half, side by side, at equal depth coverage.
    frags[0].covered = 0x00FF;
    frags[1].covered = 0xFF00;
    for key in 0..32 {
        let buf = r.stratified(&px, &frags, &RayRng::new(0, 0, key, RngScheme::Hash), key, true);
        let written = (0..16).filter(|&s| buf.splat[s] != u32::MAX).count();
        assert_eq!(written, 4, "frame {key}");
    }
}

/// Frames are reproducible and independent of the draw order for StochasticSplats (whose
/// decisions are hashes of ids, not of positions in a stream).
#[test]
fn stochastic_splat_does_not_depend_on_draw_order() {
    let (scene, camera) = scenes::cloud();
    let camera = camera.rescaled(24, 18).unwrap();
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    for (x, y) in [(12, 9), (5, 7), (20, 3)] {
        let px = r.pixel(x, y);
        let mut frags = r.fragments(&px);
        let rng = RayRng::new(x, y, 5, RngScheme::Hash);
        let a = r.draw(&RasterMethod::StochasticSplat, &px, &frags, &rng, 5);
        frags.reverse();
        let b = r.draw(&RasterMethod::StochasticSplat, &px, &frags, &rng, 5);
        assert_eq!(a, b);
    }
}

#[test]
fn bad_raster_settings_are_refused() {
    let (scene, camera) = scenes::layers();
    let bad = RasterSettings { samples: 3, ..RasterSettings::default() };
    let err = Rasterizer::new(&scene, &camera, RenderSettings::default(), bad).err().unwrap();
    assert!(err.to_string().contains("3 samples per pixel"), "{err}");
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    let trig = Frames { rng: RngScheme::Trig, ..Frames::default() };
    assert!(render_raster(&r, &RasterMethod::StochasticSplat, &trig, &|_| {}).is_err());
    let none = Frames { count: 0, ..Frames::default() };
    assert!(render_raster(&r, &RasterMethod::StochasticSplat, &none, &|_| {}).is_err());
    for u_shift in [f32::NAN, 1.0, -2.0] {
        let bad = Frames { u_shift, ..Frames::default() };
        let err = render_raster(&r, &RasterMethod::StochasticSplat, &bad, &|_| {}).unwrap_err().to_string();
        assert!(err.contains("u_shift"), "{err}");
    }
}

/// Front to back picks the iso-opacity depth and splat: two full-pixel splats of α = 0.2 and
/// 0.5 put T at 0.8 then 0.4, so with the threshold 0.7 the second one is picked.
#[test]
fn under_picks_the_iso_opacity_splat() {
    let (scene, camera) = one_pixel(&[0.2, 0.5], 1);
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    let out = render(&r, &sorted(Blend::Under), 1);
    assert_eq!(out.picked, vec![Some(1)]);
    let depth = out.depth.data()[0];
    assert_relative_eq!(depth, 5.3, max_relative = 1e-3);
    assert_relative_eq!(out.normal.pixel(0, 0)[2], 1.0, epsilon = 1e-3);
}

/// The 3DGS early stop: behind two splats of α = 0.98 the transmittance is 4e-4, and the third
/// would take it to 8e-6 < 1e-4, so the third and fourth are not composited (their colour,
/// weighted 3.9e-4 and 7.8e-6, is missing); both blend orders stop at the same splat. Without
/// the option the sum is Eq. 3 over all four.
#[test]
fn early_stop_drops_the_splats_behind_t_1e_4() {
    let (scene, camera) = one_pixel(&[0.98, 0.98, 0.98, 0.98], 1);
    let rgb = |i: usize| scene.particles[i].sh[0] * crate::sh::SH_C0 + Vec3::splat(0.5);
    let with = |early_stop, blend| {
        let raster = RasterSettings { early_stop, ..RasterSettings::default() };
        let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
        assert_relative_eq!(r.fragments(&r.pixel(0, 0))[0].alpha, 0.98, epsilon = 1e-4);
        let out = render(&r, &sorted(blend), 1);
        Vec3::from_slice(out.mean.pixel(0, 0)).as_dvec3()
    };
    let weights = [0.98, 0.98 * 0.02, 0.98 * 4e-4, 0.98 * 8e-6];
    let sum = |n: usize| (0..n).map(|i| weights[i] * rgb(i).as_dvec3()).sum::<DVec3>();
    for blend in [Blend::Under, Blend::Over] {
        let stopped = with(true, blend);
        let full = with(false, blend);
        assert!((stopped - sum(2)).abs().max_element() < 1e-5, "{blend:?}: {stopped} vs {}", sum(2));
        assert!((full - sum(4)).abs().max_element() < 1e-5, "{blend:?}: {full} vs {}", sum(4));
        assert!((full - stopped).max_element() > 1e-4, "{blend:?}: the early stop changed nothing");
    }
}
