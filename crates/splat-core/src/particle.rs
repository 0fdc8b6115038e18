//! Gaussian particles: mean, scale, rotation, opacity and SH colour (Sun et al. §3.1, Eq. 1).
//!
//! The covariance follows 3DGS training, Σ = R S² Rᵀ with R the rotation matrix of the unit
//! quaternion (w, x, y, z). Eq. 1 of Sun et al. writes Σ = Rᵀ S² R, the transposed convention;
//! real assets are trained with 3DGS, so that is the one used here.

use crate::filter::ScreenFilter;
use crate::trainer::Trained;
use glam::{Mat3, Quat, Vec3};
use thiserror::Error;

/// Largest supported SH degree.
pub const SH_MAX_DEGREE: u8 = 3;
/// Number of SH coefficients per colour channel at degree 3.
pub const SH_MAX_COEFFS: usize = 16;

/// Number of SH coefficients per colour channel for a degree: (degree + 1)².
pub const fn sh_coeff_count(degree: u8) -> usize {
    (degree as usize + 1) * (degree as usize + 1)
}

/// One 3D Gaussian particle, with the activations of 3DGS already applied.
#[derive(Clone, Debug, PartialEq)]
pub struct Particle {
    /// Mean μ in world space.
    pub mean: Vec3,
    /// Standard deviations along the particle's local axes (linear, not log), all > 0.
    pub scale: Vec3,
    /// Unit quaternion; its rotation matrix is R in Σ = R S² Rᵀ.
    pub rotation: Quat,
    /// Opacity in [0, 1] (after the sigmoid).
    pub opacity: f32,
    /// SH coefficients, RGB per entry, `sh[0]` is the DC term. Entries past the scene's degree are 0.
    pub sh: Sh,
}

/// The SH coefficients of one particle, stored as the particle needs them: the DC term alone
/// (inline, 16 bytes) when bands 1–3 are all zero — every particle of a degree-0 scene — else all
/// 16 on the heap. Reading any index 0..16 works either way (absent coefficients are zero);
/// writing a higher band moves a DC-only particle to the full form.
#[derive(Clone, Debug)]
pub enum Sh {
    /// Only the DC term; bands 1–3 are zero.
    Dc(Vec3),
    /// All 16 coefficients.
    Bands(Box<[Vec3; SH_MAX_COEFFS]>),
}

impl Sh {
    /// The compact form of `coefficients`: [`Sh::Dc`] when bands 1–3 are zero.
    pub fn from_array(coefficients: [Vec3; SH_MAX_COEFFS]) -> Self {
        if coefficients[1..].iter().all(|c| *c == Vec3::ZERO) {
            Self::Dc(coefficients[0])
        } else {
            Self::Bands(Box::new(coefficients))
        }
    }

    /// The stored coefficients: 1 (DC only) or 16; those not stored are zero.
    pub fn as_slice(&self) -> &[Vec3] {
        match self {
            Self::Dc(dc) => std::slice::from_ref(dc),
            Self::Bands(all) => &all[..],
        }
    }

    /// All 16 coefficients.
    pub fn to_array(&self) -> [Vec3; SH_MAX_COEFFS] {
        match self {
            Self::Dc(dc) => {
                let mut all = [Vec3::ZERO; SH_MAX_COEFFS];
                all[0] = *dc;
                all
            }
            Self::Bands(all) => **all,
        }
    }

    /// Zero the coefficients from index `from` on (dropping SH bands), compacting when only the
    /// DC term is left.
    pub fn truncate(&mut self, from: usize) {
        if let Self::Bands(all) = self {
            all[from.min(SH_MAX_COEFFS)..].fill(Vec3::ZERO);
            if from <= 1 || all[1..].iter().all(|c| *c == Vec3::ZERO) {
                *self = Self::Dc(all[0]);
            }
        }
    }
}

impl Default for Sh {
    fn default() -> Self {
        Self::Dc(Vec3::ZERO)
    }
}

impl From<[Vec3; SH_MAX_COEFFS]> for Sh {
    fn from(coefficients: [Vec3; SH_MAX_COEFFS]) -> Self {
        Self::from_array(coefficients)
    }
}

impl PartialEq for Sh {
    /// Equal coefficients, whichever form holds them.
    fn eq(&self, other: &Self) -> bool {
        self.to_array() == other.to_array()
    }
}

/// Zero, for reading a coefficient a DC-only particle does not store.
const ZERO: Vec3 = Vec3::ZERO;

impl std::ops::Index<usize> for Sh {
    type Output = Vec3;

