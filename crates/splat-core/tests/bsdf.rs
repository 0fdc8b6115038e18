//! The path tracer's BSDFs: the directions a BSDF samples are distributed by the density it
//! evaluates (a χ² goodness-of-fit test in the manner of Mitsuba 3's `ChiSquareTest`), and the
//! test rejects a sampler whose roughness is off by 2 %.

use glam::{Vec2, Vec3};
use splat_core::path::bsdf::Bsdf;
use splat_core::rng::SplitMix64;
use std::f32::consts::PI;

/// Cells in cos θ (equal solid angle) and in φ.
const Z_CELLS: usize = 24;
const PHI_CELLS: usize = 48;
/// Midpoint sub-cells per side when integrating the density over a cell.
const SUB: usize = 12;
/// Samples drawn per test.
const SAMPLES: usize = 2_000_000;

fn cell(w: Vec3) -> usize {
    let z = ((w.z + 1.0) * 0.5 * Z_CELLS as f32).clamp(0.0, Z_CELLS as f32 - 1.0) as usize;
    let phi = w.y.atan2(w.x).rem_euclid(2.0 * PI);
    let p = (phi / (2.0 * PI) * PHI_CELLS as f32).clamp(0.0, PHI_CELLS as f32 - 1.0) as usize;
    z * PHI_CELLS + p
}

/// Upper-tail p-value of χ² with `dof` degrees of freedom (Wilson–Hilferty, accurate for the
/// hundreds of degrees of freedom here).
fn chi2_p_value(chi2: f64, dof: f64) -> f64 {
    let k = 2.0 / (9.0 * dof);
    let z = ((chi2 / dof).cbrt() - (1.0 - k)) / k.sqrt();
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// Complementary error function (Numerical Recipes' erfcc, relative error < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// The χ² p-value of directions drawn by `sampler` against the density `eval` evaluates, for
/// outgoing direction `wo`; absorbed draws are one more cell, expected 1 − ∫p.
fn chi2_test(sampler: &Bsdf, eval: &Bsdf, wo: Vec3) -> f64 {
    let cells = Z_CELLS * PHI_CELLS;
    let mut observed = vec![0.0f64; cells + 1];
    let mut rng = SplitMix64::new(0xC41 ^ (wo.z.to_bits() as u64));
    for _ in 0..SAMPLES {
        let (ul, u) = (rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()));
        match sampler.sample(wo, ul, u) {
            Some(s) if !s.delta => observed[cell(s.wi)] += 1.0,
            _ => observed[cells] += 1.0,
        }
    }
    let mut expected = vec![0.0f64; cells + 1];
    let (dz, dphi) = (2.0 / Z_CELLS as f64, 2.0 * std::f64::consts::PI / PHI_CELLS as f64);
    for (c, e) in expected[..cells].iter_mut().enumerate() {
        let (zi, pi) = (c / PHI_CELLS, c % PHI_CELLS);
        let mut integral = 0.0;
        for a in 0..SUB {
            for b in 0..SUB {
                let z = -1.0 + (zi as f64 + (a as f64 + 0.5) / SUB as f64) * dz;
                let phi = (pi as f64 + (b as f64 + 0.5) / SUB as f64) * dphi;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let wi = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                integral += f64::from(eval.eval(wo, wi).1);
            }
        }
        *e = integral * dz * dphi / (SUB * SUB) as f64 * SAMPLES as f64;
    }
    let total: f64 = expected[..cells].iter().sum();
    expected[cells] = (SAMPLES as f64 - total).max(0.0);
    // Pool the cells expected to get fewer than 5 draws.
    let (mut chi2, mut dof, mut pool_o, mut pool_e) = (0.0, 0usize, 0.0, 0.0);
    for (&o, &e) in observed.iter().zip(&expected) {
        if e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            chi2 += (o - e).powi(2) / e;
            dof += 1;
        }
    }
    if pool_e > 0.0 {
        chi2 += (pool_o - pool_e).powi(2) / pool_e.max(5.0);
        dof += 1;
    }
    chi2_p_value(chi2, (dof - 1) as f64)
}

fn dir(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}

/// The lobes and mixtures tested, with the outgoing elevations.
fn cases() -> Vec<(&'static str, Bsdf)> {
    let grey = Vec3::splat(0.8);
    let (untinted, gold) = (Vec3::ONE, Vec3::new(1.0, 0.78, 0.34));
    // The albedo checks read the red channel: F₀ = 0.3 there, Schlick's Fresnel in full.
    let tinted = Vec3::new(0.3, 0.6, 0.9);
    vec![
        ("lambert", Bsdf::new(1.0, grey, 0.0, untinted, 0.0, 0.0, 1.0)),
        ("conductor r=0.5", Bsdf::new(0.0, grey, 1.0, untinted, 0.0, 0.5, 1.0)),
        ("conductor r=0.8", Bsdf::new(0.0, grey, 1.0, untinted, 0.0, 0.8, 1.0)),
        ("tinted conductor r=0.4", Bsdf::new(0.0, grey, 1.0, tinted, 0.0, 0.4, 1.0)),
        ("glass r=0.5 from outside", Bsdf::new(0.0, grey, 0.0, untinted, 1.0, 0.5, 1.5)),
        ("glass r=0.6 from inside", Bsdf::new(0.0, grey, 0.0, untinted, 1.0, 0.6, 1.0 / 1.5)),
        ("mixture", Bsdf::new(0.3, grey, 0.3, gold, 0.4, 0.55, 1.33)),
        // glTF's dielectric layer over the Lambertian base, F₀ raised from 0.04 to 0.25 so
        // that the layer takes a quarter of the draws or more; rough, then smooth (a delta).
        ("layered lambert r=0.3", Bsdf::new(1.0, grey, 0.0, untinted, 0.0, 0.3, 1.0).with_layer(0.25)),
        ("layered lambert, smooth layer", Bsdf::new(1.0, grey, 0.0, untinted, 0.0, 0.0, 1.0).with_layer(0.25)),
    ]
}

