//! CPU ray tracing through a BVH with every ray-tracing method of the seeds: exact, the k-buffer
//! multi-pass baseline, stochastic any-hit (Algorithm 1), its N-samples-per-traversal extension
//! (§3.5), the vk stochastic pass, and 3DGRT's stochastic depth sampling (the biased control).
//!
//! Each method is one function of a ray and a source of decisions ([`Decide`]). In rendering,
//! the decisions are the counter-based hashes of [`crate::rng::RayRng`]; in tests they can be
//! set outcome by outcome, so that the expectation of the very code that renders is computed
//! exactly by enumeration.

use crate::bvh::{Bvh, Bvh4, MAX_PRIMITIVES};
use crate::camera::Camera;
use crate::catalogue::{MethodId, Parameters};
use crate::composite::{ShadedHit, depth_order, shade_hit};
use crate::frame::{Decide, Frames, PixelFrames, Progress, RenderOutput, Sample, depth_before, render_tiles};
use crate::hit::{Hit, HitDistance, PreparedParticle, Ray, intersect, sphere_entry, to_canonical};
use crate::lighting::{Incident, Light, Lighting, Look, Shadows, shadow_slot};
use crate::mesh::{Meshes, SurfaceHit, fresnel, reflect, refract};
use crate::par;
use crate::particle::{Aabb, Scene};
use crate::rng::RayRng;
use crate::settings::{RenderError, RenderSettings, validate_scene};
use crate::sh;
use glam::{DVec3, Vec2, Vec3};
use std::cell::OnceCell;

pub use crate::catalogue::{DEFAULT_K, DEFAULT_MAX_PASSES, DEFAULT_MIN_TRANSMITTANCE, MAX_SLOTS};
// The sorted shadow pass keeps its hits in a k-buffer.
const _: () = assert!(crate::lighting::MAX_SHADOW_K <= MAX_SLOTS);

/// A ray-tracing method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Every hit through the BVH, sorted, Eq. 3.
    Exact,
    /// 3DGRT / vk "all pass": K hits per pass kept sorted and integrated, the next pass
    /// restarting behind the last hit, until `max_passes` or transmittance ≤ `min_transmittance`.
    KBuffer {
        /// Hits per pass.
        k: usize,
        /// Pass limit.
        max_passes: u32,
        /// Early-out transmittance (0 disables it; above 0 the result is truncated, not exact).
        min_transmittance: f32,
    },
    /// Algorithm 1: one traversal, Russian roulette on alpha, closest accepted hit, t_max
    /// clipped on accept, one shading per ray.
    Stochastic,
    /// §3.5: `m` traversals per frame, each carrying `n` independent instantiations.
    StochasticN {
        /// Traversals per frame.
        m: u32,
        /// Samples per traversal (≤ 64).
        n: u32,
    },
    /// vk stochastic pass: K sorted hits per pass, the pass accepted with probability
    /// 1 − T_pass and its radiance divided by it, else discarded.
    StochasticPass {
        /// Hits per pass.
        k: usize,
        /// Pass limit.
        max_passes: u32,
    },
    /// 3DGRT stochastic depth sampling: the first k accepted hits composited in order with
    /// their alphas. Biased (Sun et al. §5, Fig. 7): the control the tests must reject.
    DepthSampling {
        /// Accepted hits composited.
        k: usize,
    },
    /// Every particle as an opaque ellipsoid, its bounding ellipsoid in the BVH
    /// ([`bounding_radius`]: the cutoff, or nearer where a faint particle is culled sooner): the
    /// closest entry is shaded. Not an estimator of Eq. 3: the cost of a plain mesh-like ray
    /// through the same BVH, for benchmarks.
    Opaque,
}

impl Method {
    /// The k-buffer with the vk defaults.
    pub const KBUFFER: Method =
        Method::KBuffer { k: DEFAULT_K, max_passes: DEFAULT_MAX_PASSES, min_transmittance: DEFAULT_MIN_TRANSMITTANCE };
    /// The stochastic pass with the vk defaults.
    pub const STOCHASTIC_PASS: Method = Method::StochasticPass { k: DEFAULT_K, max_passes: DEFAULT_MAX_PASSES };

    /// The method as the [catalogue](crate::catalogue) knows it: its entry, and its parameters
    /// (the others at their defaults); the inverse of [`MethodId::algorithm`].
    pub fn identity(&self) -> (MethodId, Parameters) {
        let d = Parameters::default();
        match *self {
            Method::Exact => (MethodId::Exact, d),
            Method::KBuffer { k, max_passes, min_transmittance } => {
                (MethodId::KBuffer, Parameters { k, max_passes, min_transmittance, ..d })
            }
            Method::Stochastic => (MethodId::Stochastic, d),
            Method::StochasticN { m, n } => (MethodId::StochasticN, Parameters { m, n, ..d }),
            Method::StochasticPass { k, max_passes } => (MethodId::StochasticPass, Parameters { k, max_passes, ..d }),
            Method::DepthSampling { k } => (MethodId::DepthSampling, Parameters { k, ..d }),
            Method::Opaque => (MethodId::Opaque, d),
        }
    }

    /// The method's entry in the catalogue (its name, its code in the GPU kernel).
    pub fn id(&self) -> MethodId {
        self.identity().0
    }

    /// Whether frames differ (the method draws random decisions).
    pub fn is_stochastic(&self) -> bool {
        self.id().entry().stochastic
    }

