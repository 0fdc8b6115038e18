//! The scattering functions of mesh surfaces in the path tracer: Lambertian (optionally under
//! a dielectric specular layer, glTF's `fresnel_mix`), rough conductor (GGX, sampled by visible
//! normals) and smooth or rough dielectric, mixed by the shares of a
//! [`crate::mesh::MeshMaterial`].
//!
//! Everything works in the local shading frame, z along the normal turned toward the outgoing
//! direction ωₒ (so ωₒ.z > 0). Each lobe gives f(ωₒ, ωᵢ)|cos θᵢ| and its sampling density
//! p(ωᵢ) per solid angle; a sample carries the weight f|cos θᵢ|/p that multiplies the path
//! throughput. Lobes whose roughness is below [`MIN_ROUGHNESS`] are Dirac deltas (a perfect
//! mirror, smooth glass): they are sampled, never evaluated, and next-event estimation skips
//! them.
//!
//! References: Walter, Marschner, Li & Torrance 2007 (microfacet transmission, the generalised
//! half vector); Heitz 2014 (height-correlated Smith G₂); Heitz 2018 and Dupuy & Benyoub 2023
//! (sampling visible normals by a spherical cap).

use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// Roughness below which a lobe is a perfect specular delta.
pub const MIN_ROUGHNESS: f32 = 1e-3;

/// A mixture of the three lobes, weights summing to at most 1 (the rest is absorbed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bsdf {
    /// Weight of the Lambertian lobe.
    pub diffuse: f32,
    /// Lambertian albedo ρ (f = ρ/π).
    pub albedo: Vec3,
    /// Weight of the GGX conductor lobe, rough or not.
    pub conductor: f32,
    /// The conductor's reflectance F₀ at normal incidence (Schlick's Fresnel,
    /// [`crate::mesh::schlick`]; 1: an untinted mirror).
    pub tint: Vec3,
    /// Weight of the dielectric lobe.
    pub dielectric: f32,
    /// F₀ of the dielectric specular layer over the Lambertian lobe (0: none): glTF 2.0's
    /// `fresnel_mix` (Appendix B), F(ωₒ·h) of the GGX lobe of roughness α reflected and 1 − F
    /// passed to the Lambertian base.
    pub layer_f0: f32,
    /// GGX α = roughness² of the conductor and dielectric lobes and of the layer (0 for delta
    /// lobes).
    pub alpha: f32,
    /// η = n_t / n_i across the dielectric as seen from ωₒ's side.
    pub eta: f32,
}

/// One direction drawn from a [`Bsdf`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Incident direction ωᵢ (local frame).
    pub wi: Vec3,
    /// f|cos θᵢ| / p: what the throughput is multiplied by.
    pub weight: Vec3,
    /// Density p(ωᵢ) of the mixture's non-delta lobes (0 for a delta sample).
    pub pdf: f32,
    /// Whether a delta lobe was sampled (no next-event estimation or MIS along it).
    pub delta: bool,
}

impl Bsdf {
    /// The mixture of `roughness` (GGX α = roughness²) and the given lobe weights.
    pub fn new(
        diffuse: f32,
        albedo: Vec3,
        conductor: f32,
        tint: Vec3,
        dielectric: f32,
        roughness: f32,
        eta: f32,
    ) -> Self {
        let alpha = if roughness < MIN_ROUGHNESS { 0.0 } else { roughness * roughness };
        Self { diffuse, albedo, conductor, tint, dielectric, layer_f0: 0.0, alpha, eta }
    }

    /// The same mixture with a dielectric specular layer of reflectance `f0` at normal incidence
    /// over its Lambertian lobe.
    pub fn with_layer(self, f0: f32) -> Self {
        Self { layer_f0: f0, ..self }
    }

    /// The specular layer's Fresnel reflectance F(cos θ), Schlick's of its F₀.
    fn layer_fresnel(&self, cos: f32) -> f32 {
        crate::mesh::schlick(Vec3::splat(self.layer_f0), cos).x
    }

    /// The probability q that a draw of the Lambertian lobe takes its specular layer instead:
    /// the layer's Fresnel reflectance at ωₒ's incidence on the surface, F(ωₒ.z).
    fn layer_pick(&self, wo: Vec3) -> f32 {
        self.layer_fresnel(wo.z)
    }

    /// Whether the conductor and dielectric lobes are deltas.
    pub fn specular_is_delta(&self) -> bool {
        self.alpha == 0.0
    }

    /// Whether any non-delta lobe has weight: next-event estimation has something to evaluate.
    pub fn has_smooth_part(&self) -> bool {
        self.diffuse > 0.0 || (!self.specular_is_delta() && self.conductor + self.dielectric > 0.0)
    }