/// Bonferroni: every one of the 18 tests at family-wise level 1 %.
const ALPHA: f64 = 0.01 / 18.0;

#[test]
fn sampled_directions_follow_the_evaluated_density() {
    let mut failures = Vec::new();
    for (name, b) in cases() {
        for theta in [30.0, 75.0] {
            let p = chi2_test(&b, &b, dir(theta));
            eprintln!("{name}, θₒ = {theta}°: p = {p:.4}");
            if p < ALPHA {
                failures.push(format!("{name} at θₒ = {theta}°: p = {p:.2e}"));
            }
        }
    }
    assert!(failures.is_empty(), "χ² rejects: {failures:?}");
}

/// The same test rejects a sampler whose GGX α is 2 % too large (roughness √1.02 times), in
/// every case with a rough conductor or dielectric lobe. (The layered base draws its GGX layer,
/// the conductor's sampler, a quarter of the time at θₒ = 30°: there the error goes unseen,
/// p = 0.13.)
#[test]
fn a_two_percent_roughness_error_is_rejected() {
    let rough = |b: &Bsdf| b.alpha > 0.0 && b.conductor + b.dielectric > 0.0;
    for (name, b) in cases().into_iter().filter(|(_, b)| rough(b)) {
        let wider = Bsdf { alpha: b.alpha * 1.02, ..b };
        let p = chi2_test(&wider, &b, dir(30.0));
        eprintln!("{name} sampled with α × 1.02: p = {p:.2e}");
        assert!(p < ALPHA, "{name}: a 2 % roughness error passes (p = {p})");
    }
}

/// f and the sampling weights describe the same lobe: the directional albedo ∫ f |cos θᵢ| dωᵢ by
/// quadrature of `eval` equals the mean weight f|cos θᵢ|/p of sampled directions; no lobe
/// creates energy (radiance carried across a dielectric is scaled by 1/η², so power is the
/// reflected part plus η² times the transmitted one, at most 1); lossless smooth glass keeps
/// all of it and a nearly smooth conductor nearly all.
#[test]
fn evaluated_and_sampled_albedos_agree() {
    // (albedo, power): power weights transmitted directions by η².
    let albedo_by_quadrature = |b: &Bsdf, wo: Vec3| {
        let (nz, np) = (400, 200);
        let (mut sum, mut power) = (0.0f64, 0.0f64);
        for i in 0..nz {
            for j in 0..np {
                let z = -1.0 + (i as f64 + 0.5) / nz as f64 * 2.0;
                let phi = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                let r = (1.0 - z * z).sqrt();
                let wi = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                let f = f64::from(b.eval(wo, wi).0.x);
                sum += f;
                power += if z < 0.0 { f * f64::from(b.eta * b.eta) } else { f };
            }
        }
        let cell = 4.0 * std::f64::consts::PI / (nz * np) as f64;
        (sum * cell, power * cell)
    };
    let albedo_by_sampling = |b: &Bsdf, wo: Vec3| {
        let mut rng = SplitMix64::new(11);
        let n = 400_000;
        let sum: f64 = (0..n)
            .filter_map(|_| b.sample(wo, rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32())))
            .map(|s| f64::from(s.weight.x))
            .sum();
        sum / n as f64
    };
    for (name, b) in cases() {
        let wo = dir(40.0);
        let ((q, power), s) = (albedo_by_quadrature(&b, wo), albedo_by_sampling(&b, wo));
        // A smooth layer's mirror reflection, F(ωₒ.z) of the base's weight, is a delta that
        // quadrature of `eval` does not see.
        let delta = if b.alpha == 0.0 && b.layer_f0 > 0.0 {
            f64::from(b.diffuse * splat_core::mesh::schlick(Vec3::splat(b.layer_f0), wo.z).x)
        } else {
            0.0
        };
        let (q, power) = (q + delta, power + delta);
        eprintln!("{name}: albedo {q:.4} by quadrature, {s:.4} by sampling; power {power:.4}");
        assert!((q - s).abs() < 0.01 * q.max(1.0), "{name}: {q} by quadrature, {s} by sampling");
        assert!(power <= 1.0 + 1e-3, "{name} creates energy: {power}");
    }
    let smooth_glass = Bsdf::new(0.0, Vec3::ONE, 0.0, Vec3::ONE, 1.0, 0.0, 1.5);
    let mut rng = SplitMix64::new(3);
    let mean: f64 = (0..10_000)
        .filter_map(|_| smooth_glass.sample(dir(50.0), rng.next_f32(), Vec2::new(rng.next_f32(), 0.5)))
        .map(|s| f64::from(s.weight.x) * if s.wi.z < 0.0 { 1.5f64.powi(2) } else { 1.0 })
        .sum::<f64>()
        / 10_000.0;
    assert!((mean - 1.0).abs() < 1e-6, "smooth glass loses energy: {mean}");
    let near_mirror = Bsdf::new(0.0, Vec3::ONE, 1.0, Vec3::ONE, 0.0, 0.05, 1.0);
    assert!(albedo_by_sampling(&near_mirror, dir(30.0)) > 0.99);
}
