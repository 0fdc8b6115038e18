//! Exact front-to-back compositing of depth-sorted hits (Sun et al. Eq. 3), in f64,
//! with the iso-opacity depth (vk_gaussian_splatting Lighting §1.1) and the integrated normal (vk_gaussian_splatting Lighting §2.1).

use crate::hit::{Hit, PreparedParticle, Ray};
use crate::normal::particle_normal;
use crate::particle::Scene;
use crate::sh;
use glam::{DVec3, Vec3};

/// Default iso-opacity threshold on transmittance (vk `depthIsoThreshold`).
pub const DEFAULT_ISO_THRESHOLD: f32 = 0.7;
/// An integrated normal shorter than this is degenerate and replaced by the camera-facing one
/// ([`integrated_normal`]; `DEGENERATE_NORMAL` in the ray-tracing and raster shaders).
pub const DEGENERATE_NORMAL: f64 = 1e-6;

/// The one rule for the integrated normal Σ nᵢ αᵢ Tᵢ of a ray or pixel that met at least one
/// particle, ray tracing and splatting alike (vk_gaussian_splatting Lighting §2.3): its
/// direction, or the camera-facing −d where it is shorter than [`DEGENERATE_NORMAL`] (normals
/// that cancel, or weights that vanish). Where nothing was met the normal is zero instead.
pub fn integrated_normal(sum: DVec3, ray_dir: Vec3) -> Vec3 {
    let len = sum.length();
    if len > DEGENERATE_NORMAL { (sum / len).as_vec3() } else { -ray_dir }
}

/// A hit with everything shading needs: distance, alpha, colour and unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadedHit {
    /// Hit distance t.
    pub t: f32,
    /// Alpha αᵢ in [0, 1].
    pub alpha: f32,
    /// Colour cᵢ.
    pub color: Vec3,
    /// Unit world-space normal nᵢ.
    pub normal: Vec3,
    /// Particle index, the tie-breaker of equal distances.
    pub index: u32,
}

/// The front-to-back order of two hits (t, id): by distance, ties by particle index, so the order
/// is total and does not depend on the order the hits were found in.
pub fn depth_order(t: f32, id: u32, other_t: f32, other_id: u32) -> std::cmp::Ordering {
    t.total_cmp(&other_t).then(id.cmp(&other_id))
}

/// Sort hits front to back by [`depth_order`].
pub fn sort_front_to_back(hits: &mut [ShadedHit]) {
    hits.sort_unstable_by(|a, b| depth_order(a.t, a.index, b.t, b.index));
}

/// Result of compositing one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Composite {
    /// Foreground radiance L = Σ Tᵢ αᵢ cᵢ (Eq. 3), without background.
    pub radiance: DVec3,
    /// Final transmittance T_{M+1} = Π (1 − αᵢ).
    pub transmittance: f64,
    /// Iso-opacity depth: t of the first hit after which transmittance is below the threshold.
    pub depth: Option<f32>,
    /// Integrated normal N = Σ nᵢ αᵢ Tᵢ (not normalised).
    pub normal: DVec3,
    /// Number of hits composited.
    pub hits: usize,
}

impl Composite {
    /// Pixel colour: L + T_{M+1} × background.
    pub fn color_over(&self, background: Vec3) -> DVec3 {
        self.radiance + self.transmittance * background.as_dvec3()
    }

    /// Overall opacity 1 − T_{M+1}.
    pub fn alpha(&self) -> f64 {
        1.0 - self.transmittance
    }

    /// The integrated normal as a unit vector; when it is degenerate (e.g. two opposite normals
    /// of equal weight) the camera-facing −`ray_dir` is used (vk_gaussian_splatting Lighting §2.1); zero with no hit.
    pub fn unit_normal(&self, ray_dir: Vec3) -> Vec3 {
        if self.hits == 0 {
            return Vec3::ZERO;
        }
        integrated_normal(self.normal, ray_dir)
    }
}

