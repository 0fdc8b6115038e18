//! CPU ray tracing through a BVH with every ray-tracing method of the seeds: exact, the k-buffer
//! multi-pass baseline, stochastic any-hit (Algorithm 1), its N-samples-per-traversal extension
//! (§3.5), the vk stochastic pass, and 3DGRT's stochastic depth sampling (the biased control).
//!
//! Each method is one function of a ray and a source of decisions ([`Decide`]). In rendering,
//! the decisions are the counter-based hashes of [`crate::rng::RayRng`]; in tests they can be
//! set outcome by outcome, so that the expectation of the very code that renders is computed
//! exactly by enumeration.
//!
//! This file holds the scene ([`TraceScene`]), the dispatch of a sample to its method, Eq. 3's
//! integration and what lies behind the splats (meshes, bounces); the methods live beside it,
//! each file with its GPU twin of the same name in `splat-gpu/shaders/`: `stochastic.rs`
//! (Algorithm 1, §3.5), `kbuffer.rs` (the sorted hits of exact, the k-buffer, the stochastic
//! pass and depth sampling) and `shadow.rs` (lighting a hit, the shadow rays).

use crate::bvh::{Bvh4, MAX_PRIMITIVES};
use crate::camera::Camera;
use crate::camera_sampling::{FrameSample, frame_sample};
use crate::catalogue::MethodId;
use crate::composite::{ShadedHit, shade_hit};
use crate::frame::{Decide, Frames, PixelFrames, Progress, RenderOutput, Sample, depth_before, render_tiles};
use crate::hit::{Hit, HitDistance, PreparedParticle, Ray, intersect, sphere_entry, to_canonical};
use crate::lighting::{Incident, Light, Lighting, Look, shadow_slot};
use crate::mesh::{Meshes, SurfaceHit, fresnel, reflect, refract};
use crate::par;
use crate::particle::{Aabb, Scene};
use crate::rng::RayRng;
use crate::settings::{RenderError, RenderSettings, validate_scene};
use crate::sh;
use glam::{DVec3, Vec2, Vec3};
use std::borrow::Cow;
use std::cell::OnceCell;

mod kbuffer;
mod shadow;
mod stochastic;

pub(crate) use kbuffer::{Candidate, KBuf};

pub use crate::catalogue::{
    DEFAULT_K, DEFAULT_MAX_PASSES, DEFAULT_MIN_TRANSMITTANCE, MAX_HITS, MAX_SAMPLES_PER_TRAVERSAL, Method,
};
// The sorted shadow pass keeps its hits in a k-buffer.
const _: () = assert!(crate::lighting::MAX_SHADOW_K <= MAX_HITS);

impl Method {
    /// The k-buffer with the vk defaults.
    pub const KBUFFER: Method =
        Method::KBuffer { k: DEFAULT_K, max_passes: DEFAULT_MAX_PASSES, min_transmittance: DEFAULT_MIN_TRANSMITTANCE };
    /// The stochastic pass with the vk defaults.
    pub const STOCHASTIC_PASS: Method = Method::StochasticPass { k: DEFAULT_K, max_passes: DEFAULT_MAX_PASSES };

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
    /// The 4-wide BVH both backends traverse.
    bvh: Bvh4,
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
    lighting: Cow<'a, Lighting>,
    /// Opaque meshes that clip every ray ([`crate::mesh`]); none by default.
    meshes: Cow<'a, Meshes>,
}

/// The radius, in standard deviations, of the ellipsoid that holds every hit point of a
/// particle: its visible extent ([`crate::kernel::KernelParams::visible_extent`]) where hits are
/// taken at the maximum density along the ray, which lies inside it whenever the hit is kept
/// (and where the [`HitDistance::Center`] convention, which keeps the same hits, finds the
/// point its ray passes nearest the centre); the sphere around the icosahedron proxy of
/// [`HitDistance::Icosahedron`], whose crossing may lie anywhere on the proxy.
pub fn bounding_radius(settings: &RenderSettings, opacity: f32) -> f32 {
    let visible = settings.kernel.visible_extent(opacity);
    match settings.hit_distance {
        HitDistance::Mean | HitDistance::Center => visible,
        HitDistance::Icosahedron => visible * crate::hit::ICOSAHEDRON_CIRCUMRADIUS,
    }
}

