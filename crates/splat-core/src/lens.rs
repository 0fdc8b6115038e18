//! The lens of a camera: how a direction in camera space lands on the image, after COLMAP's
//! camera models (`src/colmap/sensor/models.h`), so that a capture renders through the camera
//! that filmed it without undistorting its images first.
//!
//! A perspective lens maps a camera-space point (x, y, z) to the normalised coordinates
//! (u, v) = (x / z, y / z); an (equidistant) fisheye lens to (u, v) = θ (x, y) / √(x² + y²) with
//! θ = atan2(√(x² + y²), z), the angle from the axis. Both then distort (u, v) by
//! [`Distortion`] and scale to pixels: (f_x (u + du) + c_x, f_y (v + dv) + c_y). The
//! equirectangular lens maps the azimuth and elevation to the whole image instead.
//!
//! | COLMAP model | lens | distortion |
//! |---|---|---|
//! | `SIMPLE_PINHOLE`, `PINHOLE` | [`Lens::Pinhole`] | none |
//! | `SIMPLE_RADIAL` (k), `RADIAL` (k1, k2) | [`Lens::Perspective`] | radial a₁ = k1, a₂ = k2 |
//! | `OPENCV` (k1, k2, p1, p2) | [`Lens::Perspective`] | radial, tangential |
//! | `FULL_OPENCV` (k1, k2, p1, p2, k3, k4, k5, k6) | [`Lens::Perspective`] | rational radial (k4–k6 below the line), tangential |
//! | `SIMPLE_RADIAL_FISHEYE` (k), `RADIAL_FISHEYE` (k1, k2), `OPENCV_FISHEYE` (k1–k4) | [`Lens::Fisheye`] | radial in θ |
//! | `THIN_PRISM_FISHEYE` (k1, k2, p1, p2, k3, k4, sx1, sy1) | [`Lens::Fisheye`] | radial, tangential, thin prism |
//! | `EQUIRECTANGULAR` | [`Lens::Equirectangular`] | none |
//!
//! A pixel's ray inverts the distortion by Newton's method on the analytic Jacobian, as COLMAP's
//! `IterativeUndistortion` does with automatic differentiation (its trust region, at most 100
//! steps), to a step below [`UNDISTORT_TOLERANCE`] in normalised coordinates.

use glam::{DVec2, DVec3};

/// Newton's method stops when a step is shorter than this, in normalised image coordinates
/// (about 1e-9 px at a focal length of 1000 px).
pub const UNDISTORT_TOLERANCE: f64 = 1e-12;
/// Most Newton steps of the undistortion (COLMAP's `kNumIterations`).
pub const UNDISTORT_STEPS: u32 = 100;
/// The step below which the single-precision twin (`lens.wgsl`) stops, relative to
/// max(1, |x|): a few units in the last place of f32.
pub const UNDISTORT_TOLERANCE_F32: f32 = 1e-6;

/// The distortion of normalised coordinates (u, v), r² = u² + v² (the general form of COLMAP's
/// models; each model fills the coefficients it has and leaves the others 0):
///
/// ```text
/// ρ  = (1 + a₁r² + a₂r⁴ + a₃r⁶ + a₄r⁸) / (1 + b₁r² + b₂r⁴ + b₃r⁶) − 1
/// du = u ρ + 2 p₁ u v + p₂ (r² + 2u²) + s₁ r²
/// dv = v ρ + 2 p₂ u v + p₁ (r² + 2v²) + s₂ r²
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    /// a₁…a₄: the radial polynomial (COLMAP's k1, k2, k3, k4; FULL_OPENCV's k1, k2, k3).
    pub radial: [f32; 4],
    /// b₁…b₃: the rational denominator (FULL_OPENCV's k4, k5, k6).
    pub rational: [f32; 3],
    /// p₁, p₂: tangential (decentring) distortion.
    pub tangential: [f32; 2],
    /// s₁, s₂: thin-prism distortion (THIN_PRISM_FISHEYE's sx1, sy1).
    pub prism: [f32; 2],
}

