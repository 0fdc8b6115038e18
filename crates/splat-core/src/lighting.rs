//! Synthetic lights, the material of a splat set and the Blinn–Phong shading that lights a
//! particle (the vk_gaussian_splatting documentation, "Lighting, Shading and Shadows":
//! introduction, §3 and §4).
//!
//! The particles keep their baked radiance: a material says how much of the particle's SH colour
//! c is emitted as is and how much is reflected from the lights,
//!
//! ```text
//! Lit(x, n, v, c) = (k_e + k_a) ⊙ c
//!                 + Σ_l V_l(x) E_l(x) ⊙ [ k_d ⊙ c max(0, n·l) + k_s max(0, n·h)^s ],   h = (l + v)/|l + v|
//! ```
//!
//! with k_e, k_a, k_d, k_s the emissive, ambient, diffuse and specular colours of the set, s its
//! shininess, l the unit direction to the light, v the unit direction to the viewer, E_l the
//! light's irradiance colour at x and V_l ∈ [0, 1]³ its visibility (the shadow ray, [`Shadows`]).
//! The specular lobe is counted only where n·l > 0. The default material is fully emissive
//! (k_e = 1, the rest 0): the set is a radiance field and no light is needed ([`Lighting::is_on`]).
//! The WGSL twin of [`Material::shade`] lives beside the GPU kernels.

use crate::hit::Ray;
use glam::{Vec2, Vec3};

/// The material of one splat set (vk_gaussian_splatting, introduction): colours multiplying the
/// particle's SH colour, and a specular colour and exponent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// k_e: the share of the SH colour emitted whatever the lights.
    pub emissive: Vec3,
    /// k_a: the share of the SH colour reflected from a uniform ambient light of radiance 1.
    pub ambient: Vec3,
    /// k_d: the share of the SH colour reflected diffusely (Lambert's cosine).
    pub diffuse: Vec3,
    /// k_s: the colour of the specular highlight (not multiplied by the SH colour).
    pub specular: Vec3,
    /// s: the Blinn–Phong exponent.
    pub shininess: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self::EMISSIVE
    }
}

impl Material {
    /// Fully emissive: the particle's own radiance, unlit (the vk default).
    pub const EMISSIVE: Material = Material {
        emissive: Vec3::ONE,
        ambient: Vec3::ZERO,
        diffuse: Vec3::ZERO,
        specular: Vec3::ZERO,
        shininess: 32.0,
    };

    /// A matte surface: 0.1 ambient and 0.9 diffuse (the default of a mesh,
    /// [`crate::mesh::MeshMaterial`]).
    pub const DIFFUSE: Material = Material {
        emissive: Vec3::ZERO,
        ambient: Vec3::splat(0.1),
        diffuse: Vec3::splat(0.9),
        specular: Vec3::ZERO,
        shininess: 32.0,
    };

    /// Whether the material only emits: lighting it changes nothing, so no light is evaluated.
    pub fn is_emissive(&self) -> bool {
        self.emissive == Vec3::ONE
            && self.ambient == Vec3::ZERO
            && self.diffuse == Vec3::ZERO
            && self.specular == Vec3::ZERO
    }

    /// Check that every colour is finite and non-negative and the exponent finite and ≥ 0.
    pub fn validate(&self) -> Result<(), String> {
        let colours = [
            ("emissive", self.emissive),
            ("ambient", self.ambient),
            ("diffuse", self.diffuse),
            ("specular", self.specular),
        ];
        for (name, c) in colours {
            if !c.is_finite() || c.min_element() < 0.0 {
                return Err(format!("material {name} colour {c} must be finite and non-negative"));
            }
        }
        if !(self.shininess.is_finite() && self.shininess >= 0.0) {
            return Err(format!("material shininess {} must be finite and non-negative", self.shininess));
        }
        Ok(())
    }

