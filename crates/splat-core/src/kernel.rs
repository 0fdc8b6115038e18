//! The particle response along a ray: a generalized Gaussian kernel with cutoff, alpha clamp
//! and alpha cull (3DGRT; vk_gaussian_splatting defaults).

/// Default cutoff s, in standard deviations, of the bounding ellipsoid of Eq. 2.
///
/// 3 (3DGRT and vk_gaussian_splatting) rather than Sun et al.'s 2√2: at 3σ the degree-2 response
/// is e^−4.5 ≈ 0.0111, so only particles with opacity above 0.35 can still produce an alpha
/// above the 1/255 cull at the cutoff; at 2√2σ the response is e^−4 ≈ 0.0183 and every particle
/// with opacity above 0.21 would be cut while still visible.
pub const DEFAULT_CUTOFF: f32 = 3.0;
/// Default kernel degree n (the classic Gaussian exp(−½ d²)).
pub const DEFAULT_DEGREE: u32 = 2;
/// Largest alpha a single particle can take (3DGS / vk `alphaClamp`), so that no particle is
/// fully opaque and transmittance never reaches exactly zero.
pub const ALPHA_CLAMP: f32 = 0.99;
/// Alphas below this are culled as invisible (3DGS / vk `alphaCull`, one 8-bit step).
pub const ALPHA_CULL: f32 = 1.0 / 255.0;

/// Parameters of the particle response.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelParams {
    /// Kernel degree n in 1..=8; see [`response`].
    pub degree: u32,
    /// Cutoff s in standard deviations (Eq. 2): the ellipsoid outside which a hit is negligible.
    pub cutoff: f32,
    /// Upper clamp of alpha.
    pub alpha_clamp: f32,
    /// Alphas below this are culled.
    pub alpha_cull: f32,
}

impl Default for KernelParams {
    fn default() -> Self {
        Self { degree: DEFAULT_DEGREE, cutoff: DEFAULT_CUTOFF, alpha_clamp: ALPHA_CLAMP, alpha_cull: ALPHA_CULL }
    }
}

impl KernelParams {
    /// Check the parameters, naming the first bad one.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=8).contains(&self.degree) {
            return Err(format!("kernel degree {} is outside 1..=8", self.degree));
        }
        if !(self.cutoff.is_finite() && self.cutoff > 0.0) {
            return Err(format!("cutoff {} must be a positive number of standard deviations", self.cutoff));
        }
        if !(self.alpha_cull >= 0.0 && self.alpha_cull <= self.alpha_clamp && self.alpha_clamp <= 1.0) {
            return Err(format!(
                "alpha cull {} and clamp {} must satisfy 0 <= cull <= clamp <= 1",
                self.alpha_cull, self.alpha_clamp
            ));
        }
        Ok(())
    }

    /// Kernel response at squared Mahalanobis distance d² ([`response`] with this degree).
    pub fn response(&self, d2: f32) -> f32 {
        response(d2, self.degree)
    }

    /// Response on the cutoff ellipsoid, the smallest response a non-negligible hit can have:
    /// exp(−4.5 (s/3)ⁿ), which is e^−4.5 ≈ 0.0111 at the default s = 3 for every degree.
    pub fn response_at_cutoff(&self) -> f32 {
        response(self.cutoff * self.cutoff, self.degree)
    }

    /// The visible extent of a particle of this opacity, in standard deviations: the Mahalanobis
    /// radius beyond which opacity × response < alpha_cull, so [`KernelParams::alpha`] culls
    /// every hit, capped at the cutoff. From exp(−4.5 (d/3)ⁿ) ≥ cull / opacity:
    /// d² ≤ 9 (ln(opacity / cull) / 4.5)^(2/n). It is widened by 10⁻⁵ in the logarithm and 0.1 %
    /// in d² (far more than the f32 error of the response and of d²), so that no hit the kernel
    /// keeps lies outside it; a particle below the cull has extent 0. Bounding a particle by this extent rather than the
    /// cutoff (3DGRT's adaptive bounds) shrinks the boxes of faint particles without changing
    /// a single hit: at opacity 0.05 the extent is 2.26σ, at 0.01 1.37σ.
    pub fn visible_extent(&self, opacity: f32) -> f32 {
        self.visible_radius(opacity).min(self.cutoff)
    }

    /// [`KernelParams::visible_extent`] without the cutoff: the Mahalanobis radius beyond which
    /// the alpha cull takes every hit of a particle of this opacity (infinite without a cull).
    /// The splatting path, which has no cutoff, bounds gsplat's footprint by it.
    pub fn visible_radius(&self, opacity: f32) -> f32 {
        if self.alpha_cull <= 0.0 {
            return f32::INFINITY;
        }
        if opacity.is_nan() || opacity < self.alpha_cull {
            return 0.0;
        }
        // 10⁻⁵ in the exponent covers the f32 rounding of opacity × response (a few ulps, and a
        // response that rounds to 1 near the centre for high degrees).
        let x = ((f64::from(opacity) / f64::from(self.alpha_cull)).ln() + 1e-5) / 4.5;
        let d2 = 9.0 * if self.degree == 2 { x } else { x.powf(2.0 / f64::from(self.degree)) };
        (d2 * 1.001).sqrt() as f32
    }

    /// alpha = opacity × response, `None` when culled, clamped to [`KernelParams::alpha_clamp`].
    pub fn alpha(&self, opacity: f32, response: f32) -> Option<f32> {
        let alpha = opacity * response;
        (alpha >= self.alpha_cull && alpha > 0.0).then_some(alpha.min(self.alpha_clamp))
    }
}