/// Composite hits sorted front to back (Eq. 3) in f64, with the iso-opacity depth at
/// transmittance threshold `iso_threshold` (vk_gaussian_splatting Lighting §1.1: the first hit whose evaluation
/// drops transmittance below the threshold) and the integrated normal (vk_gaussian_splatting Lighting §2.1).
pub fn composite(sorted: &[ShadedHit], iso_threshold: f32) -> Composite {
    let iso = f64::from(iso_threshold);
    let mut radiance = DVec3::ZERO;
    let mut normal = DVec3::ZERO;
    let mut transmittance = 1.0f64;
    let mut depth = None;
    for hit in sorted {
        let alpha = f64::from(hit.alpha);
        let weight = transmittance * alpha; // Tᵢ αᵢ
        radiance += weight * hit.color.as_dvec3();
        normal += weight * hit.normal.as_dvec3();
        transmittance *= 1.0 - alpha;
        if depth.is_none() && transmittance < iso {
            depth = Some(hit.t);
        }
    }
    Composite { radiance, transmittance, depth, normal, hits: sorted.len() }
}

/// Shade a hit of particle `hit.index`: colour from its SH along the ray direction, normal by
/// the settings' mode.
pub fn shade_hit(
    scene: &Scene,
    p: &PreparedParticle,
    hit: Hit,
    ray: &Ray,
    settings: &crate::settings::RenderSettings,
) -> ShadedHit {
    let particle = &scene.particles[hit.index as usize];
    ShadedHit {
        t: hit.t,
        alpha: hit.alpha,
        color: sh::eval_stored(particle.sh.as_slice(), scene.sh_degree, ray.dir, settings.sh_storage),
        normal: particle_normal(p, ray, settings.normal_mode, settings.kernel.cutoff),
        index: hit.index,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn hit(t: f32, alpha: f32, color: Vec3) -> ShadedHit {
        ShadedHit { t, alpha, color, normal: Vec3::Z, index: 0 }
    }

    #[test]
    fn one_opaque_hit_gives_its_colour() {
        let c = composite(&[hit(1.0, 1.0, Vec3::new(0.2, 0.4, 0.6))], 0.7);
        assert_relative_eq!(c.color_over(Vec3::ONE).y, 0.4, epsilon = 1e-7);
        assert_eq!(c.transmittance, 0.0);
        assert_eq!(c.depth, Some(1.0));
    }

    #[test]
    fn two_layers_by_hand() {
        let c = composite(&[hit(1.0, 0.5, Vec3::X), hit(2.0, 0.5, Vec3::Y)], 0.3);
        assert_relative_eq!(c.radiance.x, 0.5);
        assert_relative_eq!(c.radiance.y, 0.25);
        assert_relative_eq!(c.transmittance, 0.25);
        assert_eq!(c.depth, Some(2.0), "T drops to 0.25 < 0.3 at the second hit");
        assert_eq!(composite(&[hit(1.0, 0.5, Vec3::X)], 0.3).depth, None);
    }

    #[test]
    fn opposite_normals_fall_back_to_camera_facing() {
        let a = ShadedHit { normal: Vec3::X, ..hit(1.0, 0.5, Vec3::ONE) };
        let b = ShadedHit { normal: -Vec3::X, ..hit(2.0, 1.0, Vec3::ONE) };
        let c = composite(&[a, b], 0.7);
        assert_eq!(c.unit_normal(Vec3::Z), -Vec3::Z);
        assert_eq!(composite(&[], 0.7).unit_normal(Vec3::Z), Vec3::ZERO);
    }

    /// The one degenerate-normal rule of ray tracing and splatting (and their shaders'
    /// `DEGENERATE_NORMAL`): a sum longer than the threshold gives its direction, a shorter
    /// one — normals that cancel exactly, or nearly — the camera-facing −d. Splatting used to
    /// keep an exactly cancelled sum at zero (as if nothing was drawn) and to normalise any
    /// other, however short.
    #[test]
    fn one_rule_for_degenerate_normals() {
        let d = Vec3::new(0.0, 0.0, 1.0);
        assert_eq!(integrated_normal(DVec3::new(0.0, 2.0, 0.0), d), Vec3::Y);
        assert_eq!(integrated_normal(DVec3::ZERO, d), -d);
        assert_eq!(integrated_normal(DVec3::new(0.0, 1e-9, 0.0), d), -d);
        assert_eq!(integrated_normal(DVec3::new(0.0, 2.0 * DEGENERATE_NORMAL, 0.0), d), Vec3::Y);
    }
}