/// The box the BVH bounds a particle by: that of its [`bounding_radius`] ellipsoid, grown under
/// [`HitDistance::Center`] by R / [`crate::hit::CENTER_VIEW_COS_MIN`] (R its largest semi-axis
/// there) to hold the plane point of every kept hit.
pub fn bounding_box(settings: &RenderSettings, p: &crate::particle::Particle) -> Aabb {
    let radius = bounding_radius(settings, p.opacity);
    let b = p.aabb(radius).padded();
    match settings.hit_distance {
        HitDistance::Center => {
            let grow = Vec3::splat(radius * p.scale.max_element() / crate::hit::CENTER_VIEW_COS_MIN);
            Aabb { min: b.min - grow, max: b.max + grow }.padded()
        }
        HitDistance::Mean | HitDistance::Icosahedron => b,
    }
}

/// Refuse a camera that sees rays farther off its axis than `settings`' hit distance
/// convention takes ([`crate::hit::CENTER_VIEW_COS_MIN`] under [`HitDistance::Center`]), before
/// any work: those rays would miss every particle.
pub fn check_camera(settings: &RenderSettings, camera: &Camera) -> Result<(), RenderError> {
    if settings.hit_distance != HitDistance::Center {
        return Ok(());
    }
    let cos = camera.min_view_cos();
    if cos < crate::hit::CENTER_VIEW_COS_MIN {
        return Err(RenderError::Settings(format!(
            "the centre hit distance takes rays within {:.0}° of the view axis, and this camera sees {:.0}° off \
             axis: use the mean hit distance, or a narrower camera",
            crate::hit::CENTER_VIEW_COS_MIN.acos().to_degrees(),
            cos.clamp(-1.0, 1.0).acos().to_degrees()
        )));
    }
    Ok(())
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
        let (radii, boxes): (Vec<f32>, Vec<Aabb>) =
            par::map(&scene.particles, |p| (bounding_radius(&settings, p.opacity), bounding_box(&settings, p)))
                .into_iter()
                .unzip();
        // The boxes and binary nodes go before the prepared particles are made.
        let (bvh, ids) = Bvh4::build(boxes, "particles").map_err(RenderError::Settings)?;
        let prims = par::map(&ids, |&i| PreparedParticle::new(&scene.particles[i as usize]));
        let clamp = settings.kernel.alpha_clamp;
        let alpha_bound = ids.iter().map(|&i| scene.particles[i as usize].opacity.min(clamp)).collect();
        let radius_sq = ids.iter().map(|&i| radii[i as usize].powi(2)).collect();
        let (lighting, meshes) = (Cow::Owned(Lighting::default()), Cow::Owned(Meshes::none()));
        Ok(Self { scene, settings, bvh, prims, ids, alpha_bound, radius_sq, lighting, meshes })
    }

    /// The same scene lit by `lighting` (checked against the scene's particle count).
    pub fn with_lighting(mut self, lighting: impl Into<Cow<'a, Lighting>>) -> Result<Self, RenderError> {
        let lighting = lighting.into();
        lighting.validate(self.scene.particles.len()).map_err(RenderError::Settings)?;
        self.lighting = lighting;
        Ok(self)
    }

    /// The same scene among `meshes`, which clip every ray and shadow the splats.
    pub fn with_meshes(mut self, meshes: impl Into<Cow<'a, Meshes>>) -> Self {
        self.meshes = meshes.into();
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
    /// with stochastic shadow rays or area lights, or a camera drawn per frame
    /// ([`crate::camera_sampling`]).
    pub fn is_random(&self) -> bool {
        self.lighting.draws_for(!self.meshes.is_empty()) || self.settings.sampling.is_random()
    }

    /// The settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// One render of this scene's world (splats, meshes, lighting, settings) through `camera`.
    pub fn shot<'s>(&'s self, camera: &'s Camera) -> crate::Shot<'s> {
        crate::Shot {
            scene: self.scene,
            meshes: &self.meshes,
            lighting: &self.lighting,
            camera,
            settings: &self.settings,
        }
    }

    /// The 4-wide BVH over the particles, which both backends traverse.
    pub fn bvh(&self) -> &Bvh4 {
        &self.bvh
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

    /// What lies behind the splats of a segment clipped by mesh surface `hit`: its shaded colour
    /// S ([`TraceScene::shade_surface`]), and for a transparent surface (opacity α < 1) one more
    /// layer of Eq. 3, α S + (1 − α) × the radiance of the same ray continued past it (the same
    /// method and bounce: a layer is no bounce). Depth and normal are the surface's where α alone
    /// takes the transmittance below the iso threshold, else those of what lies behind.
    fn surface_sample<D: Decide>(&self, seg: &Segment<D>, hit: &SurfaceHit) -> Sample {
        let surface = self.shade_surface(seg, hit);
        if hit.alpha >= 1.0 {
            return surface;
        }
        let x = seg.ray.at(hit.t);
        let past = Ray { t_min: hit.t, t_max: self.settings.t_max, ..seg.ray };
        let mesh_t_min = hit.t + surface_offset(x) / seg.ray.dir.length();
        // One recursion a layer: a ray through thousands of layers grows the stack on the heap
        // rather than overflowing it.
        let behind = stacker::maybe_grow(LAYER_RED_ZONE, LAYER_STACK, || {
            self.trace_ray(&seg.method, &past, seg.decide.past_layer(), mesh_t_min)
        });
        let alpha = f64::from(hit.alpha);
        let surface_first = 1.0 - hit.alpha < self.settings.iso_threshold || behind.depth.is_none();
        Sample {
            color: alpha * surface.color + (1.0 - alpha) * behind.color,
            alpha: alpha + (1.0 - alpha) * behind.alpha,
            ..if surface_first { surface } else { behind }
        }
    }

    /// The shaded colour S of a mesh surface hit by the segment's ray ([`crate::mesh`]): the
    /// material's local share lit by the world's lights (shadow rays through meshes and splats),
    /// plus the mirror and glass shares from secondary rays traced by the same method one bounce
    /// deeper, while the bounce limit allows. Depth and normal are the surface's.
    fn shade_surface<D: Decide>(&self, seg: &Segment<D>, hit: &SurfaceHit) -> Sample {
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
                color += material.mirror_reflectance((-d.dot(n)).clamp(0.0, 1.0)) * trace(reflect(d, n));
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

    /// The shaded colour S of mesh surface `hit` on `ray` as the ray tracer sees it: lit with
    /// shadow rays, mirror and glass bounces traced by `method` (the hybrid pipeline's
    /// continuation of a rasterized first hit, vk_gaussian_splatting Lighting §5). A
    /// transparent surface's S alone: the rasterizer composites it as a fragment.
    pub fn surface(&self, method: &Method, ray: &Ray, hit: &SurfaceHit, decide: &impl Decide) -> Sample {
        let seg = Segment {
            ray: Ray { t_max: hit.t, ..*ray },
            surface: Some(*hit),
            method: *method,
            decide: Bounce::camera(decide),
            behind: OnceCell::new(),
        };
        self.shade_surface(&seg, hit)
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

    /// The k closest hits of `ray` accepted by roulette in slot `slot`, sorted.
    pub(crate) fn first_k_accepted(&self, ray: &Ray, decide: &impl Decide, k: usize, slot: u32) -> KBuf {
        let accept = |id: u32, p: Vec3, alpha: f32| decide.accepts(id, decide.particle(id, slot, p), alpha);
        self.next_k(ray, k, (ray.t_min, u32::MAX), Some(&accept))
    }

    /// Closest entry into any particle's bounding ellipsoid ([`bounding_radius`]), shaded opaque.
    fn opaque<D: Decide>(&self, seg: &Segment<D>) -> Sample {
        let ray = &seg.ray;
        let mut best = Candidate::EMPTY;
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, t_max| {
            let (o, d) = to_canonical(&self.prims[leaf as usize], ray);
            let Some(t) = sphere_entry(o, d, self.radius_sq[leaf as usize]) else { return };
            let id = self.ids[leaf as usize];
            if t > ray.t_min && t < ray.t_max && depth_before(t, id, best.t, best.id) {
                best = Candidate { t, id, leaf, alpha: 1.0 };
                *t_max = t;
            }
        });
        if best.id == u32::MAX {
            return self.behind(seg);
        }
        let p = &self.scene.particles[best.id as usize];
        let color =
            sh::eval_stored(p.sh.as_slice(), self.scene.sh_degree, ray.dir, self.settings.sh_storage).as_dvec3();
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
/// Stack a ray continued past a transparent surface must have left, or it continues on a new
/// stack segment of [`LAYER_STACK`] bytes (`stacker`).
const LAYER_RED_ZONE: usize = 256 * 1024;
const LAYER_STACK: usize = 1024 * 1024;

/// Bit of a pass number where a ray's transparent layer starts (above the bounce number,
/// d ≤ [`crate::settings::MAX_BOUNCES`] < 16).
pub const LAYER_PASS_SHIFT: u32 = 24;

/// The decisions of a ray `depth` bounces after the camera ray: slot s of bounce d is slot
/// s + d·2²⁰ (shadow slots s + d·2²⁶, passes likewise), so that every bounce decides
/// independently of the rays before it (a particle seen directly and in a mirror is accepted
/// or not independently in each, as the expectation over the path needs). At depth 0 the
/// decisions are the camera ray's, bit for bit.
///
/// A ray continued past a transparent surface keeps its bounce: each particle lies in one
/// layer only, so decisions keyed by particle stay independent. The stochastic pass's
/// decisions are keyed by pass number alone, and the layer behind is reached only when every
/// pass in front was rejected, so layer l draws its passes at pass + l·2²⁴ (bits 24–31: the
/// passes of layers l and l + 256 coincide, a ray's 256th transparent surface).
struct Bounce<'d, D> {
    inner: &'d D,
    depth: u32,
    layer: u32,
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
        Self { inner, depth: 0, layer: 0 }
    }

    fn deeper(&self) -> Self {
        Self { depth: self.depth + 1, layer: 0, ..*self }
    }

    /// The decisions of the same ray continued past a transparent surface.
    fn past_layer(&self) -> Self {
        Self { layer: self.layer.wrapping_add(1), ..*self }
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
        self.inner.pass(self.slot(pass).wrapping_add(self.layer << LAYER_PASS_SHIFT))
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

/// Render `frames.count` frames of `method` (one for a deterministic method under a still
/// camera) on the frame loop of [`crate::frame`], each frame's rays drawn by the settings'
/// [`crate::camera_sampling`] (pixel centres and a pinhole by default). `progress` receives
/// finished pixel counts.
pub fn render_frames(
    trace: &TraceScene,
    camera: &Camera,
    method: &Method,
    frames: &Frames,
    progress: Progress,
) -> Result<RenderOutput, RenderError> {
    camera.validate()?;
    method.validate()?;
    check_camera(trace.settings(), camera)?;
    let sampling = trace.settings().sampling;
    let keys = frames.keys(method.is_stochastic() || trace.is_random())?;
    let samples: Vec<FrameSample> =
        (0..keys.len() as u32).map(|f| frame_sample(frames.seed, frames.index(f))).collect();
    Ok(render_tiles(
        camera,
        progress,
        |_| (),
        |_, x, y| {
            let still = trace.clip(camera.pixel_ray(x, y));
            let mut pixel = PixelFrames::new(frames.accumulation);
            for (key, s) in keys.iter().zip(&samples) {
                let ray = if sampling.is_random() { trace.clip(sampling.ray(camera, x, y, s)) } else { still };
                pixel.push(&trace.sample(method, &ray, &RayRng::new(x, y, *key, frames.rng).shifted(frames.u_shift)));
            }
            pixel
        },
    ))
}