    fn index(&self, k: usize) -> &Vec3 {
        match self {
            Self::Dc(dc) if k == 0 => dc,
            Self::Dc(_) => {
                assert!(k < SH_MAX_COEFFS, "SH index {k} out of range 0..16");
                &ZERO
            }
            Self::Bands(all) => &all[k],
        }
    }
}

impl std::ops::IndexMut<usize> for Sh {
    fn index_mut(&mut self, k: usize) -> &mut Vec3 {
        if let (Self::Dc(dc), 1..) = (&*self, k) {
            let mut all = [Vec3::ZERO; SH_MAX_COEFFS];
            all[0] = *dc;
            *self = Self::Bands(Box::new(all));
        }
        match self {
            Self::Dc(dc) => dc,
            Self::Bands(all) => &mut all[k],
        }
    }
}

/// Why a particle is not a valid Gaussian.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum ParticleError {
    /// A component is NaN or infinite.
    #[error("{field} is not finite ({value})")]
    NonFinite {
        /// The offending field.
        field: &'static str,
        /// Its value.
        value: f32,
    },
    /// A scale is zero, negative, or so small that 1/scale overflows.
    #[error("scale along axis {axis} is {value}: scales must be positive with a finite inverse")]
    BadScale {
        /// Local axis 0, 1 or 2.
        axis: usize,
        /// The scale.
        value: f32,
    },
    /// The quaternion has zero length and defines no rotation.
    #[error("rotation quaternion has zero length")]
    ZeroQuaternion,
    /// The quaternion is not of unit length (use [`Particle::new`], which normalises it).
    #[error("rotation quaternion has length {0}, expected 1")]
    NotUnitQuaternion(f32),
    /// Opacity outside [0, 1].
    #[error("opacity {0} is outside [0, 1]")]
    Opacity(f32),
}

impl Particle {
    /// A particle with colour given as SH degree 0 from a display RGB colour (inverse of Eq. `sh`).
    pub fn with_rgb(mean: Vec3, scale: Vec3, rotation: Quat, opacity: f32, rgb: Vec3) -> Self {
        Self { mean, scale, rotation, opacity, sh: Sh::Dc(crate::sh::rgb_to_dc(rgb)) }
    }

    /// Build a particle from raw parts, normalising the quaternion and validating every field.
    pub fn new(
        mean: Vec3,
        scale: Vec3,
        rotation: Quat,
        opacity: f32,
        sh: [Vec3; SH_MAX_COEFFS],
    ) -> Result<Self, ParticleError> {
        let p = Self { mean, scale, rotation: normalize_quat(rotation)?, opacity, sh: Sh::from_array(sh) };
        p.validate()?;
        Ok(p)
    }

    /// Whether it is a 2D Gaussian as the readers make one: its third scale exactly
    /// [`SURFEL_THICKNESS`] × the larger of the other two.
    pub fn is_surfel(&self) -> bool {
        self.scale.z == surfel_thickness(self.scale.x, self.scale.y)
    }

    /// Check that the particle is a finite, non-degenerate Gaussian with a unit quaternion.
    pub fn validate(&self) -> Result<(), ParticleError> {
        let vectors = [("mean", self.mean), ("scale", self.scale)];
        for (field, v) in vectors {
            for value in v.to_array() {
                if !value.is_finite() {
                    return Err(ParticleError::NonFinite { field, value });
                }
            }
        }
        for value in self.sh.as_slice().iter().flat_map(|c| c.to_array()) {
            if !value.is_finite() {
                return Err(ParticleError::NonFinite { field: "sh", value });
            }
        }
        for value in self.rotation.to_array() {
            if !value.is_finite() {
                return Err(ParticleError::NonFinite { field: "rotation", value });
            }
        }
        if !self.opacity.is_finite() {
            return Err(ParticleError::NonFinite { field: "opacity", value: self.opacity });
        }
        for (axis, value) in self.scale.to_array().into_iter().enumerate() {
            if !(value > 0.0 && (1.0 / (value * value)).is_finite()) {
                return Err(ParticleError::BadScale { axis, value });
            }
        }
        if !(0.0..=1.0).contains(&self.opacity) {
            return Err(ParticleError::Opacity(self.opacity));
        }
        if (self.rotation.length() - 1.0).abs() > 1e-3 {
            return Err(ParticleError::NotUnitQuaternion(self.rotation.length()));
        }
        Ok(())
    }

    /// Rotation matrix R of the quaternion (the 3DGS `build_rotation`).
    pub fn rotation_matrix(&self) -> Mat3 {
        Mat3::from_quat(self.rotation)
    }