    /// f(ωₒ, ωᵢ)|cos θᵢ| and the mixture density p(ωᵢ) of the non-delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        let mut f = Vec3::ZERO;
        let mut pdf = 0.0;
        if self.diffuse > 0.0 && wi.z > 0.0 {
            if self.layer_f0 > 0.0 {
                // glTF's fresnel_mix: (1 − F(ωₒ·h)) of the base, F(ωₒ·h) of the layer.
                let h = (wo + wi).normalize();
                let fresnel = self.layer_fresnel(wo.dot(h));
                let q = self.layer_pick(wo);
                f += self.diffuse * (1.0 - fresnel) * self.albedo * (wi.z / PI);
                pdf += self.diffuse * (1.0 - q) * wi.z / PI;
                if !self.specular_is_delta() {
                    let (fl, pl) = conductor_eval(wo, wi, self.alpha, Vec3::splat(self.layer_f0));
                    f += self.diffuse * fl;
                    pdf += self.diffuse * q * pl;
                }
            } else {
                f += self.diffuse * self.albedo * (wi.z / PI);
                pdf += self.diffuse * wi.z / PI;
            }
        }
        if !self.specular_is_delta() {
            if self.conductor > 0.0 {
                let (fc, pc) = conductor_eval(wo, wi, self.alpha, self.tint);
                f += self.conductor * fc;
                pdf += self.conductor * pc;
            }
            if self.dielectric > 0.0 {
                let (fd, pd) = dielectric_eval(wo, wi, self.alpha, self.eta);
                f += Vec3::splat(self.dielectric * fd);
                pdf += self.dielectric * pd;
            }
        }
        (f, pdf)
    }

    /// Draw ωᵢ: `u_lobe` picks a lobe by weight, `u` places the direction. `None` when the draw
    /// is absorbed (the leftover weight, or a direction below the surface).
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let mut pick = u_lobe;
        let wi = if pick < self.diffuse {
            let q = if self.layer_f0 > 0.0 { self.layer_pick(wo) } else { 0.0 };
            if pick < self.diffuse * q {
                // The specular layer; smooth, a mirror reflection of weight F(ωₒ.z) / q = 1.
                if self.specular_is_delta() {
                    let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                    return Some(BsdfSample { wi, weight: Vec3::ONE, pdf: 0.0, delta: true });
                }
                Some(reflect_about(wo, visible_normal(wo, self.alpha, u))).filter(|wi| wi.z > 0.0)?
            } else {
                cosine_hemisphere(u)
            }
        } else {
            pick -= self.diffuse;
            if pick < self.conductor {
                if self.specular_is_delta() {
                    let wi = Vec3::new(-wo.x, -wo.y, wo.z);
                    let weight = crate::mesh::schlick(self.tint, wo.z);
                    return Some(BsdfSample { wi, weight, pdf: 0.0, delta: true });
                }
                // Reflected below the surface: absorbed (not the dielectric's transmission).
                Some(reflect_about(wo, visible_normal(wo, self.alpha, u))).filter(|wi| wi.z > 0.0)?
            } else if pick - self.conductor < self.dielectric {
                if self.specular_is_delta() {
                    return smooth_dielectric_sample(wo, self.eta, u.x);
                }
                rough_dielectric_direction(wo, self.alpha, self.eta, u, (pick - self.conductor) / self.dielectric)?
            } else {
                return None;
            }
        };
        let (f, pdf) = self.eval(wo, wi);
        (pdf > 0.0 && f != Vec3::ZERO).then(|| BsdfSample { wi, weight: f / pdf, pdf, delta: false })
    }
}

/// A cosine-weighted direction of the upper hemisphere (Malley's method on the concentric disk).
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = crate::lighting::concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// The mirror image of `wo` about the unit microfacet normal `h`.
fn reflect_about(wo: Vec3, h: Vec3) -> Vec3 {
    2.0 * wo.dot(h) * h - wo
}

/// GGX normal distribution D(h) (Trowbridge–Reitz) for roughness α.
pub fn ggx_d(h: Vec3, alpha: f32) -> f32 {
    if h.z <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let k = h.z * h.z * (a2 - 1.0) + 1.0;
    a2 / (PI * k * k)
}

/// Smith's Λ(ω) for GGX.
fn ggx_lambda(w: Vec3, alpha: f32) -> f32 {
    let cos2 = w.z * w.z;
    if cos2 <= 0.0 {
        return f32::INFINITY;
    }
    let tan2 = (1.0 - cos2).max(0.0) / cos2;
    0.5 * ((1.0 + alpha * alpha * tan2).sqrt() - 1.0)
}