    /// Check the method's parameters against the catalogue's [limits](crate::catalogue::Limits),
    /// and that `stochastic-n`'s m × n samples fit the decision slots of a ray.
    pub fn validate(&self) -> Result<(), RenderError> {
        let (_, p) = self.identity();
        p.validate()?;
        let samples = u64::from(p.m) * u64::from(p.n);
        if samples > u64::from(MAX_PRIMARY_SLOTS) {
            return Err(RenderError::Settings(format!(
                "stochastic-n draws m × n = {samples} samples a ray, more than {MAX_PRIMARY_SLOTS}"
            )));
        }
        Ok(())
    }
}

/// A scene ready for ray tracing: BVH, particles in leaf order, settings.
pub struct TraceScene<'a> {
    scene: &'a Scene,
    settings: RenderSettings,
    /// The binary tree (what the GPU traverses).
    bvh: Bvh,
    /// Its 4-wide collapse (what the CPU traverses): the same leaves.
    wide: Bvh4,
    /// Prepared particles in BVH leaf order.
    prims: Vec<PreparedParticle>,
    /// Scene index of each leaf-order particle.
    ids: Vec<u32>,
    /// min(opacity, alpha clamp) of each leaf-order particle: the largest alpha it can take,
    /// which rejects most hits on the draw alone (beside `ids`, so that the early reject reads
    /// 8 bytes a particle).
    alpha_bound: Vec<f32>,
    /// Squared radius (in standard deviations) of each leaf-order particle's bounding
    /// ellipsoid, [`bounding_radius`].
    radius_sq: Vec<f32>,
    /// Materials, lights and shadows ([`crate::lighting`]); off by default.
    lighting: Lighting,
    /// Opaque meshes that clip every ray ([`crate::mesh`]); none by default.
    meshes: Meshes,
}

/// The radius, in standard deviations, of the ellipsoid a particle is bounded by in the BVH: its
/// visible extent ([`crate::kernel::KernelParams::visible_extent`]) where hits are taken at
/// the maximum density along the ray, which lies inside it whenever the hit is kept; the cutoff
/// with [`HitDistance::Center`], whose hit point may lie anywhere inside the cutoff ellipsoid.
pub fn bounding_radius(settings: &RenderSettings, opacity: f32) -> f32 {
    match settings.hit_distance {
        HitDistance::Mean => settings.kernel.visible_extent(opacity),
        HitDistance::Center => settings.kernel.cutoff,
    }
}

/// A candidate hit in a k-buffer, ordered by (t, id).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Slot {
    pub(crate) t: f32,
    pub(crate) id: u32,
    pub(crate) leaf: u32,
    pub(crate) alpha: f32,
}

impl Slot {
    pub(crate) const EMPTY: Slot = Slot { t: f32::INFINITY, id: u32::MAX, leaf: 0, alpha: 0.0 };

    /// Whether the slot holds a hit.
    pub(crate) fn is_hit(&self) -> bool {
        self.id != u32::MAX
    }
}

/// Up to `cap` hits kept sorted by (t, id).
pub(crate) struct KBuf {
    slots: [Slot; MAX_SLOTS],
    len: usize,
    cap: usize,
}

impl KBuf {
    fn new(cap: usize) -> Self {
        Self { slots: [Slot::EMPTY; MAX_SLOTS], len: 0, cap }
    }

    fn is_full(&self) -> bool {
        self.len == self.cap
    }

    /// The last kept hit (the farthest).
    fn last(&self) -> Slot {
        if self.len == 0 { Slot::EMPTY } else { self.slots[self.len - 1] }
    }

    /// Whether a hit at (t, id) would be kept.
    fn admits(&self, t: f32, id: u32) -> bool {
        !self.is_full() || depth_before(t, id, self.last().t, self.last().id)
    }

    /// Insert, dropping the farthest when full (insertion sort, as the vk any-hit shader does).
    fn insert(&mut self, s: Slot) {
        let mut i = if self.is_full() { self.len - 1 } else { self.len };
        if !self.is_full() {
            self.len += 1;
        }
        while i > 0 && depth_before(s.t, s.id, self.slots[i - 1].t, self.slots[i - 1].id) {
            self.slots[i] = self.slots[i - 1];
            i -= 1;
        }
        self.slots[i] = s;
    }

    pub(crate) fn as_slice(&self) -> &[Slot] {
        &self.slots[..self.len]
    }
}

/// Front-to-back integration state (Eq. 3), in f64.
#[derive(Clone, Copy)]
struct Integrator {
    radiance: DVec3,
    normal: DVec3,
    transmittance: f64,
    /// Iso-opacity depth and the particle that set it (vk_gaussian_splatting Lighting §1.1).
    depth: Option<(f32, u32)>,
    /// The farthest hit so far and its particle (the stochastic pass's fallback, §1.3).
    farthest: Option<(f32, u32)>,
}

impl Integrator {
    const START: Integrator =
        Integrator { radiance: DVec3::ZERO, normal: DVec3::ZERO, transmittance: 1.0, depth: None, farthest: None };

    /// Composite one more hit behind the others, with colour `color` (its SH colour, or its lit
    /// colour in the volumetric look).
    fn add(&mut self, h: &ShadedHit, color: Vec3, iso: f32) {
        let alpha = f64::from(h.alpha);
        let w = self.transmittance * alpha;
        self.radiance += w * color.as_dvec3();
        self.normal += w * h.normal.as_dvec3();
        self.transmittance *= 1.0 - alpha;
        if self.depth.is_none() && self.transmittance < f64::from(iso) {
            self.depth = Some((h.t, h.index));
        }
        self.farthest = Some((h.t, h.index));
    }