    /// Covariance Σ = R S² Rᵀ.
    pub fn covariance(&self) -> Mat3 {
        let r = self.rotation_matrix();
        r * Mat3::from_diagonal(self.scale * self.scale) * r.transpose()
    }

    /// Inverse covariance Σ⁻¹ = R S⁻² Rᵀ (exact, without a general matrix inverse).
    pub fn covariance_inverse(&self) -> Mat3 {
        let r = self.rotation_matrix();
        r * Mat3::from_diagonal((self.scale * self.scale).recip()) * r.transpose()
    }

    /// Canonical transform M = S⁻¹ Rᵀ: x ↦ M (x − μ) maps the Gaussian to the unit one, so that
    /// (x − μ)ᵀ Σ⁻¹ (x − μ) = ‖M (x − μ)‖² (Eq. 2).
    pub fn canonical_transform(&self) -> Mat3 {
        Mat3::from_diagonal(self.scale.recip()) * self.rotation_matrix().transpose()
    }

    /// Axis-aligned box of the ellipsoid ‖M (x − μ)‖ ≤ s (Eq. 2): the exact box, half-extent
    /// s √Σᵢᵢ per axis, which is tighter than the paper's rotate-and-expand box.
    pub fn aabb(&self, cutoff: f32) -> Aabb {
        let cov = self.covariance();
        let diag = Vec3::new(cov.x_axis.x, cov.y_axis.y, cov.z_axis.z).max(Vec3::ZERO);
        let half = cutoff * Vec3::new(diag.x.sqrt(), diag.y.sqrt(), diag.z.sqrt());
        Aabb { min: self.mean - half, max: self.mean + half }
    }
}

/// Normalise a quaternion, refusing one of zero (or non-finite) length.
pub fn normalize_quat(q: Quat) -> Result<Quat, ParticleError> {
    let v = glam::Vec4::from(q);
    let len = v.length();
    if !len.is_finite() {
        return Err(ParticleError::NonFinite { field: "rotation", value: len });
    }
    if len < 1e-12 {
        return Err(ParticleError::ZeroQuaternion);
    }
    Ok(Quat::from_vec4(v / len))
}

/// Bytes of a particle in its array, and of the SH bands it holds on the heap ([`Sh::Bands`]).
const PARTICLE_BYTES: usize = std::mem::size_of::<Particle>();
const BANDS_BYTES: usize = std::mem::size_of::<[Vec3; SH_MAX_COEFFS]>();

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (min = +∞, max = −∞), the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb { min: Vec3::INFINITY, max: Vec3::NEG_INFINITY };

    /// Smallest box containing both.
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb { min: self.min.min(other.min), max: self.max.max(other.max) }
    }

    /// Whether the box contains no point.
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The box grown by 10⁻⁴ of its size plus 10⁻⁶, so that the f32 rounding of a hit test
    /// cannot place a hit just outside it (BVH boxes and the renderer's tile cull).
    pub fn padded(&self) -> Aabb {
        let pad = 1e-4 * (self.max - self.min).max(Vec3::splat(1e-6)) + Vec3::splat(1e-6);
        Aabb { min: self.min - pad, max: self.max + pad }
    }

    /// Centre of the box.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// The eight corners.
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// The third scale of a 2D Gaussian (a 2DGS surfel, Huang et al. 2024), relative to its larger
/// in-plane scale. Along any ray that does not graze the surfel's plane, a 3D Gaussian this flat
/// responds most where the ray crosses the plane, with the in-plane Gaussian's value there: its
/// squared Mahalanobis distance of closest approach is the surfel's ray–splat intersection
/// (2DGS §4.2) to a relative O(ε² cot² θ), θ the ray's angle to the plane. So every renderer
/// that evaluates 3D Gaussians along rays renders surfels through the surfel equation, and the
/// readers give 2DGS captures this thickness. Small enough to be invisible, large enough that
/// the canonical transform (1/ε) stays well inside f32.
pub const SURFEL_THICKNESS: f32 = 1e-5;

/// The third scale the readers give a surfel of in-plane scales `s0`, `s1`:
/// [`SURFEL_THICKNESS`] × the larger.
pub fn surfel_thickness(s0: f32, s1: f32) -> f32 {
    SURFEL_THICKNESS * s0.max(s1)
}