impl Distortion {
    /// Every coefficient, for checks.
    fn coefficients(&self) -> impl Iterator<Item = f32> + '_ {
        self.radial.iter().chain(&self.rational).chain(&self.tangential).chain(&self.prism).copied()
    }

    /// (du, dv) at (u, v), and the Jacobian of (u + du, v + dv) as rows.
    fn apply(&self, x: DVec2) -> (DVec2, [DVec2; 2]) {
        let [a1, a2, a3, a4] = self.radial.map(f64::from);
        let [b1, b2, b3] = self.rational.map(f64::from);
        let [p1, p2] = self.tangential.map(f64::from);
        let [s1, s2] = self.prism.map(f64::from);
        let (u, v) = (x.x, x.y);
        let r2 = u * u + v * v;
        let n = 1.0 + r2 * (a1 + r2 * (a2 + r2 * (a3 + r2 * a4)));
        let d = 1.0 + r2 * (b1 + r2 * (b2 + r2 * b3));
        let dn = a1 + r2 * (2.0 * a2 + r2 * (3.0 * a3 + r2 * 4.0 * a4));
        let dd = b1 + r2 * (2.0 * b2 + r2 * 3.0 * b3);
        let rho = n / d - 1.0;
        // dρ/d(r²)
        let rho_r2 = (dn * d - n * dd) / (d * d);
        let du = u * rho + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u) + s1 * r2;
        let dv = v * rho + 2.0 * p2 * u * v + p1 * (r2 + 2.0 * v * v) + s2 * r2;
        let j = [
            DVec2::new(
                1.0 + rho + 2.0 * u * u * rho_r2 + 2.0 * p1 * v + 6.0 * p2 * u + 2.0 * s1 * u,
                2.0 * u * v * rho_r2 + 2.0 * p1 * u + 2.0 * p2 * v + 2.0 * s1 * v,
            ),
            DVec2::new(
                2.0 * u * v * rho_r2 + 2.0 * p2 * v + 2.0 * p1 * u + 2.0 * s2 * u,
                1.0 + rho + 2.0 * v * v * rho_r2 + 2.0 * p2 * u + 6.0 * p1 * v + 2.0 * s2 * v,
            ),
        ];
        (DVec2::new(du, dv), j)
    }

    /// The distorted coordinates of undistorted (u, v).
    pub fn distort(&self, x: DVec2) -> DVec2 {
        x + self.apply(x).0
    }

    /// The undistorted coordinates whose distortion is `target`: Newton's method from the
    /// target itself with COLMAP's trust region (a step no longer than max(0.1 |x|, 0.1)), and
    /// whether it converged within [`UNDISTORT_STEPS`]; the last iterate either way (as COLMAP
    /// returns it), which far outside the lens's image circle is not a solution.
    pub fn undistort(&self, target: DVec2) -> (DVec2, bool) {
        let mut x = target;
        for _ in 0..UNDISTORT_STEPS {
            let (d, [j0, j1]) = self.apply(x);
            let f = x + d - target;
            let det = j0.x * j1.y - j0.y * j1.x;
            if !(det.abs() > 0.0 && det.is_finite()) {
                return (x, false);
            }
            let mut step = DVec2::new(j1.y * f.x - j0.y * f.y, j0.x * f.y - j1.x * f.x) / det;
            let radius = (0.1 * x.length()).max(0.1);
            if step.length() > radius {
                step *= radius / step.length();
            }
            x -= step;
            if step.length() < UNDISTORT_TOLERANCE {
                return (x, true);
            }
        }
        (x, false)
    }
}

/// How a camera maps directions to its image (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Lens {
    /// The pinhole: (u, v) = (x / z, y / z), undistorted.
    #[default]
    Pinhole,
    /// A perspective lens with distortion.
    Perspective(Distortion),
    /// An equidistant fisheye, r = θ, with distortion; it sees past 90° from the axis.
    Fisheye(Distortion),
    /// The equirectangular (360°) projection of COLMAP's `EQUIRECTANGULAR` model: the azimuth
    /// atan2(x, z) ∈ (−π, π] across the image width from its left edge, the elevation
    /// atan2(−y, √(x² + z²)) down its height from +π/2 (up, −y) at the top.
    Equirectangular,
}