/// Smith's masking G₁(ω) = 1 / (1 + Λ(ω)).
pub fn ggx_g1(w: Vec3, alpha: f32) -> f32 {
    1.0 / (1.0 + ggx_lambda(w, alpha))
}

/// Height-correlated masking–shadowing G₂(ωₒ, ωᵢ) = 1 / (1 + Λ(ωₒ) + Λ(ωᵢ)) (Heitz 2014).
pub fn ggx_g2(wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))
}

/// The density of visible normals D_ωₒ(h) = G₁(ωₒ) max(0, ωₒ·h) D(h) / ωₒ.z.
pub fn visible_normal_pdf(wo: Vec3, h: Vec3, alpha: f32) -> f32 {
    ggx_g1(wo, alpha) * wo.dot(h).max(0.0) * ggx_d(h, alpha) / wo.z
}

/// A microfacet normal drawn from D_ωₒ (Dupuy & Benyoub 2023: a spherical cap in the
/// stretched configuration, then unstretched).
pub fn visible_normal(wo: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    let wh = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let phi = 2.0 * PI * u.x;
    let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
    let sin_theta = (1.0 - z * z).clamp(0.0, 1.0).sqrt();
    let h = Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), z) + wh;
    Vec3::new(alpha * h.x, alpha * h.y, h.z.max(0.0)).normalize()
}

/// The rough conductor of reflectance `f0` at normal incidence: f|cos θᵢ| = F(ωₒ·h) D G₂ /
/// (4 ωₒ.z), F by Schlick ([`crate::mesh::schlick`]), and p = D_ωₒ(h) / (4 ωₒ·h).
fn conductor_eval(wo: Vec3, wi: Vec3, alpha: f32, f0: Vec3) -> (Vec3, f32) {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return (Vec3::ZERO, 0.0);
    }
    let h = (wo + wi).normalize();
    let d = ggx_d(h, alpha);
    let f = crate::mesh::schlick(f0, wo.dot(h)) * (d * ggx_g2(wo, wi, alpha) / (4.0 * wo.z));
    let pdf = visible_normal_pdf(wo, h, alpha) / (4.0 * wo.dot(h));
    (f, pdf)
}

/// Smooth glass: reflect with probability F, else refract; each weight is 1 (times η⁻² for
/// radiance carried across the interface, 1/η² with η = n_t / n_i).
fn smooth_dielectric_sample(wo: Vec3, eta: f32, u: f32) -> Option<BsdfSample> {
    let f = crate::mesh::fresnel(wo.z, 1.0 / eta);
    if u < f {
        let wi = Vec3::new(-wo.x, -wo.y, wo.z);
        return Some(BsdfSample { wi, weight: Vec3::ONE, pdf: 0.0, delta: true });
    }
    let wi = crate::mesh::refract(-wo, Vec3::Z, 1.0 / eta)?;
    Some(BsdfSample { wi, weight: Vec3::splat(1.0 / (eta * eta)), pdf: 0.0, delta: true })
}

/// Draw ωᵢ from the rough dielectric: a visible normal h, then reflection with probability
/// F(ωₒ·h) (decided by `u_choice`) or refraction through h.
fn rough_dielectric_direction(wo: Vec3, alpha: f32, eta: f32, u: Vec2, u_choice: f32) -> Option<Vec3> {
    let h = visible_normal(wo, alpha, u);
    let cos_o = wo.dot(h);
    if cos_o <= 0.0 {
        return None;
    }
    // A reflection below the surface or a refraction above it is absorbed (the density
    // evaluated on that side is the other event's).
    if u_choice < crate::mesh::fresnel(cos_o, 1.0 / eta) {
        Some(reflect_about(wo, h)).filter(|wi| wi.z > 0.0)
    } else {
        crate::mesh::refract(-wo, h, 1.0 / eta).filter(|wi| wi.z < 0.0)
    }
}