/// A set of particles sharing one SH degree and one screen-space filter.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// The particles.
    pub particles: Vec<Particle>,
    /// SH degree 0..=3 used for every particle's colour.
    pub sh_degree: u8,
    /// The screen-space filter the capture was trained with, which the splatting renderers
    /// apply ([`ScreenFilter`]; a file's mode, or a front end's override).
    pub screen_filter: ScreenFilter,
    /// The renderer, kernel, near plane and background the capture's file or its run's folder
    /// says its trainer drew it with, where they say ([`Trained`]: a trainer's checkpoint, a
    /// run's config), which front ends render it with where the user chose no preset.
    pub trained: Option<Trained>,
}

impl Scene {
    /// A scene of 3DGS particles (the 3DGS dilation).
    pub fn new(particles: Vec<Particle>, sh_degree: u8) -> Self {
        Self { particles, sh_degree, screen_filter: ScreenFilter::Dilation, trained: None }
    }

    /// Whether every particle is a 2D Gaussian ([`Particle::is_surfel`]): a 2DGS capture, which
    /// the writers record as one where the format can.
    pub fn is_surfels(&self) -> bool {
        !self.particles.is_empty() && self.particles.iter().all(Particle::is_surfel)
    }

    /// Bytes the scene holds on the heap: its particle array (at its capacity) and the SH
    /// bands of the particles that have them.
    pub fn heap_bytes(&self) -> usize {
        let bands = self.particles.iter().filter(|p| matches!(p.sh, Sh::Bands(_))).count();
        self.particles.capacity() * PARTICLE_BYTES + bands * BANDS_BYTES
    }

    /// What [`Scene::heap_bytes`] will measure of `count` particles read at SH degree
    /// `sh_degree` (each with bands above degree 0), for a reader to check before it reads.
    pub fn bytes_for(count: u64, sh_degree: u8) -> u64 {
        let bands = if sh_degree > 0 { BANDS_BYTES } else { 0 };
        count.saturating_mul((PARTICLE_BYTES + bands) as u64)
    }

    /// Box of all particle means.
    pub fn mean_bounds(&self) -> Aabb {
        self.particles.iter().fold(Aabb::EMPTY, |b, p| b.union(Aabb { min: p.mean, max: p.mean }))
    }

    /// Box of the central part of the scene: per axis, the `q` and `1 − q` quantiles of the
    /// means. Real captures have far floaters; framing a camera on this box ignores them.
    pub fn robust_bounds(&self, q: f32) -> Aabb {
        if self.particles.is_empty() {
            return Aabb::EMPTY;
        }
        let mut axes: [Vec<f32>; 3] = Default::default();
        for p in &self.particles {
            for (axis, v) in axes.iter_mut().zip(p.mean.to_array()) {
                axis.push(v);
            }
        }
        let n = self.particles.len();
        let lo = ((q.clamp(0.0, 0.5) * (n - 1) as f32).round() as usize).min(n - 1);
        let hi = n - 1 - lo;
        let mut min = [0.0; 3];
        let mut max = [0.0; 3];
        for (k, axis) in axes.iter_mut().enumerate() {
            axis.sort_by(f32::total_cmp);
            min[k] = axis[lo];
            max[k] = axis[hi];
        }
        Aabb { min: Vec3::from(min), max: Vec3::from(max) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sh_stores_the_dc_term_alone_until_a_band_is_set() {
        let mut coefficients = [Vec3::ZERO; SH_MAX_COEFFS];
        coefficients[0] = Vec3::new(0.1, 0.2, 0.3);
        let mut sh = Sh::from_array(coefficients);
        assert!(matches!(sh, Sh::Dc(_)));
        assert_eq!(sh.as_slice().len(), 1);
        assert_eq!(sh[15], Vec3::ZERO);
        sh[5] = Vec3::ONE;
        assert!(matches!(sh, Sh::Bands(_)));
        assert_eq!((sh[0], sh[5], sh.as_slice().len()), (coefficients[0], Vec3::ONE, 16));
        // Equality looks at the coefficients, not the form.
        let mut full = coefficients;
        full[5] = Vec3::ONE;
        assert_eq!(sh, Sh::Bands(Box::new(full)));
        sh.truncate(4);
        assert!(matches!(sh, Sh::Dc(_)), "only the DC term is left");
        assert_eq!(sh, Sh::from_array(coefficients));
        // A DC-only particle evaluates as a degree-3 one with zero bands.
        let d = Vec3::new(0.3, -0.4, 0.866).normalize();
        assert_eq!(crate::sh::eval(sh.as_slice(), 3, d), crate::sh::eval(&coefficients, 3, d));
        assert_eq!(std::mem::size_of::<Particle>(), 64, "a degree-0 particle is 64 bytes");
    }
}