    /// The part of Lit that needs no light: (k_e + k_a) ⊙ c.
    #[inline]
    pub fn unlit(&self, c: Vec3) -> Vec3 {
        (self.emissive + self.ambient) * c
    }

    /// One light's Blinn–Phong term before visibility: E ⊙ [k_d ⊙ c max(0, n·l) + k_s max(0, n·h)^s].
    #[inline]
    pub fn direct(&self, c: Vec3, n: Vec3, v: Vec3, incident: &Incident) -> Vec3 {
        let n_l = n.dot(incident.l);
        if n_l <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (incident.l + v).normalize_or_zero();
        // max(0, n·h)^s, with 0^0 = 1 as powf has it.
        let specular = if self.specular == Vec3::ZERO { 0.0 } else { n.dot(h).max(0.0).powf(self.shininess) };
        incident.irradiance * (self.diffuse * c * n_l + self.specular * specular)
    }

    /// Lit(x, n, v, c) for lights given as (incident light, visibility) pairs (module docs).
    pub fn shade(&self, c: Vec3, n: Vec3, v: Vec3, lights: impl IntoIterator<Item = (Incident, Vec3)>) -> Vec3 {
        lights
            .into_iter()
            .fold(self.unlit(c), |sum, (incident, visibility)| sum + visibility * self.direct(c, n, v, &incident))
    }
}

/// Where a light is and how it spreads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// Light from a point, falling off as 1/d².
    Point {
        /// Position.
        position: Vec3,
    },
    /// A point light within a cone: full inside the inner half-angle, none outside the outer one,
    /// a smoothstep of the cosine between them.
    Spot {
        /// Position.
        position: Vec3,
        /// Unit axis of the cone, from the light outward.
        direction: Vec3,
        /// Inner half-angle in degrees.
        inner_deg: f32,
        /// Outer half-angle in degrees (≥ inner).
        outer_deg: f32,
    },
    /// Parallel light with no falloff.
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
    },
}

/// A synthetic light (vk_gaussian_splatting §3–4): point, spot or directional, with a colour,
/// an intensity and a radius that makes its shadows soft.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Kind and placement.
    pub kind: LightKind,
    /// Colour (multiplied by the intensity).
    pub color: Vec3,
    /// Intensity: irradiance at distance 1 for point and spot lights, irradiance for directional.
    pub intensity: f32,
    /// Radius of the emitter: a sphere (point, spot) or, for a directional light, the tangent of
    /// its angular radius. Each sample of a pixel lights from one uniform point of the disk the
    /// emitter shows to the shaded point, so shadows get penumbras; 0 is a hard light.
    pub radius: f32,
}

/// The light arriving at a point from one light sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Incident {
    /// Unit direction from the point toward the light.
    pub l: Vec3,
    /// Distance to the light sample (infinite for directional lights).
    pub distance: f32,
    /// Irradiance colour E_l: colour × intensity × falloff × cone.
    pub irradiance: Vec3,
}

