//! Normal of one particle at a ray hit (vk_gaussian_splatting Lighting §2.4).

use crate::hit::{PreparedParticle, Ray, sphere_entry, to_canonical};
use glam::Vec3;

/// How the normal of a single particle is computed (vk_gaussian_splatting Lighting §2.4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NormalMode {
    /// Normal of the plane that linearly approximates the maximum-density surface,
    /// n ∝ Σ⁻¹(μ − o), oriented toward the ray origin (the vk default).
    #[default]
    MaxDensityPlane,
    /// Normal of the cutoff ellipsoid ‖M(x − μ)‖ = s where the ray enters it.
    KernelEllipsoid,
}

/// Unit normal of particle `p` for `ray`, oriented toward the ray origin (n·d ≤ 0).
///
/// Both modes work in canonical space, where Σ⁻¹ = Mᵀ M: the max-density plane normal is
/// Σ⁻¹(o − μ) = Mᵀ o_c, and the ellipsoid normal at canonical point x_c is Mᵀ x_c. When the ray
/// starts inside the ellipsoid or misses it, the ellipsoid mode falls back to the plane normal.
pub fn particle_normal(p: &PreparedParticle, ray: &Ray, mode: NormalMode, cutoff: f32) -> Vec3 {
    let (o_c, d_c) = to_canonical(p, ray);
    let m_t = p.canonical.transpose();
    let canonical_point = match mode {
        NormalMode::MaxDensityPlane => o_c,
        NormalMode::KernelEllipsoid => ellipsoid_entry(o_c, d_c, cutoff).unwrap_or(o_c),
    };
    let n = (m_t * canonical_point).try_normalize().unwrap_or(-ray.dir);
    if n.dot(ray.dir) > 0.0 { -n } else { n }
}

/// Canonical point where o_c + t d_c first enters the sphere of radius s, if the ray starts
/// outside it and crosses it ahead of the origin (the entry of [`sphere_entry`], whose
/// discriminant keeps its digits for flat splats).
fn ellipsoid_entry(o_c: Vec3, d_c: Vec3, s: f32) -> Option<Vec3> {
    if o_c.length_squared() <= s * s {
        return None;
    }
    let t = sphere_entry(o_c, d_c, s * s)?;
    (t > 0.0).then(|| o_c + t * d_c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particle::Particle;
    use approx::assert_relative_eq;
    use glam::Quat;

    #[test]
    fn sphere_normal_points_from_centre_to_origin() {
        let centre = Vec3::new(0.3, -0.2, 4.0);
        let p = PreparedParticle::new(&Particle::with_rgb(centre, Vec3::splat(0.5), Quat::IDENTITY, 1.0, Vec3::ONE));
        let origin = Vec3::new(0.1, 0.4, -1.0);
        let ray = Ray::new(origin, (centre - origin).normalize());
        let expected = (origin - centre).normalize();
        for mode in [NormalMode::MaxDensityPlane, NormalMode::KernelEllipsoid] {
            let n = particle_normal(&p, &ray, mode, 3.0);
            assert_relative_eq!(n.dot(expected), 1.0, epsilon = 1e-5);
        }
    }

    #[test]
    fn flat_particle_normal_is_its_thin_axis() {
        let rot = Quat::from_rotation_x(0.5);
        let p = PreparedParticle::new(&Particle::with_rgb(Vec3::ZERO, Vec3::new(1.0, 1.0, 0.01), rot, 1.0, Vec3::ONE));
        let ray = Ray::new(Vec3::new(0.2, 0.3, -4.0), Vec3::new(0.05, 0.0, 1.0).normalize());
        let thin_axis = rot * Vec3::Z;
        for mode in [NormalMode::MaxDensityPlane, NormalMode::KernelEllipsoid] {
            let n = particle_normal(&p, &ray, mode, 3.0);
            assert_relative_eq!(n.dot(thin_axis).abs(), 1.0, epsilon = 1e-3);
            assert!(n.dot(ray.dir) <= 0.0);
        }
    }

    /// Through a flat splat (canonical directions stretched 10⁴ times) a ray that misses the
    /// cutoff sphere by an f64 margin never gets an entry point (the textbook b² − a c in f32
    /// gave some), and one that crosses it from outside always does.
    #[test]
    fn ellipsoid_entries_of_flat_splats_follow_f64() {
        let mut rng = crate::rng::SplitMix64::new(8);
        let (mut hits, mut misses) = (0, 0);
        for _ in 0..20_000 {
            let o = Vec3::new(rng.range(-4.0, 4.0), rng.range(-4.0, 4.0), rng.range(-4e4, 4e4));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1e4, 1e4));
            let (od, dd) = (o.as_dvec3(), d.as_dvec3());
            let margin = (dd.length_squared() * 9.0 - od.cross(dd).length_squared()) / (dd.length_squared() * 9.0);
            let ahead = od.dot(dd) < 0.0 && od.length_squared() > 9.0 * 1.01;
            match ellipsoid_entry(o, d, 3.0) {
                Some(_) => {
                    assert!(margin > -1e-3, "a miss (margin {margin}) got an entry point");
                    hits += 1;
                }
                None if margin > 1e-3 && ahead => panic!("a crossing ray (margin {margin}) got none"),
                None => misses += 1,
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} entries, {misses} misses");
    }
}