impl Lens {
    /// What it is, in words.
    pub const fn describe(&self) -> &'static str {
        match self {
            Lens::Pinhole => "a pinhole lens",
            Lens::Perspective(_) => "a distorted perspective lens",
            Lens::Fisheye(_) => "a fisheye lens",
            Lens::Equirectangular => "an equirectangular (360°) lens",
        }
    }

    /// Its distortion, if it has one.
    pub fn distortion(&self) -> Option<&Distortion> {
        match self {
            Lens::Perspective(d) | Lens::Fisheye(d) => Some(d),
            Lens::Pinhole | Lens::Equirectangular => None,
        }
    }

    /// Whether a coefficient is not finite.
    pub fn is_finite(&self) -> bool {
        self.distortion().is_none_or(|d| d.coefficients().all(f32::is_finite))
    }

    /// The distorted normalised coordinates of camera-space point `p`, `None` where the lens
    /// does not see it (behind a perspective lens, on the axis behind a fisheye). Not for the
    /// equirectangular lens, which has no normalised coordinates ([`Lens::equirectangular`]).
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        match self {
            Lens::Pinhole | Lens::Perspective(_) if p.z <= 0.0 => None,
            Lens::Pinhole => Some(DVec2::new(p.x / p.z, p.y / p.z)),
            Lens::Perspective(d) => Some(d.distort(DVec2::new(p.x / p.z, p.y / p.z))),
            Lens::Fisheye(d) => {
                let r = p.x.hypot(p.y);
                let theta = r.atan2(p.z);
                if r == 0.0 {
                    return (p.z > 0.0).then_some(DVec2::ZERO);
                }
                Some(d.distort(DVec2::new(p.x, p.y) * (theta / r)))
            }
            Lens::Equirectangular => None,
        }
    }

    /// The camera-space unit direction whose distorted normalised coordinates are `x`, and
    /// whether the undistortion converged. Not for the equirectangular lens.
    pub fn unproject(&self, x: DVec2) -> (DVec3, bool) {
        match self {
            Lens::Pinhole | Lens::Equirectangular => (x.extend(1.0).normalize(), true),
            Lens::Perspective(d) => {
                let (u, converged) = d.undistort(x);
                (u.extend(1.0).normalize(), converged)
            }
            Lens::Fisheye(d) => {
                let (u, converged) = d.undistort(x);
                let theta = u.length();
                let dir = if theta > 0.0 { (u * (theta.sin() / theta)).extend(theta.cos()) } else { DVec3::Z };
                (dir, converged)
            }
        }
    }

    /// The equirectangular direction of the fractional image position `f` = (x / W, y / H).
    pub fn equirectangular(f: DVec2) -> DVec3 {
        let azimuth = 2.0 * std::f64::consts::PI * (f.x - 0.5);
        let elevation = std::f64::consts::PI * (0.5 - f.y);
        DVec3::new(elevation.cos() * azimuth.sin(), -elevation.sin(), elevation.cos() * azimuth.cos())
    }

    /// The fractional image position (x / W, y / H) of an equirectangular direction.
    pub fn equirectangular_position(p: DVec3) -> Option<DVec2> {
        let horizontal = p.x.hypot(p.z);
        if horizontal + p.y.abs() == 0.0 {
            return None;
        }
        let azimuth = p.x.atan2(p.z);
        let elevation = (-p.y).atan2(horizontal);
        Some(DVec2::new(azimuth / (2.0 * std::f64::consts::PI) + 0.5, 0.5 - elevation / std::f64::consts::PI))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distortion() -> Distortion {
        Distortion {
            radial: [-0.28, 0.07, 0.01, -0.002],
            rational: [0.02, -0.01, 0.003],
            tangential: [1e-3, -2e-3],
            prism: [5e-4, -3e-4],
        }
    }

    /// The analytic Jacobian is the derivative of the distortion (central differences).
    #[test]
    fn the_jacobian_is_the_derivative() {
        let d = distortion();
        for x in [DVec2::new(0.3, -0.2), DVec2::new(-0.6, 0.45), DVec2::new(0.01, 0.9)] {
            let (_, j) = d.apply(x);
            let h = 1e-6;
            for (axis, e) in [DVec2::X, DVec2::Y].into_iter().enumerate() {
                let num = (d.distort(x + h * e) - d.distort(x - h * e)) / (2.0 * h);
                assert!((j[0][axis] - num.x).abs() < 1e-7 && (j[1][axis] - num.y).abs() < 1e-7, "{x} {axis}");
            }
        }
    }

    /// Undistortion inverts distortion across the field, for each lens family.
    #[test]
    fn undistortion_inverts_distortion() {
        let d = distortion();
        for u in [-0.7f64, -0.3, 0.0, 0.2, 0.65] {
            for v in [-0.5f64, 0.0, 0.4] {
                let x = DVec2::new(u, v);
                let (back, converged) = d.undistort(d.distort(x));
                assert!(converged && (back - x).length() < 1e-10, "{x}: {back}");
            }
        }
        for lens in [Lens::Perspective(d), Lens::Fisheye(Distortion { radial: [0.05, -0.01, 0.002, 0.0], ..d })] {
            for dir in [DVec3::new(0.3, -0.2, 1.0), DVec3::new(-0.5, 0.1, 0.8), DVec3::new(0.0, 0.0, 1.0)] {
                let (back, converged) = lens.unproject(lens.project(dir).unwrap());
                assert!(converged && (back - dir.normalize()).length() < 1e-9, "{lens:?} {dir}: {back}");
            }
        }
        // A fisheye sees past 90°.
        let fisheye = Lens::Fisheye(Distortion::default());
        let side = DVec3::new(1.0, 0.0, -0.3).normalize();
        assert!((fisheye.unproject(fisheye.project(side).unwrap()).0 - side).length() < 1e-12);
        for f in [DVec2::new(0.1, 0.2), DVec2::new(0.75, 0.9), DVec2::new(0.5, 0.5)] {
            let back = Lens::equirectangular_position(Lens::equirectangular(f)).unwrap();
            assert!((back - f).length() < 1e-12, "{f}: {back}");
        }
    }
}