/// A uniform point of the unit disk from two uniforms (concentric mapping, Shirley & Chiu 1997).
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let p = 2.0 * u - Vec2::ONE;
    if p == Vec2::ZERO {
        return Vec2::ZERO;
    }
    let (r, theta) = if p.x.abs() > p.y.abs() {
        (p.x, std::f32::consts::FRAC_PI_4 * (p.y / p.x))
    } else {
        (p.y, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (p.x / p.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// A point of the disk of radius `radius` centred at `centre` and facing `axis`, from `u` ∈ [0, 1)².
fn disk_point(centre: Vec3, axis: Vec3, radius: f32, u: Vec2) -> Vec3 {
    let (b1, b2) = axis.any_orthonormal_pair();
    let d = radius * concentric_disk(u);
    centre + d.x * b1 + d.y * b2
}

impl Light {
    /// Check the light's numbers, naming the first bad one.
    pub fn validate(&self) -> Result<(), String> {
        if !self.color.is_finite() || self.color.min_element() < 0.0 {
            return Err(format!("light colour {} must be finite and non-negative", self.color));
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(format!("light intensity {} must be finite and non-negative", self.intensity));
        }
        if !(self.radius.is_finite() && self.radius >= 0.0) {
            return Err(format!("light radius {} must be finite and non-negative", self.radius));
        }
        let unit = |d: Vec3| d.is_finite() && (d.length() - 1.0).abs() < 1e-3;
        match self.kind {
            LightKind::Point { position } if !position.is_finite() => {
                Err(format!("light position {position} is not finite"))
            }
            LightKind::Spot { position, direction, inner_deg, outer_deg } => {
                if !position.is_finite() {
                    Err(format!("spot light position {position} is not finite"))
                } else if !unit(direction) {
                    Err(format!("spot light direction {direction} is not a unit vector"))
                } else if !(0.0 <= inner_deg && inner_deg <= outer_deg && outer_deg <= 90.0) {
                    Err(format!("spot cone needs 0 ≤ inner ≤ outer ≤ 90 degrees (got {inner_deg}, {outer_deg})"))
                } else {
                    Ok(())
                }
            }
            LightKind::Directional { direction } if !unit(direction) => {
                Err(format!("directional light direction {direction} is not a unit vector"))
            }
            _ => Ok(()),
        }
    }

    /// Whether two samples of the light can differ (an emitter with a radius).
    pub fn is_area(&self) -> bool {
        self.radius > 0.0
    }

    /// The point of a point or spot emitter at `position` that lights `x` in sample `u`: on the
    /// disk of the light's radius facing `x`.
    fn sample_point(&self, position: Vec3, x: Vec3, u: Vec2) -> Vec3 {
        if self.radius == 0.0 {
            return position;
        }
        disk_point(position, (position - x).normalize(), self.radius, u)
    }

    /// The light arriving at `x` from the sample `u` ∈ [0, 1)² of the emitter; `None` where it
    /// sends nothing (outside a spot's cone, or at the light's own position).
    pub fn incident(&self, x: Vec3, u: Vec2) -> Option<Incident> {
        let e = self.color * self.intensity;
        match self.kind {
            LightKind::Directional { direction } => {
                let l = (-direction + self.radius * disk_offset(-direction, u)).normalize();
                Some(Incident { l, distance: f32::INFINITY, irradiance: e })
            }
            LightKind::Point { position } => point_incident(x, self.sample_point(position, x, u), e),
            LightKind::Spot { position, direction, inner_deg, outer_deg } => {
                let mut inc = point_incident(x, self.sample_point(position, x, u), e)?;
                let cos = (-inc.l).dot(direction);
                let (ci, co) = (inner_deg.to_radians().cos(), outer_deg.to_radians().cos());
                let cone = if ci <= co { f32::from(cos >= co) } else { smoothstep(co, ci, cos) };
                inc.irradiance *= cone;
                (cone > 0.0).then_some(inc)
            }
        }
    }
}

/// The offset within the unit disk facing `axis`, for a directional light's angular spread.
fn disk_offset(axis: Vec3, u: Vec2) -> Vec3 {
    let (b1, b2) = axis.any_orthonormal_pair();
    let d = concentric_disk(u);
    d.x * b1 + d.y * b2
}

fn point_incident(x: Vec3, light: Vec3, e: Vec3) -> Option<Incident> {
    let to = light - x;
    let d2 = to.length_squared();
    (d2 > 0.0).then(|| {
        let distance = d2.sqrt();
        Incident { l: to / distance, distance, irradiance: e / d2 }
    })
}

fn smoothstep(a: f32, b: f32, x: f32) -> f32 {
    let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The camera headlight lighting a world with no lights: white light from the ray's origin,
/// without falloff and without shadows (it sits at the eye, behind every caster).
pub fn headlight(ray: &Ray, t: f32) -> Incident {
    Incident { l: -ray.dir, distance: t, irradiance: Vec3::ONE }
}

/// Default offset of a shadow ray's origin along the light direction (vk `particleShadowOffset`).
pub const DEFAULT_SHADOW_OFFSET: f32 = 0.2;
/// Default hits of vk's sorted shadow pass: the any-hit payload size (vk `PARTICLES_SPP`, the
/// k of the k-buffer).
pub const DEFAULT_SHADOW_K: usize = 18;
/// Largest k of the sorted shadow pass (a fixed array on the stack, as the k-buffer's).
pub const MAX_SHADOW_K: usize = 64;
/// Default transmittance below which vk's shadow ray stops and the point is in shadow
/// (vk `shadowTransmittanceThreshold`).
pub const DEFAULT_SHADOW_THRESHOLD: f32 = 0.8;

/// How visibility toward a light is computed from a shaded point (ray tracing only: the raster
/// pipelines light without shadows, vk_gaussian_splatting §3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shadows {
    /// Every light is visible.
    None,
    /// vk_gaussian_splatting §4: one pass of the `k` nearest hits sorted, transmittance
    /// integrated front to back; when it drops below `threshold` the ray stops and the point is
    /// in shadow. Each hit tints the light by its colour with `colored` strength:
    /// T ← T ⊙ ((1 − α) + `colored` α c). Deterministic, not an estimator of the transmittance.
    Sorted {
        /// Hits of the pass.
        k: usize,
        /// Transmittance threshold of the early stop.
        threshold: f32,
        /// Coloured-shadow strength in [0, 1].
        colored: f32,
    },
    /// One traversal with Russian roulette on α (Algorithm 1 with visibility in place of
    /// colour): visibility 0 at the first accepted hit, else 1. Its expectation is the exact
    /// transmittance Π(1 − αᵢ) between the point and the light.
    Stochastic,
    /// The exact transmittance Π(1 − αᵢ) over every hit between the point and the light: the
    /// expectation of [`Shadows::Stochastic`], its oracle.
    Exact,
}

impl Shadows {
    /// vk's sorted shadow with its defaults (K of the k-buffer, threshold 0.8, no tint).
    pub const SORTED: Shadows =
        Shadows::Sorted { k: DEFAULT_SHADOW_K, threshold: DEFAULT_SHADOW_THRESHOLD, colored: 0.0 };
}

/// Which integration sorted methods (`exact`, `kbuffer`, `raster-sorted`) use when lit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Look {
    /// vk_gaussian_splatting §1.1 and §2.1: integrate radiance and normal, pick the iso-opacity
    /// depth, light the integrated result once with the material of the picked particle.
    /// Pixels that never reach the threshold show the background.
    #[default]
    Surface,
    /// Light every hit at its own position and normal, then integrate: Σ Tᵢ αᵢ Lit(xᵢ, nᵢ, cᵢ).
    /// The expectation of the stochastic methods, hence their oracle.
    Volumetric,
}

/// A splat set inside the scene's one particle id space: its first id and its material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatSet {
    /// Id of the set's first particle; the set runs to the next set's first id.
    pub first: u32,
    /// Material of every particle of the set.
    pub material: Material,
}

/// Everything lighting needs besides the particles: the material of each set, the lights,
/// shadows and the look of sorted methods. The default is one emissive set, no lights: off.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    /// Sets in increasing `first` order, the first at 0.
    pub sets: Vec<SplatSet>,
    /// The lights; with none, a headlight ([`headlight`]).
    pub lights: Vec<Light>,
    /// Visibility of the lights (ray tracing).
    pub shadows: Shadows,
    /// Offset of a shadow ray's origin along the light direction.
    pub shadow_offset: f32,
    /// Integration of sorted methods.
    pub look: Look,
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            sets: vec![SplatSet { first: 0, material: Material::EMISSIVE }],
            lights: Vec::new(),
            shadows: Shadows::None,
            shadow_offset: DEFAULT_SHADOW_OFFSET,
            look: Look::Surface,
        }
    }
}