    fn unit_normal(&self, dir: Vec3) -> Vec3 {
        let c = crate::composite::Composite {
            radiance: self.radiance,
            transmittance: self.transmittance,
            depth: self.depth.map(|d| d.0),
            normal: self.normal,
            hits: usize::from(self.farthest.is_some()),
        };
        c.unit_normal(dir)
    }

    /// The integrated hits over what lies behind them (Eq. 3): L + T × behind, coverage
    /// 1 − T + T × its coverage. Depth and normal are the splats' where they reach the
    /// iso-opacity threshold, else those of a surface behind, if any.
    fn over(&self, behind: &Sample, dir: Vec3) -> Sample {
        let splats_first = self.depth.is_some() || behind.depth.is_none();
        Sample {
            color: self.radiance + self.transmittance * behind.color,
            alpha: 1.0 - self.transmittance + self.transmittance * behind.alpha,
            depth: if splats_first { self.depth.map(|d| d.0) } else { behind.depth },
            normal: if splats_first { self.unit_normal(dir) } else { behind.normal },
            picked: None,
        }
    }
}

impl<'a> TraceScene<'a> {
    /// Validate, build the BVH over the particles' cutoff boxes and lay the particles out in
    /// leaf order.
    pub fn new(scene: &'a Scene, settings: RenderSettings) -> Result<Self, RenderError> {
        validate_scene(scene, &settings)?;
        if scene.particles.len() > MAX_PRIMITIVES {
            return Err(RenderError::Settings(format!(
                "{} particles exceed the {MAX_PRIMITIVES} a BVH can index",
                scene.particles.len()
            )));
        }
        let (radii, boxes): (Vec<f32>, Vec<Aabb>) = par::map(&scene.particles, |p| {
            let radius = bounding_radius(&settings, p.opacity);
            (radius, p.aabb(radius).padded())
        })
        .into_iter()
        .unzip();
        let bvh = Bvh::build(&boxes);
        let wide = Bvh4::from_binary(&bvh);
        let prims = par::map(&bvh.order, |&i| PreparedParticle::new(&scene.particles[i as usize]));
        let ids = bvh.order.clone();
        let clamp = settings.kernel.alpha_clamp;
        let alpha_bound = bvh.order.iter().map(|&i| scene.particles[i as usize].opacity.min(clamp)).collect();
        let radius_sq = bvh.order.iter().map(|&i| radii[i as usize].powi(2)).collect();
        let lighting = Lighting::default();
        Ok(Self { scene, settings, bvh, wide, prims, ids, alpha_bound, radius_sq, lighting, meshes: Meshes::none() })
    }

    /// The same scene lit by `lighting` (checked against the scene's particle count).
    pub fn with_lighting(mut self, lighting: Lighting) -> Result<Self, RenderError> {
        lighting.validate(self.scene.particles.len()).map_err(RenderError::Settings)?;
        self.lighting = lighting;
        Ok(self)
    }

    /// The same scene among `meshes`, which clip every ray and shadow the splats.
    pub fn with_meshes(mut self, meshes: Meshes) -> Self {
        self.meshes = meshes;
        self
    }

    /// The lighting.
    pub fn lighting(&self) -> &Lighting {
        &self.lighting
    }

    /// The meshes.
    pub fn meshes(&self) -> &Meshes {
        &self.meshes
    }

    /// Whether a sample is random even for a deterministic method: lit splats or lit meshes
    /// with stochastic shadow rays or area lights.
    pub fn is_random(&self) -> bool {
        self.lighting.draws_for(!self.meshes.is_empty())
    }

    /// The settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The binary BVH (the GPU's layout).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The 4-wide BVH the CPU traverses, collapsed from [`TraceScene::bvh`].
    pub fn wide_bvh(&self) -> &Bvh4 {
        &self.wide
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        self.scene
    }

    /// Prepared particles in BVH leaf order (what a GPU uploads beside [`TraceScene::bvh`]).
    pub fn leaf_particles(&self) -> &[PreparedParticle] {
        &self.prims
    }

    /// Scene index of each leaf-order particle.
    pub fn leaf_ids(&self) -> &[u32] {
        &self.ids
    }

    /// The ray with the settings' range.
    pub fn clip(&self, ray: Ray) -> Ray {
        Ray { t_min: self.settings.t_min, t_max: self.settings.t_max, ..ray }
    }

    #[inline(always)]
    fn hit(&self, leaf: u32, ray: &Ray) -> Option<Hit> {
        let s = &self.settings;
        intersect(&self.prims[leaf as usize], self.ids[leaf as usize], ray, &s.kernel, s.hit_distance)
    }

    pub(crate) fn shade(&self, leaf: u32, t: f32, alpha: f32, ray: &Ray) -> ShadedHit {
        let hit = Hit { t, alpha, index: self.ids[leaf as usize] };
        shade_hit(self.scene, &self.prims[leaf as usize], hit, ray, &self.settings)
    }

    /// Whether sorted methods light every hit before integrating ([`Look::Volumetric`]).
    fn volumetric(&self) -> bool {
        self.lighting.is_on() && self.lighting.look == Look::Volumetric
    }

    /// A shaded pick seen as an opaque sample, lit at its own position and normal (§1.2, §2.2).
    fn opaque_sample<D: Decide>(&self, leaf: u32, t: f32, seg: &Segment<D>, slot: u32) -> Sample {
        let h = self.shade(leaf, t, 1.0, &seg.ray);
        let color = self.lit(h.color, h.index, t, h.normal, &seg.ray, &seg.decide, slot);
        Sample { color: color.as_dvec3(), alpha: 1.0, depth: Some(t), normal: h.normal, picked: Some(h.index) }
    }

