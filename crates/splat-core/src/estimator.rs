//! The stochastic binary-opacity estimator (Sun et al. §3.3, Eqs. 4–6) as a pure function of
//! the acceptance outcomes, and exact expectations by enumerating every outcome.
//!
//! Random numbers are not drawn here: the estimator takes the outcome α̂ᵢ ∈ {0, 1} of each hit,
//! so that its expectation can be computed exactly and tests can prove it equals Eq. 3.

use crate::composite::ShadedHit;
use glam::{DVec3, Vec3};

/// Eq. 6: among hits in any order (e.g. BVH order), the index of the closest accepted one,
/// ties broken by particle index as in [`crate::composite::sort_front_to_back`].
pub fn closest_accepted(hits: &[ShadedHit], accepted: &[bool]) -> Option<usize> {
    hits.iter()
        .zip(accepted)
        .enumerate()
        .filter(|(_, (_, a))| **a)
        .min_by(|(_, (a, _)), (_, (b, _))| a.t.total_cmp(&b.t).then(a.index.cmp(&b.index)))
        .map(|(i, _)| i)
}

/// The estimate L̂ of one outcome (Eq. 6): the colour of the closest accepted hit, or the
/// background when none is accepted (the background term T̂_{M+1} × background of Eq. 5).
pub fn binary_opacity_estimate(hits: &[ShadedHit], accepted: &[bool], background: Vec3) -> DVec3 {
    closest_accepted(hits, accepted).map_or(background, |i| hits[i].color).as_dvec3()
}

/// Exact expectation of an estimator over the 2^M outcomes of independent α̂ᵢ ~ Bernoulli(αᵢ)
/// (Eq. 4): Σ over outcomes of P(outcome) × estimate(outcome). M is limited to 24.
pub fn expectation_by_enumeration(hits: &[ShadedHit], estimate: impl Fn(&[bool]) -> DVec3) -> DVec3 {
    let m = hits.len();
    assert!(m <= 24, "enumerating 2^{m} outcomes is too many");
    let mut accepted = vec![false; m];
    let mut sum = DVec3::ZERO;
    for mask in 0u32..(1 << m) {
        let mut p = 1.0f64;
        for (i, (a, hit)) in accepted.iter_mut().zip(hits).enumerate() {
            *a = mask >> i & 1 == 1;
            let alpha = f64::from(hit.alpha);
            p *= if *a { alpha } else { 1.0 - alpha };
        }
        if p > 0.0 {
            sum += p * estimate(&accepted);
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_accepted_ignores_list_order() {
        let h = |t: f32, index: u32| ShadedHit { t, alpha: 0.5, color: Vec3::splat(t), normal: Vec3::Z, index };
        let hits = [h(3.0, 0), h(1.0, 1), h(2.0, 2)];
        assert_eq!(closest_accepted(&hits, &[true, false, true]), Some(2));
        assert_eq!(closest_accepted(&hits, &[true, true, true]), Some(1));
        assert_eq!(closest_accepted(&hits, &[false; 3]), None);
    }
}