impl Lighting {
    /// One set of `material` lit by `lights`.
    pub fn single(material: Material, lights: Vec<Light>, shadows: Shadows) -> Self {
        Self { sets: vec![SplatSet { first: 0, material }], lights, shadows, ..Self::default() }
    }

    /// Whether any set reflects light: otherwise rendering is exactly the unlit path.
    pub fn is_on(&self) -> bool {
        self.sets.iter().any(|s| !s.material.is_emissive())
    }

    /// Whether a lit sample is random even for a deterministic method: stochastic shadow rays,
    /// or an area light sampled per frame.
    pub fn is_random(&self) -> bool {
        self.is_on() && self.draws()
    }

    /// Whether lighting a point draws random numbers: stochastic shadow rays or an area light.
    pub fn draws(&self) -> bool {
        self.shadows == Shadows::Stochastic || self.lights.iter().any(Light::is_area)
    }

    /// Whether a traced sample is random even for a deterministic method: lit splats, or lit
    /// meshes (`meshes`), whose lighting [`Lighting::draws`].
    pub fn draws_for(&self, meshes: bool) -> bool {
        (self.is_on() || meshes) && self.draws()
    }

    /// Lit(x, n, v, c) of particle `id` hit at distance `t` along `ray` with unit normal `n`:
    /// `c` itself for an emissive set, the headlight when there are no lights. Light j is
    /// sampled at `sample(j, light)` and seen from x with visibility `visible(j, x, incident)`,
    /// asked only where the light contributes (a shadow ray there would change nothing).
    #[allow(clippy::too_many_arguments)]
    pub fn shade(
        &self,
        c: Vec3,
        id: u32,
        ray: &Ray,
        t: f32,
        n: Vec3,
        sample: impl Fn(usize, &Light) -> Vec2,
        visible: impl FnMut(usize, Vec3, &Incident) -> Vec3,
    ) -> Vec3 {
        self.shade_material(self.material(id), c, ray, t, n, sample, visible)
    }