/// Generalized Gaussian kernel of degree n at squared Mahalanobis distance d²:
/// exp(−4.5 (d/3)ⁿ) (3DGRT). Every degree agrees at d = 3 (response e^−4.5), and n = 2 is the
/// classic exp(−½ d²).
pub fn response(d2: f32, degree: u32) -> f32 {
    let u = d2 * (1.0 / 9.0); // (d/3)²
    let un = match degree {
        2 => u,
        4 => u * u,
        8 => (u * u) * (u * u),
        n => u.powf(n as f32 * 0.5),
    };
    (-4.5 * un).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Just inside the visible extent a particle can still be kept; beyond it, never: for every
    /// degree and opacities from the cull to 1, the alpha at the extent (minus the widening) is
    /// at the cull and the alpha just past it is culled.
    #[test]
    fn the_visible_extent_bounds_every_kept_alpha() {
        for degree in [1, 2, 3, 4, 8] {
            let k = KernelParams { degree, ..KernelParams::default() };
            for i in 0..=1000 {
                let opacity = ALPHA_CULL + (1.0 - ALPHA_CULL) * (i as f32 / 1000.0).powi(3);
                let r = k.visible_extent(opacity);
                assert!(r <= k.cutoff && r > 0.0);
                let past = r * r * 1.0001;
                assert!(
                    k.alpha(opacity, k.response(past)).is_none() || past > k.cutoff * k.cutoff,
                    "degree {degree}, opacity {opacity}: kept at d² = {past} beyond r = {r}"
                );
                if r < k.cutoff && opacity > 2.0 * ALPHA_CULL {
                    let inside = r * r / 1.001 * 0.999;
                    assert!(
                        k.alpha(opacity, k.response(inside)).is_some(),
                        "degree {degree}, opacity {opacity}: r = {r} is not tight"
                    );
                }
            }
            assert_eq!(k.visible_extent(ALPHA_CULL * 0.99), 0.0);
        }
        assert_eq!(KernelParams { alpha_cull: 0.0, ..KernelParams::default() }.visible_extent(0.5), DEFAULT_CUTOFF);
    }

    #[test]
    fn degree_two_is_the_classic_gaussian() {
        for d2 in [0.0f32, 0.5, 1.0, 4.0, 9.0] {
            assert_relative_eq!(response(d2, 2), (-0.5 * d2).exp(), max_relative = 1e-6);
        }
    }

    #[test]
    fn every_degree_meets_at_three_sigma() {
        for n in 1..=8 {
            assert_relative_eq!(response(9.0, n), (-4.5f32).exp(), max_relative = 1e-5);
            assert_relative_eq!(response(0.0, n), 1.0);
        }
    }

    #[test]
    fn response_at_default_cutoff_is_documented_value() {
        let k = KernelParams::default();
        assert_relative_eq!(k.response_at_cutoff(), 0.011_108_996, max_relative = 1e-5);
    }

    #[test]
    fn alpha_is_clamped_and_culled() {
        let k = KernelParams::default();
        assert_eq!(k.alpha(1.0, 1.0), Some(ALPHA_CLAMP));
        assert_eq!(k.alpha(0.5, 1.0), Some(0.5));
        assert_eq!(k.alpha(1.0, 0.5 / 255.0), None);
        assert!(KernelParams { degree: 0, ..k }.validate().is_err());
        assert!(KernelParams { cutoff: f32::NAN, ..k }.validate().is_err());
    }
}
