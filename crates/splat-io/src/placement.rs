//! Placing splats by the transforms of a scene graph (glTF nodes, USD `xformOp`s) and by axis
//! flips (`.spz`'s coordinate systems).
//!
//! A Gaussian placed by x ↦ M x + t has the mean M μ + t and the covariance M Σ Mᵀ (the glTF
//! extension's Σ = M C Cᵀ Mᵀ). That is again a scaled rotation R S Sᵀ Rᵀ when M = s Q with Q
//! orthogonal: a uniform scale s, and Q a rotation or a mirror. A mirror is a rotation after
//! the flip F = diag(1, 1, −1) (Q = R F), and F Σ F = (F R₀ F) S Sᵀ (F R₀ F)ᵀ keeps the Gaussian a
//! scaled rotation whose rotation is F R₀ F. The radiance turns with the directions: each SH
//! basis function keeps or flips its sign under F (its parity), and R maps the coefficients by
//! [`splat_core::sh::Rotation`].

use glam::{Mat3, Mat4, Quat, Vec3};
use splat_core::Particle;
use splat_core::sh::Rotation;

/// The signs of the 15 SH basis functions of bands 1–3 under (x, y, z) ↦ (sx x, sy y, sz z), in
/// the 3DGS order (y, z, x; xy, yz, 3z²−1, xz, x²−y²; y(3x²−y²), xyz, y(4z²−x²−y²),
/// z(2z²−3x²−3y²), x(4z²−x²−y²), z(x²−y²), x(x²−3y²)): each one's parity in each axis.
fn sh_parity(s: Vec3) -> [f32; 15] {
    let (x, y, z) = (s.x, s.y, s.z);
    [y, z, x, x * y, y * z, 1.0, x * z, 1.0, y, x * y * z, y, z, x, z, x]
}

/// The quaternion of S R S for the axis flips `s` (x, y, z each ±1): a rotation even where S
/// is a mirror, which keeps w and takes the flips of the other two axes on each of x, y, z.
fn flip_quat(q: Quat, s: Vec3) -> Quat {
    Quat::from_xyzw(s.y * s.z * q.x, s.x * s.z * q.y, s.x * s.y * q.z, q.w)
}

/// SH coefficients (DC first) under the axis flips `s`: each basis function by its parity.
fn flip_sh(sh: &mut [Vec3], s: Vec3) {
    for (c, sign) in sh.iter_mut().skip(1).zip(sh_parity(s)) {
        *c *= sign;
    }
}

/// Convert a particle by the axis flips `s` (x, y, z each ±1; an involution): the mean and the
/// radiance flip with the axes, the rotation R becomes S R S.
pub(crate) fn flip_axes(p: &mut Particle, s: Vec3) {
    if s == Vec3::ONE {
        return;
    }
    p.mean *= s;
    p.rotation = flip_quat(p.rotation, s);
    if let splat_core::Sh::Bands(all) = &mut p.sh {
        flip_sh(&mut all[..], s);
    }
}

/// The flip a mirror is taken as, before its rotation: z ↦ −z.
const MIRROR: Vec3 = Vec3::new(1.0, 1.0, -1.0);

/// A transform as splats take it: M = T · s R (· F where it mirrors), and R's map of SH
/// coefficients where R is not the identity.
pub(crate) struct Placement {
    /// The whole transform, for the means.
    pub(crate) matrix: Mat4,
    /// R.
    pub(crate) rotation: Quat,
    /// s.
    pub(crate) scale: f32,
    /// Whether M mirrors (negative determinant): F = diag(1, 1, −1) comes first.
    pub(crate) mirror: bool,
    sh: Option<Rotation>,
}

impl Placement {
    /// The placement of transform `m`, or why splats cannot take it.
    pub(crate) fn of(m: Mat4) -> Result<Self, String> {
        let linear = Mat3::from_mat4(m);
        let lengths = Vec3::new(linear.x_axis.length(), linear.y_axis.length(), linear.z_axis.length());
        let scale = lengths.x;
        if !(scale.is_finite() && scale > 0.0) || (lengths - Vec3::splat(scale)).abs().max_element() > 1e-5 * scale {
            return Err(format!(
                "its transform scales the axes by {lengths}: Gaussians take a uniform scale only (Σ = M C Cᵀ Mᵀ would not stay a scaled rotation)"
            ));
        }
        let orthogonal = linear * (1.0 / scale);
        let mirror = orthogonal.determinant() < 0.0;
        let rotation = if mirror { orthogonal * Mat3::from_diagonal(MIRROR) } else { orthogonal };
        let rotation = Quat::from_mat3(&rotation).normalize();
        let sh = (rotation.angle_between(Quat::IDENTITY) > 1e-6).then(|| Rotation::new(rotation));
        Ok(Self { matrix: m, rotation, scale, mirror, sh })
    }