    /// [`Lighting::shade`] with `material` given rather than looked up by particle (how a mesh
    /// surface is lit, [`crate::mesh`]).
    #[allow(clippy::too_many_arguments)]
    pub fn shade_material(
        &self,
        material: &Material,
        c: Vec3,
        ray: &Ray,
        t: f32,
        n: Vec3,
        sample: impl Fn(usize, &Light) -> Vec2,
        mut visible: impl FnMut(usize, Vec3, &Incident) -> Vec3,
    ) -> Vec3 {
        if material.is_emissive() {
            return c;
        }
        let (x, v) = (ray.at(t), -ray.dir);
        if self.lights.is_empty() {
            return material.shade(c, n, v, [(headlight(ray, t), Vec3::ONE)]);
        }
        let mut sum = material.unlit(c);
        for (j, light) in self.lights.iter().enumerate() {
            let Some(incident) = light.incident(x, sample(j, light)) else { continue };
            let direct = material.direct(c, n, v, &incident);
            if direct != Vec3::ZERO {
                sum += direct * visible(j, x, &incident);
            }
        }
        sum
    }

    /// [`Lighting::shade`] with every light visible and sampled at its centre: the lighting of
    /// the raster pipelines, which have no shadows (vk_gaussian_splatting Lighting §3).
    pub fn shade_unshadowed(&self, c: Vec3, id: u32, ray: &Ray, t: f32, n: Vec3) -> Vec3 {
        self.shade_material_unshadowed(self.material(id), c, ray, t, n)
    }

    /// [`Lighting::shade_unshadowed`] with `material` given (how the raster pipelines light a
    /// mesh, [`crate::mesh`]).
    pub fn shade_material_unshadowed(&self, material: &Material, c: Vec3, ray: &Ray, t: f32, n: Vec3) -> Vec3 {
        self.shade_material(material, c, ray, t, n, |_, _| Vec2::splat(0.5), |_, _, _| Vec3::ONE)
    }

