//! The screen-space filter a trainer convolves every projected Gaussian with. It is part of what
//! a capture means: the optimiser fitted the particles through it, so a capture renders as its
//! trainer renders it only through the same filter.
//!
//! Each filter adds s I to the projected 2D covariance Σ₂ (px²), and two of them also scale the
//! opacity by the compensation ρ that keeps the splat's integral:
//!
//! ```text
//! Σ′ = Σ₂ + s I,    o′ = ρ o,    ρ = √(det Σ₂ / det Σ′)   (ρ = 1 for the 3DGS dilation)
//! ```
//!
//! | filter | s (px²) | ρ | trainer |
//! |---|---|---|---|
//! | [`ScreenFilter::Dilation`] | 0.3 | 1 | 3DGS (Kerbl et al. 2023), the INRIA rasterizer |
//! | [`ScreenFilter::Antialiased`] | 0.3 | √(det Σ₂ / det Σ′) | gsplat's `antialiased` mode |
//! | [`ScreenFilter::Mip`] | 0.1 | √(det Σ₂ / det Σ′) | Mip-Splatting's 2D Mip filter (Yu et al. 2024 §5.2) |
//!
//! Only the splatting renderers project a Gaussian to the screen, so only they apply it; the
//! ray tracers render the particles themselves.

/// The 3DGS low-pass dilation s, px²: "every Gaussian should be at least one pixel wide".
pub const DILATION: f32 = 0.3;
/// Mip-Splatting's 2D Mip filter s, px² (its `kernel_size`, 0.1 in every published run): a
/// Gaussian approximation of the one-pixel box filter.
pub const MIP_FILTER: f32 = 0.1;

/// The screen-space filter of a capture (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ScreenFilter {
    /// 3DGS: Σ′ = Σ₂ + 0.3 I, the opacity unchanged. Captures of the INRIA trainer and most
    /// others; the default.
    #[default]
    Dilation,
    /// gsplat's `antialiased` rasterize mode (nerfstudio's `rasterize_mode: antialiased`; the
    /// `SplatRenderMode: mip` of gsplat's and Brush's `.ply` files): Σ′ = Σ₂ + 0.3 I with the
    /// opacity × √(det Σ₂ / det Σ′).
    Antialiased,
    /// Mip-Splatting's 2D Mip filter: Σ′ = Σ₂ + 0.1 I with the opacity × √(det Σ₂ / det Σ′).
    /// A Mip-Splatting capture also carries its 3D smoothing filter (`filter_3D`), which the
    /// reader folds into the particles.
    Mip,
}

impl ScreenFilter {
    /// Every filter.
    pub const ALL: [ScreenFilter; 3] = [ScreenFilter::Dilation, ScreenFilter::Antialiased, ScreenFilter::Mip];

    /// The variance s added to Σ₂, px².
    pub const fn variance(self) -> f32 {
        match self {
            ScreenFilter::Dilation | ScreenFilter::Antialiased => DILATION,
            ScreenFilter::Mip => MIP_FILTER,
        }
    }

    /// Whether the opacity is scaled by ρ = √(det Σ₂ / det Σ′).
    pub const fn compensates(self) -> bool {
        !matches!(self, ScreenFilter::Dilation)
    }

    /// The filtered covariance Σ′ = Σ₂ + s I as (a, b, c) = (Σ′ₓₓ, Σ′ₓᵧ, Σ′ᵧᵧ), and the
    /// opacity factor ρ: 1 for the dilation, else √(det Σ₂ / det Σ′), 0 where Σ₂ is degenerate
    /// (det Σ₂ ≤ 0, as both trainers set it).
    #[inline]
    pub fn apply(self, a: f32, b: f32, c: f32) -> ([f32; 3], f32) {
        let s = self.variance();
        let filtered = [a + s, b, c + s];
        if !self.compensates() {
            return (filtered, 1.0);
        }
        let det = a * c - b * b;
        let det_filtered = filtered[0] * filtered[2] - b * b;
        let rho = if det > 0.0 && det_filtered > 0.0 { (det / det_filtered).sqrt() } else { 0.0 };
        (filtered, rho)
    }

    /// Its name on the command line and in messages.
    pub const fn name(self) -> &'static str {
        match self {
            ScreenFilter::Dilation => "3dgs",
            ScreenFilter::Antialiased => "antialiased",
            ScreenFilter::Mip => "mip",
        }
    }

    /// What it is, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            ScreenFilter::Dilation => "3DGS's 0.3 px² dilation",
            ScreenFilter::Antialiased => {
                "gsplat's antialiased mode, Brush's SplatRenderMode mip (0.3 px², opacity compensated)"
            }
            ScreenFilter::Mip => "Mip-Splatting's 2D Mip filter (0.1 px², opacity compensated)",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The compensation keeps a splat's integral: o′ · 2π √det Σ′ = o · 2π √det Σ₂ (the area
    /// of a 2D Gaussian is 2π √det Σ), for a round, an elongated and a sub-pixel splat.
    #[test]
    fn the_compensation_keeps_the_integral() {
        for (a, b, c) in [(4.0f32, 0.0, 4.0), (9.0, 2.5, 1.2), (0.05, 0.01, 0.02)] {
            for filter in [ScreenFilter::Antialiased, ScreenFilter::Mip] {
                let ([fa, fb, fc], rho) = filter.apply(a, b, c);
                assert_eq!([fa, fb, fc], [a + filter.variance(), b, c + filter.variance()]);
                let area = |a: f32, b: f32, c: f32| (a * c - b * b).sqrt();
                let kept = rho * area(fa, fb, fc) / area(a, b, c);
                assert!((kept - 1.0).abs() < 1e-5, "{filter:?} ({a}, {b}, {c}): ratio {kept}");
            }
            assert_eq!(ScreenFilter::Dilation.apply(a, b, c).1, 1.0);
        }
        assert_eq!(ScreenFilter::Mip.apply(1.0, 1.0, 1.0).1, 0.0, "a degenerate Σ₂ vanishes");
    }
}