    /// A particle's mean, scale, rotation and SH coefficients (DC first) placed.
    pub(crate) fn place(
        &self,
        mean: Vec3,
        scale: Vec3,
        rotation: Quat,
        mut sh: [Vec3; 16],
    ) -> (Vec3, Vec3, Quat, [Vec3; 16]) {
        let mut q = rotation;
        if self.mirror {
            q = flip_quat(q, MIRROR);
            flip_sh(&mut sh, MIRROR);
        }
        if let Some(r) = &self.sh {
            sh = r.apply(&sh);
        }
        (self.matrix.transform_point3(mean), self.scale * scale, self.rotation * q, sh)
    }
}

/// What the tests of placements and axis flips share.
#[cfg(test)]
pub(crate) mod check {
    use glam::{Mat3, Mat4, Quat, Vec3};
    use splat_core::Particle;

    /// A particle turned about every axis, with every SH coefficient set.
    pub(crate) fn particle() -> Particle {
        let coeffs: [Vec3; 16] =
            std::array::from_fn(|k| Vec3::new(0.1 * k as f32 - 0.5, 0.03 * k as f32, -0.02 * k as f32));
        let rotation = Quat::from_euler(glam::EulerRot::XYZ, 0.4, -0.7, 1.1);
        Particle::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.1, 0.2, 0.3), rotation, 0.5, coeffs).unwrap()
    }

    /// Assert that `q` is `p` placed by `m` as `m` maps space: the mean M μ + t, the covariance
    /// L Σ Lᵀ (L the linear part), and the colour seen along L d (normalised) within `colour`
    /// of `p`'s along d.
    pub(crate) fn assert_placed(p: &Particle, q: &Particle, m: Mat4, colour: f32, label: &str) {
        let l = Mat3::from_mat4(m);
        assert!((q.mean - m.transform_point3(p.mean)).length() < 1e-5, "{label}");
        assert!(q.covariance().abs_diff_eq(l * p.covariance() * l.transpose(), 1e-5), "{label}");
        for d in [Vec3::new(0.3, -0.5, 0.8), Vec3::new(-0.9, 0.1, 0.2), Vec3::Z] {
            let d = d.normalize();
            let a = splat_core::sh::eval(p.sh.as_slice(), 3, d);
            let b = splat_core::sh::eval(q.sh.as_slice(), 3, (l * d).normalize());
            assert!((a - b).length() < colour, "{label}: {a} vs {b}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A placement maps a particle's mean, covariance and radiance as the transform maps space
    /// ([`check::assert_placed`]); mirrors included, non-uniform scales refused.
    #[test]
    fn placements_map_mean_covariance_and_radiance() {
        let p = check::particle();
        let turn = Quat::from_euler(glam::EulerRot::ZYX, 0.3, 1.2, -0.5);
        let t = Vec3::new(5.0, -1.0, 2.0);
        for mirror in [Vec3::ONE, Vec3::new(1.0, -1.0, 1.0), Vec3::new(-1.0, -1.0, -1.0)] {
            let m = Mat4::from_scale_rotation_translation(2.0 * mirror, turn, t);
            let placement = Placement::of(m).unwrap();
            assert_eq!(placement.mirror, mirror.x * mirror.y * mirror.z < 0.0);
            let (mean, scale, rotation, sh) = placement.place(p.mean, p.scale, p.rotation, p.sh.to_array());
            let q = Particle::new(mean, scale, rotation, p.opacity, sh).unwrap();
            check::assert_placed(&p, &q, m, 1e-4, &mirror.to_string());
        }
        let stretch = Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0));
        assert!(Placement::of(stretch).err().unwrap().contains("uniform scale only"));
    }
}