    /// The material of particle `id`.
    pub fn material(&self, id: u32) -> &Material {
        let k = self.sets.partition_point(|s| s.first <= id);
        &self.sets[k.saturating_sub(1)].material
    }

    /// Check the sets, materials, lights and shadow settings for `particles` particles.
    pub fn validate(&self, particles: usize) -> Result<(), String> {
        match self.sets.first() {
            Some(s) if s.first == 0 => {}
            _ => return Err("the first splat set must start at particle 0".into()),
        }
        for (i, w) in self.sets.windows(2).enumerate() {
            if w[1].first <= w[0].first {
                return Err(format!(
                    "splat set {} starts at {}, not after set {i} ({})",
                    i + 1,
                    w[1].first,
                    w[0].first
                ));
            }
        }
        if let Some(last) = self.sets.last()
            && particles > 0
            && last.first as usize >= particles
        {
            return Err(format!("splat set starting at {} is past the {particles} particles", last.first));
        }
        for (i, s) in self.sets.iter().enumerate() {
            s.material.validate().map_err(|e| format!("splat set {i}: {e}"))?;
        }
        if self.lights.len() > MAX_LIGHTS {
            return Err(format!("{} lights is more than the {MAX_LIGHTS} supported", self.lights.len()));
        }
        for (i, l) in self.lights.iter().enumerate() {
            l.validate().map_err(|e| format!("light {i}: {e}"))?;
        }
        if !(self.shadow_offset.is_finite() && self.shadow_offset >= 0.0) {
            return Err(format!("shadow offset {} must be finite and non-negative", self.shadow_offset));
        }
        if let Shadows::Sorted { k, threshold, colored } = self.shadows {
            if !(1..=MAX_SHADOW_K).contains(&k) {
                return Err(format!("shadow k = {k} is outside 1..={MAX_SHADOW_K}"));
            }
            if !(0.0..=1.0).contains(&threshold) || !(0.0..=1.0).contains(&colored) {
                return Err(format!("shadow threshold {threshold} and colored strength {colored} must lie in [0, 1]"));
            }
        }
        Ok(())
    }
}

/// Most lights of a world (their shadow-ray decisions are numbered per light).
pub const MAX_LIGHTS: usize = 64;

/// The decision slot of the shadow ray toward light `light` from the point shaded for sample
/// slot `slot`: disjoint from every slot a primary ray draws in, so that shadow decisions are
/// independent of the decisions that chose the point.
pub fn shadow_slot(slot: u32, light: usize) -> u32 {
    0x8000_0000 | (slot << 6) | light as u32
}

/// A renderer keeps the lighting it is given, or borrows it
/// (`TraceScene::with_lighting`, `Rasterizer::with_lighting`): a caller that renders many times
/// lends it rather than cloning it for every render.
impl<'a> From<&'a Lighting> for std::borrow::Cow<'a, Lighting> {
    fn from(lighting: &'a Lighting) -> Self {
        std::borrow::Cow::Borrowed(lighting)
    }
}

