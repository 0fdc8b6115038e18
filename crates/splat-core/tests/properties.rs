//! Property tests of the oracle: compositing (Eq. 3) and the unbiasedness of the stochastic
//! binary-opacity estimator (Eqs. 4–6), checked exactly by enumerating every outcome.

use approx::assert_relative_eq;
use glam::{DVec3, Vec3};
use proptest::prelude::*;
use splat_core::composite::{ShadedHit, composite, sort_front_to_back};
use splat_core::estimator::{binary_opacity_estimate, closest_accepted, expectation_by_enumeration};

/// A hit with bounded, finite fields (no default float strategies: they produce NaN and Inf).
fn hit(index: u32) -> impl Strategy<Value = ShadedHit> {
    (0.01f32..100.0, 0.0f32..=0.99, 0.0f32..1.0, 0.0f32..1.0, 0.0f32..1.0)
        .prop_map(move |(t, alpha, r, g, b)| ShadedHit { t, alpha, color: Vec3::new(r, g, b), normal: Vec3::Z, index })
}

/// 1..=max hits with distinct indices, in random (unsorted, "BVH") order.
fn hits(max: usize) -> impl Strategy<Value = Vec<ShadedHit>> {
    (1..=max).prop_flat_map(|m| (0..m as u32).map(hit).collect::<Vec<_>>())
}

fn background() -> impl Strategy<Value = Vec3> {
    (0.0f32..1.0, 0.0f32..1.0, 0.0f32..1.0).prop_map(|(r, g, b)| Vec3::new(r, g, b))
}

/// Eq. 3 over a background, on a sorted copy.
fn eq3(hits: &[ShadedHit], bg: Vec3) -> DVec3 {
    let mut sorted = hits.to_vec();
    sort_front_to_back(&mut sorted);
    composite(&sorted, 0.7).color_over(bg)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// T_{M+1} = Π (1 − αᵢ) whatever order the hits are composited in.
    #[test]
    fn transmittance_is_the_product_in_any_order(mut hs in hits(16), seed in any::<u64>()) {
        let product: f64 = hs.iter().map(|h| 1.0 - f64::from(h.alpha)).product();
        let n = hs.len();
        for i in 0..n {
            hs.swap(i, (seed.rotate_left(i as u32) % n as u64) as usize);
        }
        assert_relative_eq!(composite(&hs, 0.7).transmittance, product, max_relative = 1e-12);
    }

    /// L is affine in each αᵢ alone: L(α) = L(0) + α (L(1) − L(0)) (the premise of §3.3).
    #[test]
    fn radiance_is_linear_in_each_alpha(hs in hits(10), pick in any::<prop::sample::Index>(), a in 0.0f32..1.0) {
        let i = pick.index(hs.len());
        let with = |alpha: f32| {
            let mut h = hs.clone();
            h[i].alpha = alpha;
            eq3(&h, Vec3::new(0.2, 0.5, 0.9))
        };
        let (l0, l1, la) = (with(0.0), with(1.0), with(a));
        let expected = l0 + f64::from(a) * (l1 - l0);
        prop_assert!((la - expected).abs().max_element() < 1e-6, "{la} vs {expected}");
    }

    /// Theorem of §3.3: E[L̂] over all 2^M outcomes of α̂ᵢ ~ Bernoulli(αᵢ), with L̂ the colour of
    /// the closest accepted hit (Eq. 6) found in unsorted order, equals Eq. 3 to 1e-9.
    #[test]
    fn stochastic_binary_opacity_is_unbiased(hs in hits(12), bg in background()) {
        let expectation = expectation_by_enumeration(&hs, |acc| binary_opacity_estimate(&hs, acc, bg));
        let exact = eq3(&hs, bg);
        prop_assert!((expectation - exact).abs().max_element() < 1e-9, "{expectation} vs {exact}");
    }

    /// Eq. 5 taken literally (composite the binary opacities in sorted order) is the same
    /// estimator as Eq. 6 for every single outcome, not only in expectation.
    #[test]
    fn eq5_and_eq6_agree_outcome_by_outcome(hs in hits(12), mask in any::<u32>(), bg in background()) {
        let accepted: Vec<bool> = (0..hs.len()).map(|i| mask >> i & 1 == 1).collect();
        let binary: Vec<ShadedHit> = hs.iter().zip(&accepted)
            .map(|(h, &a)| ShadedHit { alpha: if a { 1.0 } else { 0.0 }, ..*h })
            .collect();
        let eq5 = eq3(&binary, bg);
        let eq6 = binary_opacity_estimate(&hs, &accepted, bg);
        prop_assert!((eq5 - eq6).abs().max_element() < 1e-12);
    }
}

/// The enumeration check can fail: taking the *first accepted hit in list order* (forgetting
/// that BVH order is not depth order) is biased, and the same comparison rejects it.
#[test]
fn enumeration_rejects_first_accepted_in_list_order() {
    let h =
        |t: f32, alpha: f32, c: f32, index: u32| ShadedHit { t, alpha, color: Vec3::splat(c), normal: Vec3::Z, index };
    let hs = [h(3.0, 0.6, 0.9, 0), h(1.0, 0.5, 0.1, 1), h(2.0, 0.4, 0.5, 2)];
    let bg = Vec3::ZERO;
    let biased =
        expectation_by_enumeration(&hs, |acc| acc.iter().position(|&a| a).map_or(bg, |i| hs[i].color).as_dvec3());
    let unbiased = expectation_by_enumeration(&hs, |acc| binary_opacity_estimate(&hs, acc, bg));
    let exact = eq3(&hs, bg);
    assert!((unbiased - exact).abs().max_element() < 1e-12);
    assert!((biased - exact).abs().max_element() > 0.05, "biased {biased} vs exact {exact}");
    // And the closest accepted hit is the one at t = 1 whenever it is accepted.
    assert_eq!(closest_accepted(&hs, &[true, true, true]), Some(1));
}