    fn background_sample(&self) -> Sample {
        Sample::background(self.settings.background)
    }

    /// What lies behind the splats of a segment: the background, or the shaded mesh surface
    /// that clips it (computed once, when a method first looks past the splats).
    fn behind<D: Decide>(&self, seg: &Segment<D>) -> Sample {
        *seg.behind.get_or_init(|| match &seg.surface {
            None => self.background_sample(),
            Some(hit) => self.surface_sample(seg, hit),
        })
    }

    /// Eq. 3 front to back over the hits of a k-buffer, continuing `acc`; in the volumetric look
    /// each hit is lit first.
    fn integrate<D: Decide>(&self, acc: &mut Integrator, buf: &KBuf, seg: &Segment<D>) {
        for s in buf.as_slice() {
            self.add(acc, &self.shade(s.leaf, s.t, s.alpha, &seg.ray), seg);
        }
    }

    fn add<D: Decide>(&self, acc: &mut Integrator, h: &ShadedHit, seg: &Segment<D>) {
        let color = if self.volumetric() {
            self.lit(h.color, h.index, h.t, h.normal, &seg.ray, &seg.decide, 0)
        } else {
            h.color
        };
        acc.add(h, color, self.settings.iso_threshold);
    }

    /// The sample of a sorted integration over what lies behind it. Lit in the surface look
    /// (vk_gaussian_splatting Lighting §1.1, §2.1): the integrated radiance L, as the base colour,
    /// lit once at the iso-opacity depth with the integrated normal and the material of the
    /// particle that set the depth, then L + T × behind; a ray that never reaches the threshold
    /// shows what lies behind.
    fn finish<D: Decide>(&self, acc: &Integrator, seg: &Segment<D>) -> Sample {
        let behind = self.behind(seg);
        let unlit = acc.over(&behind, seg.ray.dir);
        if !self.lighting.is_on() || self.volumetric() {
            return unlit;
        }
        let Some((t, id)) = acc.depth else { return behind };
        let base = acc.radiance.as_vec3();
        let lit = self.lit(base, id, t, unlit.normal, &seg.ray, &seg.decide, 0).as_dvec3();
        Sample { color: lit + acc.transmittance * behind.color, picked: Some(id), ..unlit }
    }