impl From<Lighting> for std::borrow::Cow<'_, Lighting> {
    fn from(lighting: Lighting) -> Self {
        std::borrow::Cow::Owned(lighting)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn dir_light(direction: Vec3) -> Light {
        Light { kind: LightKind::Directional { direction }, color: Vec3::ONE, intensity: 2.0, radius: 0.0 }
    }

    #[test]
    fn emissive_material_returns_the_colour_bit_for_bit() {
        let c = Vec3::new(0.123_456_7, 0.8, 1e-30);
        let inc = dir_light(-Vec3::Z).incident(Vec3::ZERO, Vec2::ZERO).unwrap();
        assert_eq!(Material::EMISSIVE.shade(c, Vec3::Z, Vec3::Z, [(inc, Vec3::ONE)]), c);
        assert!(Material::EMISSIVE.is_emissive());
        assert!(!Lighting::default().is_on());
    }

    #[test]
    fn lambert_and_blinn_phong_by_hand() {
        let m = Material {
            emissive: Vec3::ZERO,
            ambient: Vec3::splat(0.1),
            diffuse: Vec3::splat(0.5),
            specular: Vec3::splat(0.25),
            shininess: 4.0,
        };
        let c = Vec3::new(0.2, 0.4, 0.8);
        let l = Vec3::new(0.0, 0.6, 0.8);
        let inc = dir_light(-l).incident(Vec3::ZERO, Vec2::splat(0.5)).unwrap();
        let (n, v) = (Vec3::Z, Vec3::Z);
        let h = (l + v).normalize();
        let expected = 0.1 * c + 2.0 * (0.5 * c * 0.8 + Vec3::splat(0.25 * h.z.powi(4)));
        let got = m.shade(c, n, v, [(inc, Vec3::ONE)]);
        assert_relative_eq!(got.x, expected.x, epsilon = 1e-6);
        assert_relative_eq!(got.z, expected.z, epsilon = 1e-6);
        // From behind the surface: only the ambient part.
        assert_eq!(m.shade(c, -Vec3::Z, v, [(inc, Vec3::ONE)]), 0.1 * c);
    }

    #[test]
    fn point_falloff_and_spot_cone() {
        let p = Light {
            kind: LightKind::Point { position: Vec3::new(0.0, 0.0, 2.0) },
            color: Vec3::ONE,
            intensity: 8.0,
            radius: 0.0,
        };
        let inc = p.incident(Vec3::ZERO, Vec2::ZERO).unwrap();
        assert_relative_eq!(inc.irradiance.x, 2.0);
        assert_relative_eq!(inc.distance, 2.0);
        let spot = Light {
            kind: LightKind::Spot {
                position: Vec3::new(0.0, 0.0, 1.0),
                direction: -Vec3::Z,
                inner_deg: 10.0,
                outer_deg: 20.0,
            },
            ..p
        };
        assert_relative_eq!(spot.incident(Vec3::ZERO, Vec2::ZERO).unwrap().irradiance.x, 8.0);
        let at =
            |deg: f32| spot.incident(Vec3::new(deg.to_radians().tan(), 0.0, 0.0), Vec2::ZERO).map(|i| i.irradiance.x);
        assert_eq!(at(25.0), None);
        let mid = at(15.0).unwrap();
        assert!(mid > 0.0 && mid < at(5.0).unwrap());
    }

    #[test]
    fn disk_samples_stay_in_the_disk_and_cover_it() {
        let mut inside = 0;
        for i in 0..32 {
            for j in 0..32 {
                let d = concentric_disk(Vec2::new(i as f32 + 0.5, j as f32 + 0.5) / 32.0);
                assert!(d.length() <= 1.0 + 1e-6);
                inside += usize::from(d.length() < 0.5);
            }
        }
        // A quarter of the area lies within radius 1/2.
        assert!((inside as f32 / 1024.0 - 0.25).abs() < 0.01, "{inside}");
    }

    #[test]
    fn materials_are_looked_up_by_set() {
        let red = Material { emissive: Vec3::X, ..Material::EMISSIVE };
        let l = Lighting {
            sets: vec![SplatSet { first: 0, material: Material::EMISSIVE }, SplatSet { first: 5, material: red }],
            ..Lighting::default()
        };
        assert_eq!(*l.material(4), Material::EMISSIVE);
        assert_eq!(*l.material(5), red);
        assert_eq!(*l.material(1000), red);
        assert!(l.validate(10).is_ok());
        assert!(l.validate(5).is_err(), "set 1 would be empty");
        assert!(l.is_on());
    }
}