/// The rough dielectric of Walter et al. 2007 (their Eqs. 20–21 with the generalised half
/// vector h ∝ ωₒ + η ωᵢ for transmission), sampled by visible normals: f|cos θᵢ| and p.
fn dielectric_eval(wo: Vec3, wi: Vec3, alpha: f32, eta: f32) -> (f32, f32) {
    if wo.z <= 0.0 || wi.z == 0.0 {
        return (0.0, 0.0);
    }
    let reflect = wi.z > 0.0;
    let h = if reflect { wo + wi } else { wo + eta * wi };
    let Some(h) = h.try_normalize() else { return (0.0, 0.0) };
    let h = if h.z < 0.0 { -h } else { h };
    let (cos_o, cos_i) = (wo.dot(h), wi.dot(h));
    // Microfacets seen from the back by either direction contribute nothing.
    if cos_o <= 0.0 || (reflect && cos_i <= 0.0) || (!reflect && cos_i >= 0.0) {
        return (0.0, 0.0);
    }
    let fresnel = crate::mesh::fresnel(cos_o, 1.0 / eta);
    let (d, g2, vn) = (ggx_d(h, alpha), ggx_g2(wo, wi, alpha), visible_normal_pdf(wo, h, alpha));
    if reflect {
        let f = fresnel * d * g2 / (4.0 * wo.z);
        (f, fresnel * vn / (4.0 * cos_o))
    } else {
        let denom = (cos_o + eta * cos_i).powi(2);
        let jacobian = eta * eta * cos_i.abs() / denom;
        // Radiance crossing into the medium is scaled by 1/η².
        let f = (1.0 - fresnel) * d * g2 * cos_o * jacobian / (wo.z * eta * eta);
        (f, (1.0 - fresnel) * vn * jacobian)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    #[test]
    fn ggx_distribution_projects_to_one() {
        // ∫ D(h) cos θ_h dω = 1, by midpoint quadrature in θ (D is isotropic).
        for alpha in [0.05, 0.3, 1.0] {
            let n = 20_000;
            let sum: f32 = (0..n)
                .map(|i| {
                    let theta = (i as f32 + 0.5) / n as f32 * PI / 2.0;
                    let h = Vec3::new(theta.sin(), 0.0, theta.cos());
                    ggx_d(h, alpha) * h.z * theta.sin() * 2.0 * PI * (PI / 2.0 / n as f32)
                })
                .sum();
            assert_relative_eq!(sum, 1.0, epsilon = 2e-3);
        }
    }

    #[test]
    fn reflection_lobes_are_reciprocal() {
        // f(ωₒ, ωᵢ) = f(ωᵢ, ωₒ): compare f|cos θᵢ| / cos θᵢ both ways.
        let b = Bsdf::new(0.3, Vec3::splat(0.7), 0.4, Vec3::new(1.0, 0.78, 0.34), 0.3, 0.5, 1.5);
        for (a, c) in [(dir(20.0, 10.0), dir(60.0, 200.0)), (dir(75.0, 0.0), dir(5.0, 90.0))] {
            let f_ac = b.eval(a, c).0 / c.z;
            let f_ca = b.eval(c, a).0 / a.z;
            assert!((f_ac - f_ca).abs().max_element() < 1e-5 * f_ac.max_element().max(1.0), "{f_ac} vs {f_ca}");
        }
    }

    #[test]
    fn refraction_obeys_the_generalised_reciprocity() {
        // For transmission f(ωₒ, ωᵢ) / η_i² is symmetric: f_{o→i} η_o⁻² … written with η
        // relative to each side, f(ωₒ, ωᵢ; η) = f(ωᵢ', ωₒ'; 1/η) / η² after flipping sides.
        let (alpha, eta) = (0.4, 1.5);
        let wo = dir(30.0, 0.0);
        let wi = -dir(15.0, 160.0);
        let forward = dielectric_eval(wo, wi, alpha, eta).0 / wi.z.abs();
        let (wo2, wi2) = (-wi, -wo); // seen from the other side the normal flips
        let backward = dielectric_eval(wo2, wi2, alpha, 1.0 / eta).0 / wi2.z.abs();
        assert!(forward > 0.0);
        assert_relative_eq!(forward * eta * eta, backward, max_relative = 1e-4);
    }

    #[test]
    fn sample_weights_equal_f_over_pdf() {
        let b = Bsdf::new(0.2, Vec3::new(0.9, 0.5, 0.1), 0.3, Vec3::new(0.95, 0.64, 0.54), 0.5, 0.35, 1.33);
        let wo = dir(40.0, 30.0);
        let mut seen = 0;
        for i in 0..64 {
            for j in 0..16 {
                let u = Vec2::new((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 16.0);
                if let Some(s) = b.sample(wo, (i * 16 + j) as f32 / 1024.0, u) {
                    let (f, pdf) = b.eval(wo, s.wi);
                    assert_relative_eq!(s.pdf, pdf, max_relative = 1e-5);
                    assert!((s.weight - f / pdf).abs().max_element() < 1e-5);
                    seen += 1;
                }
            }
        }
        assert!(seen > 900, "{seen}");
    }
}
