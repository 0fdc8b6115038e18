//! Lighting a hit and the shadow rays toward each light (the vk_gaussian_splatting lighting
//! page §4: sorted, stochastic and exact shadows; meshes block the light). The GPU twin is
//! `shaders/shadow.wgsl`.

use super::TraceScene;
use crate::frame::Decide;
use crate::hit::Ray;
use crate::lighting::{Incident, Light, Shadows, shadow_slot};
use glam::{Vec2, Vec3};

impl TraceScene<'_> {
    /// Lit(x, n, v, c) ([`Lighting::shade`]) for colour `c` of particle `id` at distance `t`
    /// along `ray` with unit normal `n`, each light behind its shadow ray; area-light samples and
    /// shadow-ray decisions are drawn for sample slot `slot`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn lit(&self, c: Vec3, id: u32, t: f32, n: Vec3, ray: &Ray, decide: &impl Decide, slot: u32) -> Vec3 {
        let sample =
            |j: usize, light: &Light| if light.is_area() { decide.light_sample(j as u32, slot) } else { Vec2::ZERO };
        let visible =
            |j: usize, x: Vec3, incident: &Incident| self.visibility(x, incident, decide, shadow_slot(slot, j));
        self.lighting.shade(c, id, ray, t, n, sample, visible)
    }

    /// Visibility of a light from `x` ([`Shadows`]): the shadow ray starts `shadow_offset` along
    /// the light direction and ends at the light (vk_gaussian_splatting Lighting §4); `decide`
    /// draws the stochastic shadow ray's decisions in slot `slot`. A mesh on the way blocks the
    /// light.
    pub fn visibility(&self, x: Vec3, incident: &Incident, decide: &impl Decide, slot: u32) -> Vec3 {
        self.visibility_from(x, self.lighting.shadow_offset, incident, decide, slot)
    }

    pub(super) fn visibility_from(
        &self,
        x: Vec3,
        offset: f32,
        incident: &Incident,
        decide: &impl Decide,
        slot: u32,
    ) -> Vec3 {
        self.shadow_visibility(x, offset, incident, decide, slot, self.lighting.shadows)
    }

    /// The visibility of a light from `x` by shadow kind `shadows`: the shadow ray starts
    /// `offset` along the light direction and ends at the light; the meshes on the way let
    /// Π (1 − α) through ([`crate::mesh::Meshes::transmittance`]: an opaque one blocks it).
    /// How the world's shadow kind ([`TraceScene::visibility`]) and the path tracer see lights.
    pub fn shadow_visibility(
        &self,
        x: Vec3,
        offset: f32,
        incident: &Incident,
        decide: &impl Decide,
        slot: u32,
        shadows: Shadows,
    ) -> Vec3 {
        let shadow = Ray {
            origin: x + offset * incident.l,
            dir: incident.l,
            view: incident.l,
            t_min: self.settings.t_min,
            t_max: (incident.distance - offset).min(self.settings.t_max),
        };
        if shadow.t_max <= shadow.t_min || shadows == Shadows::None {
            return Vec3::ONE;
        }
        let meshes = self.meshes.transmittance(&shadow);
        if meshes == 0.0 {
            return Vec3::ZERO;
        }
        meshes
            * match shadows {
                Shadows::None => Vec3::ONE,
                Shadows::Exact => Vec3::splat(self.transmittance(&shadow) as f32),
                Shadows::Stochastic => Vec3::splat(if self.occluded(&shadow, decide, slot) { 0.0 } else { 1.0 }),
                Shadows::Sorted { k, threshold, colored } => self.sorted_shadow(&shadow, k, threshold, colored),
            }
    }

    /// The exact transmittance Π(1 − αᵢ) over every hit of `ray` (f64; order does not matter).
    pub fn transmittance(&self, ray: &Ray) -> f64 {
        let mut t = 1.0f64;
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, _| {
            if let Some(h) = self.hit(leaf, ray) {
                t *= 1.0 - f64::from(h.alpha);
            }
        });
        t
    }

    /// The unbiased stochastic shadow ray: one traversal, each hit accepted by Russian roulette
    /// (u < α, decisions of slot `slot`), stopped at the first accept. P(no accept) = Π(1 − αᵢ).
    pub fn occluded(&self, ray: &Ray, decide: &impl Decide, slot: u32) -> bool {
        let early = !decide.needs_position();
        let mut occluded = false;
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, t_max| {
            if occluded {
                return;
            }
            let id = self.ids[leaf as usize];
            if early && decide.particle(id, slot, Vec3::ZERO) >= self.alpha_bound[leaf as usize] {
                return;
            }
            let Some(h) = self.hit(leaf, ray) else { return };
            let u = decide.particle(id, slot, ray.at(h.t));
            if decide.accepts(id, u, h.alpha) {
                occluded = true;
                *t_max = f32::NEG_INFINITY;
            }
        });
        occluded
    }

    /// vk_gaussian_splatting's shadow ray (§4): the `k` nearest hits sorted, transmittance
    /// T ← T ⊙ ((1 − α) + `colored` α c) front to back; in shadow (0) once every channel of T is
    /// below `threshold`.
    pub(super) fn sorted_shadow(&self, ray: &Ray, k: usize, threshold: f32, colored: f32) -> Vec3 {
        let buf = self.next_k(ray, k, (ray.t_min, u32::MAX), None);
        let mut t = Vec3::ONE;
        for s in buf.as_slice() {
            let tint = if colored > 0.0 { self.shade(s.leaf, s.t, s.alpha, ray).color } else { Vec3::ZERO };
            t *= Vec3::splat(1.0 - s.alpha) + colored * s.alpha * tint;
            if t.max_element() < threshold {
                return Vec3::ZERO;
            }
        }
        t
    }

    /// Lit(x, n, v, c) of particle `id` at distance `t` along `ray` with unit normal `n`, each
    /// light behind a shadow ray through splats and meshes (slot 0's decisions): how the hybrid
    /// pipeline lights a rasterized pick.
    pub fn light_pick(&self, c: Vec3, id: u32, t: f32, n: Vec3, ray: &Ray, decide: &impl Decide) -> Vec3 {
        self.lit(c, id, t, n, ray, decide, 0)
    }
}