    /// Lit(x, n, v, c) ([`Lighting::shade`]) for colour `c` of particle `id` at distance `t`
    /// along `ray` with unit normal `n`, each light behind its shadow ray; area-light samples and
    /// shadow-ray decisions are drawn for sample slot `slot`.
    #[allow(clippy::too_many_arguments)]
    fn lit(&self, c: Vec3, id: u32, t: f32, n: Vec3, ray: &Ray, decide: &impl Decide, slot: u32) -> Vec3 {
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

    fn visibility_from(&self, x: Vec3, offset: f32, incident: &Incident, decide: &impl Decide, slot: u32) -> Vec3 {
        self.shadow_visibility(x, offset, incident, decide, slot, self.lighting.shadows)
    }

    /// The visibility of a light from `x` by shadow kind `shadows`: the shadow ray starts
    /// `offset` along the light direction and ends at the light; a mesh on the way blocks it.
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
        if self.meshes.occludes(&shadow) {
            return Vec3::ZERO;
        }
        match shadows {
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
        self.wide.traverse(ray, &mut t_max, |leaf, _| {
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
        self.wide.traverse(ray, &mut t_max, |leaf, t_max| {
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
    fn sorted_shadow(&self, ray: &Ray, k: usize, threshold: f32, colored: f32) -> Vec3 {
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

    /// The shaded colour S of a mesh surface hit by the segment's ray ([`crate::mesh`]): the
    /// material's local share lit by the world's lights (shadow rays through meshes and splats),
    /// plus the mirror and glass shares from secondary rays traced by the same method one bounce
    /// deeper, while the bounce limit allows. Depth and normal are the surface's.
    fn surface_sample<D: Decide>(&self, seg: &Segment<D>, hit: &SurfaceHit) -> Sample {
        let material = self.meshes.material(hit.mesh);
        let d = seg.ray.dir;
        let (_, n, outside) = hit.facing(d);
        let x = seg.ray.at(hit.t);
        let mut color = Vec3::ZERO;
        if material.local_share() > 0.0 {
            let (decide, ray) = (&seg.decide, &seg.ray);
            let offset = surface_offset(x);
            let sample =
                |j: usize, light: &Light| if light.is_area() { decide.light_sample(j as u32, 0) } else { Vec2::ZERO };
            let visible = |j: usize, x: Vec3, incident: &Incident| {
                self.visibility_from(x, offset, incident, decide, shadow_slot(0, j))
            };
            let lit = self.lighting.shade_material(&material.shading, material.color, ray, hit.t, n, sample, visible);
            color += material.local_share() * lit;
        }
        if seg.decide.depth < self.settings.max_bounces {
            let next = seg.decide.deeper();
            let trace = |dir: Vec3| self.secondary(&seg.method, x, dir, next);
            if material.mirror > 0.0 {
                color += material.mirror * trace(reflect(d, n));
            }
            if material.transmission > 0.0 {
                let eta = if outside { 1.0 / material.ior } else { material.ior };
                let f = fresnel((-d.dot(n)).clamp(0.0, 1.0), eta);
                let reflected = if f > 0.0 { f * trace(reflect(d, n)) } else { Vec3::ZERO };
                let refracted = match refract(d, n, eta) {
                    Some(dir) if f < 1.0 => (1.0 - f) * trace(dir),
                    _ => Vec3::ZERO,
                };
                color += material.transmission * (reflected + refracted);
            }
        }
        Sample { color: color.as_dvec3(), alpha: 1.0, depth: Some(hit.t), normal: n, picked: None }
    }

    /// The radiance of a secondary ray from surface point `x` along `dir`: the splats from
    /// x on (the line continues exactly the mirrored or refracted line), the meshes from
    /// [`surface_offset`] on, so that the surface does not hit itself.
    fn secondary<D: Decide>(&self, method: &Method, x: Vec3, dir: Vec3, decide: Bounce<D>) -> Vec3 {
        let ray = Ray { origin: x, dir, view: dir, t_min: 0.0, t_max: self.settings.t_max };
        self.trace_ray(method, &ray, decide, surface_offset(x)).color.as_vec3()
    }

    /// The shaded colour of mesh surface `hit` on `ray` as the ray tracer sees it: lit with
    /// shadow rays, mirror and glass bounces traced by `method` (the hybrid pipeline's
    /// continuation of a rasterized first hit, vk_gaussian_splatting Lighting §5).
    pub fn surface(&self, method: &Method, ray: &Ray, hit: &SurfaceHit, decide: &impl Decide) -> Sample {
        let seg = Segment {
            ray: Ray { t_max: hit.t, ..*ray },
            surface: Some(*hit),
            method: *method,
            decide: Bounce::camera(decide),
            behind: OnceCell::new(),
        };
        self.surface_sample(&seg, hit)
    }

    /// Lit(x, n, v, c) of particle `id` at distance `t` along `ray` with unit normal `n`, each
    /// light behind a shadow ray through splats and meshes (slot 0's decisions): how the hybrid
    /// pipeline lights a rasterized pick.
    pub fn light_pick(&self, c: Vec3, id: u32, t: f32, n: Vec3, ray: &Ray, decide: &impl Decide) -> Vec3 {
        self.lit(c, id, t, n, ray, decide, 0)
    }

    /// One sample of `method` for `ray` (already clipped to the settings' range).
    pub fn sample(&self, method: &Method, ray: &Ray, decide: &impl Decide) -> Sample {
        self.trace_ray(method, ray, Bounce::camera(decide), 0.0)
    }

    /// The segment of `ray` in front of its closest mesh beyond `mesh_t_min`.
    fn segment<'d, D: Decide>(
        &self,
        method: &Method,
        ray: &Ray,
        decide: Bounce<'d, D>,
        mesh_t_min: f32,
    ) -> Segment<'d, D> {
        let surface = self.meshes.closest(&Ray { t_min: ray.t_min.max(mesh_t_min), ..*ray });
        let ray = Ray { t_max: surface.map_or(ray.t_max, |s| s.t), ..*ray };
        Segment { ray, surface, method: *method, decide, behind: OnceCell::new() }
    }

    /// One sample of `method` along `ray`, `decide.depth` bounces after the camera ray: the ray
    /// is clipped at the closest mesh beyond `mesh_t_min`, whose shaded colour takes the
    /// background's place.
    fn trace_ray<D: Decide>(&self, method: &Method, ray: &Ray, decide: Bounce<D>, mesh_t_min: f32) -> Sample {
        let seg = self.segment(method, ray, decide, mesh_t_min);
        match *method {
            Method::Exact => self.exact(&seg),
            Method::KBuffer { k, max_passes, min_transmittance } => {
                self.kbuffer(&seg, k, max_passes, min_transmittance)
            }
            Method::Stochastic => self.stochastic(&seg, 0),
            Method::StochasticN { m, n } => {
                let mut sum = Sample { alpha: 0.0, ..Sample::background(Vec3::ZERO) };
                for pass in 0..m {
                    let s = self.stochastic_n(&seg, n as usize, pass * n);
                    sum.color += s.color;
                    sum.alpha += s.alpha;
                    if pass == 0 {
                        (sum.depth, sum.normal, sum.picked) = (s.depth, s.normal, s.picked);
                    }
                }
                sum.color /= f64::from(m);
                sum.alpha /= f64::from(m);
                sum
            }
            Method::StochasticPass { k, max_passes } => self.stochastic_pass(&seg, k, max_passes),
            Method::DepthSampling { k } => self.depth_sampling(&seg, k),
            Method::Opaque => self.opaque(&seg),
        }
    }

    /// Exact: every hit along the ray through the BVH, sorted front to back, Eq. 3 (lit by the
    /// look when lighting is on; `decide` draws only shadow rays and area-light samples).
    fn exact<D: Decide>(&self, seg: &Segment<D>) -> Sample {
        let mut acc = Integrator::START;
        for s in &self.sorted_hits(&seg.ray) {
            self.add(&mut acc, &self.shade(s.leaf, s.t, s.alpha, &seg.ray), seg);
        }
        self.finish(&acc, seg)
    }

    /// Every hit of `ray` through the BVH, sorted front to back by (t, id) (the order of
    /// `composite::sort_front_to_back`), as small records: each is shaded once, in that order.
    pub(crate) fn sorted_hits(&self, ray: &Ray) -> Vec<Slot> {
        let mut found = Vec::with_capacity(64);
        let mut t_max = ray.t_max;
        self.wide.traverse(ray, &mut t_max, |leaf, _| {
            if let Some(h) = self.hit(leaf, ray) {
                found.push(Slot { t: h.t, id: h.index, leaf, alpha: h.alpha });
            }
        });
        found.sort_unstable_by(|a, b| depth_order(a.t, a.id, b.t, b.id));
        found
    }

    /// The k closest hits strictly behind (after_t, after_id), by (t, id); when `decide` is
    /// given, only hits accepted in slot 0 count (depth sampling).
    fn next_k(
        &self,
        ray: &Ray,
        k: usize,
        after: (f32, u32),
        accepted: Option<&dyn Fn(u32, Vec3, f32) -> bool>,
    ) -> KBuf {
        let mut buf = KBuf::new(k);
        let mut t_max = ray.t_max;
        self.wide.traverse(ray, &mut t_max, |leaf, t_max| {
            let Some(h) = self.hit(leaf, ray) else { return };
            let id = self.ids[leaf as usize];
            if !depth_before(after.0, after.1, h.t, id) || !buf.admits(h.t, id) {
                return;
            }
            if let Some(accept) = accepted
                && !accept(id, ray.at(h.t), h.alpha)
            {
                return;
            }
            buf.insert(Slot { t: h.t, id, leaf, alpha: h.alpha });
            if buf.is_full() {
                *t_max = buf.last().t;
            }
        });
        buf
    }

    /// k-buffer multi-pass (3DGRT / vk baseline).
    fn kbuffer<D: Decide>(&self, seg: &Segment<D>, k: usize, max_passes: u32, min_transmittance: f32) -> Sample {
        let mut acc = Integrator::START;
        let mut after = (seg.ray.t_min, u32::MAX);
        for _ in 0..max_passes {
            if acc.transmittance <= f64::from(min_transmittance) {
                break;
            }
            let buf = self.next_k(&seg.ray, k, after, None);
            self.integrate(&mut acc, &buf, seg);
            if !buf.is_full() {
                break;
            }
            after = (buf.last().t, buf.last().id);
        }
        self.finish(&acc, seg)
    }

    /// Algorithm 1: the closest hit accepted by Russian roulette (u < α), found in one
    /// traversal that clips t_max at every accept; shaded once (Eq. 6).
    ///
    /// With a position-free generator u is drawn before the kernel: α ≤ min(opacity, clamp),
    /// so u ≥ that bound rejects the hit without evaluating the exponential; the decision is
    /// the same because u is a hash, not a stream.
    fn stochastic<D: Decide>(&self, seg: &Segment<D>, slot: u32) -> Sample {
        match self.first_accepted(&seg.ray, &seg.decide, slot) {
            Some(best) => self.opaque_sample(best.leaf, best.t, seg, slot),
            None => self.behind(seg),
        }
    }

    /// Algorithm 1's traversal: the closest hit of `ray` accepted in slot `slot`, if any.
    pub(crate) fn first_accepted(&self, ray: &Ray, decide: &impl Decide, slot: u32) -> Option<Slot> {
        let early = !decide.needs_position();
        let mut best = Slot::EMPTY;
        let mut t_max = ray.t_max;
        self.wide.traverse(ray, &mut t_max, |leaf, t_max| {
            let id = self.ids[leaf as usize];
            let u = if early {
                let u = decide.particle(id, slot, Vec3::ZERO);
                if u >= self.alpha_bound[leaf as usize] {
                    return;
                }
                u
            } else {
                0.0
            };
            let Some(h) = self.hit(leaf, ray) else { return };
            if !depth_before(h.t, id, best.t, best.id) {
                return;
            }
            let u = if early { u } else { decide.particle(id, slot, ray.at(h.t)) };
            if decide.accepts(id, u, h.alpha) {
                best = Slot { t: h.t, id, leaf, alpha: h.alpha };
                *t_max = h.t;
            }
        });
        best.is_hit().then_some(best)
    }

    /// §3.5: `n` independent instantiations of Algorithm 1 in one traversal, slots
    /// `first_slot..first_slot + n`; the traversal is clipped at the farthest slot's hit.
    fn stochastic_n<D: Decide>(&self, seg: &Segment<D>, n: usize, first_slot: u32) -> Sample {
        let best = self.first_accepted_n(&seg.ray, &seg.decide, first_slot, n);
        let mut color = DVec3::ZERO;
        let mut alpha = 0.0;
        let mut first = self.background_sample();
        for (slot, b) in (first_slot..).zip(&best[..n]) {
            let s = if b.is_hit() { self.opaque_sample(b.leaf, b.t, seg, slot) } else { self.behind(seg) };
            color += s.color;
            alpha += s.alpha;
            if slot == first_slot {
                first = s;
            }
        }
        Sample { color: color / n as f64, alpha: alpha / n as f64, ..first }
    }

    /// The traversal of §3.5: for each slot of `first_slot..first_slot + n`, the closest hit of
    /// `ray` accepted in that slot ([`Slot::EMPTY`] where none is); the traversal is clipped at
    /// the farthest slot's hit.
    pub(crate) fn first_accepted_n(
        &self,
        ray: &Ray,
        decide: &impl Decide,
        first_slot: u32,
        n: usize,
    ) -> [Slot; MAX_SLOTS] {
        let early = !decide.needs_position();
        let mut best = [Slot::EMPTY; MAX_SLOTS];
        let mut u = [0.0f32; MAX_SLOTS];
        let mut t_max = ray.t_max;
        let draw = decide.slot_draws(first_slot, n);
        self.wide.traverse(ray, &mut t_max, |leaf, t_max| {
            let id = self.ids[leaf as usize];
            if early {
                let bound = self.alpha_bound[leaf as usize];
                draw(id, Vec3::ZERO, &mut u[..n]);
                if u[..n].iter().all(|&us| us >= bound) {
                    return;
                }
            }
            let Some(h) = self.hit(leaf, ray) else { return };
            let mut farthest = 0.0f32;
            for (s, (b, &us)) in best[..n].iter_mut().zip(&u[..n]).enumerate() {
                if depth_before(h.t, id, b.t, b.id) {
                    let us = if early { us } else { decide.particle(id, first_slot + s as u32, ray.at(h.t)) };
                    if decide.accepts(id, us, h.alpha) {
                        *b = Slot { t: h.t, id, leaf, alpha: h.alpha };
                    }
                }
                farthest = farthest.max(b.t);
            }
            *t_max = farthest.min(ray.t_max);
        });
        best
    }

    /// vk stochastic pass: each pass integrates its K sorted hits from T = 1; it is accepted
    /// with probability O = 1 − T_pass and returns L_pass / O, else it is discarded and the
    /// next pass starts behind it. E = Σⱼ (Πᵢ<ⱼ Tᵢ) Lⱼ + (Π Tⱼ) background: Eq. 3 exactly.
    fn stochastic_pass<D: Decide>(&self, seg: &Segment<D>, k: usize, max_passes: u32) -> Sample {
        let mut accepted = None;
        self.passes(&seg.ray, k, max_passes, |pass, acc| {
            let opacity = 1.0 - acc.transmittance;
            if seg.decide.accepts_pass(f64::from(seg.decide.pass(pass)), opacity) {
                accepted = Some(self.pass_sample(acc, seg));
            }
            accepted.is_none()
        });
        accepted.unwrap_or_else(|| self.behind(seg))
    }

    /// The exact expectation of the stochastic pass (its oracle when lit): Σⱼ (Πᵢ<ⱼ Tᵢ) Oⱼ Sⱼ +
    /// (Π Tⱼ) behind, with Sⱼ the sample pass j returns when accepted and `behind` the
    /// background or the mesh surface clipping the ray. Unlit Sⱼ = Lⱼ / Oⱼ and this is Eq. 3;
    /// lit it is not, since the specular term is not proportional to the base colour. `decide`
    /// draws only shadow rays, area-light samples and the decisions of secondary rays.
    pub fn stochastic_pass_expectation(&self, ray: &Ray, decide: &impl Decide, k: usize, max_passes: u32) -> DVec3 {
        let seg = self.segment(&Method::StochasticPass { k, max_passes }, ray, Bounce::camera(decide), 0.0);
        let mut reach = 1.0f64;
        let mut sum = DVec3::ZERO;
        self.passes(&seg.ray, k, max_passes, |_, acc| {
            let opacity = 1.0 - acc.transmittance;
            if opacity > 0.0 {
                sum += reach * opacity * self.pass_sample(acc, &seg).color;
            }
            reach *= acc.transmittance;
            true
        });
        sum + reach * self.behind(&seg).color
    }

    /// The passes of K sorted hits along `ray`, each integrated from T = 1 and handed to
    /// `visit(pass, integrator)` until it returns false, a pass is not full or `max_passes`.
    fn passes(&self, ray: &Ray, k: usize, max_passes: u32, mut visit: impl FnMut(u32, &Integrator) -> bool) {
        let mut after = (ray.t_min, u32::MAX);
        for pass in 0..max_passes {
            let buf = self.next_k(ray, k, after, None);
            if buf.len == 0 {
                return;
            }
            let mut acc = Integrator::START;
            for s in buf.as_slice() {
                let h = self.shade(s.leaf, s.t, s.alpha, ray);
                acc.add(&h, h.color, self.settings.iso_threshold);
            }
            if !visit(pass, &acc) || !buf.is_full() {
                return;
            }
            after = (buf.last().t, buf.last().id);
        }
    }

    /// An accepted pass as one opaque sample: colour L_pass / O. Lit (vk_gaussian_splatting
    /// Lighting §1.3, §2.3), that base colour is lit with the pass's integrated normal at its
    /// iso-depth, or else at its farthest hit, with the material of the particle there.
    fn pass_sample<D: Decide>(&self, acc: &Integrator, seg: &Segment<D>) -> Sample {
        let (t, id) = acc.depth.or(acc.farthest).expect("a pass with hits has a farthest hit");
        let normal = acc.unit_normal(seg.ray.dir);
        let base = acc.radiance / (1.0 - acc.transmittance);
        let color = if self.lighting.is_on() {
            self.lit(base.as_vec3(), id, t, normal, &seg.ray, &seg.decide, 0).as_dvec3()
        } else {
            base
        };
        Sample { color, alpha: 1.0, depth: Some(t), normal, picked: None }
    }

    /// 3DGRT stochastic depth sampling: the k closest hits accepted by roulette (slot 0),
    /// composited in order with their alphas (biased: α counts twice).
    fn depth_sampling<D: Decide>(&self, seg: &Segment<D>, k: usize) -> Sample {
        let buf = self.first_k_accepted(&seg.ray, &seg.decide, k, 0);
        let mut acc = Integrator::START;
        self.integrate(&mut acc, &buf, seg);
        Sample { depth: buf.as_slice().first().map(|s| s.t), ..self.finish(&acc, seg) }
    }

    /// The k closest hits of `ray` accepted by roulette in slot `slot`, sorted.
    pub(crate) fn first_k_accepted(&self, ray: &Ray, decide: &impl Decide, k: usize, slot: u32) -> KBuf {
        let accept = |id: u32, p: Vec3, alpha: f32| decide.accepts(id, decide.particle(id, slot, p), alpha);
        self.next_k(ray, k, (ray.t_min, u32::MAX), Some(&accept))
    }

    /// Closest entry into any particle's bounding ellipsoid ([`bounding_radius`]), shaded opaque.
    fn opaque<D: Decide>(&self, seg: &Segment<D>) -> Sample {
        let ray = &seg.ray;
        let mut best = Slot::EMPTY;
        let mut t_max = ray.t_max;
        self.wide.traverse(ray, &mut t_max, |leaf, t_max| {
            let (o, d) = to_canonical(&self.prims[leaf as usize], ray);
            let Some(t) = sphere_entry(o, d, self.radius_sq[leaf as usize]) else { return };
            let id = self.ids[leaf as usize];
            if t > ray.t_min && t < ray.t_max && depth_before(t, id, best.t, best.id) {
                best = Slot { t, id, leaf, alpha: 1.0 };
                *t_max = t;
            }
        });
        if best.id == u32::MAX {
            return self.behind(seg);
        }
        let p = &self.scene.particles[best.id as usize];
        let color = sh::eval(p.sh.as_slice(), self.scene.sh_degree, ray.dir).as_dvec3();
        Sample { color, alpha: 1.0, depth: Some(best.t), normal: Vec3::ZERO, picked: Some(best.id) }
    }
}

/// How far from a mesh surface point `x` a secondary or shadow ray starts looking for meshes:
/// far enough that the surface does not hit itself in f32, relative to the point's magnitude.
pub(crate) fn surface_offset(x: Vec3) -> f32 {
    SURFACE_OFFSET * x.abs().max_element().max(1.0)
}

/// How far from a mesh surface point x a secondary or shadow ray starts looking for meshes,
/// relative to max(1, |x|∞).
pub const SURFACE_OFFSET: f32 = 1e-4;

/// One straight piece of a light path: the ray clipped at the closest mesh, the method and
/// decisions that sample the splats in front of it, and what lies behind them (filled when a
/// method first needs it).
struct Segment<'d, D> {
    ray: Ray,
    surface: Option<SurfaceHit>,
    method: Method,
    decide: Bounce<'d, D>,
    behind: OnceCell<Sample>,
}

/// Bit of a decision slot where the bounce number starts, for primary slots (every slot a
/// method draws in is below it) …
pub const BOUNCE_SHIFT: u32 = 20;
/// … and for shadow slots ([`shadow_slot`] keeps bits 26–30 free for primary slots below 2²⁰).
pub const SHADOW_BOUNCE_SHIFT: u32 = 26;
/// Largest slot (and pass) a method may draw in, so that bounces get slots of their own.
pub const MAX_PRIMARY_SLOTS: u32 = 1 << BOUNCE_SHIFT;

/// The decisions of a ray `depth` bounces after the camera ray: slot s of bounce d is slot
/// s + d·2²⁰ (shadow slots s + d·2²⁶, passes likewise), so that every bounce decides
/// independently of the rays before it (a particle seen directly and in a mirror is accepted
/// or not independently in each, as the expectation over the path needs). At depth 0 the
/// decisions are the camera ray's, bit for bit.
struct Bounce<'d, D> {
    inner: &'d D,
    depth: u32,
}

// By hand: a derive would ask D: Copy, and only the reference is copied.
impl<D> Clone for Bounce<'_, D> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<D> Copy for Bounce<'_, D> {}

impl<'d, D: Decide> Bounce<'d, D> {
    fn camera(inner: &'d D) -> Self {
        Self { inner, depth: 0 }
    }

    fn deeper(&self) -> Self {
        Self { depth: self.depth + 1, ..*self }
    }

    #[inline(always)]
    fn slot(&self, slot: u32) -> u32 {
        let shift = if slot & 0x8000_0000 != 0 { SHADOW_BOUNCE_SHIFT } else { BOUNCE_SHIFT };
        slot + (self.depth << shift)
    }
}

impl<D: Decide> Decide for Bounce<'_, D> {
    #[inline(always)]
    fn needs_position(&self) -> bool {
        self.inner.needs_position()
    }
    #[inline(always)]
    fn particle(&self, id: u32, slot: u32, hit: Vec3) -> f32 {
        self.inner.particle(id, self.slot(slot), hit)
    }
    #[inline(always)]
    fn slot_draws(&self, first_slot: u32, n: usize) -> impl Fn(u32, Vec3, &mut [f32]) {
        self.inner.slot_draws(self.slot(first_slot), n)
    }
    fn pass(&self, pass: u32) -> f32 {
        self.inner.pass(self.slot(pass))
    }
    fn light_sample(&self, light: u32, slot: u32) -> Vec2 {
        self.inner.light_sample(light, self.slot(slot))
    }
    #[inline(always)]
    fn accepts(&self, id: u32, u: f32, alpha: f32) -> bool {
        self.inner.accepts(id, u, alpha)
    }
    fn accepts_pass(&self, u: f64, opacity: f64) -> bool {
        self.inner.accepts_pass(u, opacity)
    }
    fn covers(&self, alpha: f32, reference: f32) -> bool {
        self.inner.covers(alpha, reference)
    }
}

/// Render `frames.count` frames of `method` (one for a deterministic method) through pixel
/// centres on the frame loop of [`crate::frame`]. `progress` receives finished pixel counts.
pub fn render_frames(
    trace: &TraceScene,
    camera: &Camera,
    method: &Method,
    frames: &Frames,
    progress: Progress,
) -> Result<RenderOutput, RenderError> {
    camera.validate()?;
    method.validate()?;
    let keys = frames.keys(method.is_stochastic() || trace.is_random())?;
    Ok(render_tiles(
        camera,
        progress,
        |_| (),
        |_, x, y| {
            let ray = trace.clip(camera.pixel_ray(x, y));
            PixelFrames::over(&keys, |key| {
                trace.sample(method, &ray, &RayRng::new(x, y, key, frames.rng).shifted(frames.u_shift))
            })
        },
    ))
}
