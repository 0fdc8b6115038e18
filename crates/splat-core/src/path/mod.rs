//! A Monte Carlo path tracer in which Gaussians are ordinary citizens beside meshes (Sun et al.
//! 2025, §3.4, §5 "Mixing Gaussians with meshes in production rendering", Figs. 1 and 5).
//!
//! A path is a chain of segments. Each segment is a ray clipped at its closest mesh; the
//! Gaussians in front of the mesh are sampled by Algorithm 1 (one traversal, Russian roulette
//! on α, the closest accepted hit). An accepted Gaussian ends the path with its radiance: its
//! SH colour for an emissive set, else its set's material lit at its own position and normal
//! by one sample of every light (next-event estimation, shadow rays through meshes and
//! Gaussians). With no accept the path reaches the mesh (or the environment), where it gathers
//! emission and next-event estimation, then scatters by the surface's BSDF ([`bsdf`]). Over
//! the segment's Gaussians this is Eq. 3 in expectation,
//!
//! ```text
//! L(segment) = Σᵢ Tᵢ αᵢ Lᵢ + T · L(mesh or environment),
//! ```
//!
//! so the path's expectation is the same whether the Gaussians are sampled (Algorithm 1,
//! [`GaussianEstimator::Stochastic`]), sampled n times in one traversal
//! ([`GaussianEstimator::StochasticN`]: the accepted slots' mean plus the share of empty slots
//! times the continued path) or composited exactly ([`GaussianEstimator::Exact`]: every hit
//! sorted, Σ Tᵢ αᵢ Lᵢ plus T times the continued path). The last is the oracle the others are
//! tested against; 3DGRT's depth sampling at secondary segments
//! ([`GaussianEstimator::DepthSampling`]) is the biased control.
//!
//! At mesh vertices: emission of emissive meshes (two-sided area lights; multiple importance
//! sampling with the power heuristic between BSDF sampling and emitter sampling by power),
//! the world's point, spot and directional lights by next-event estimation, Russian roulette
//! on the throughput after [`PathSettings::roulette_depth`] bounces, and a constant or
//! gradient environment where a path escapes. Pixels are box-filtered (a random position in the
//! pixel per sample) and a thin lens gives depth of field.
//!
//! Mesh materials are read physically ([`bsdf::Bsdf`]): emission k_e ⊙ c, Lambertian albedo
//! k_d ⊙ c for the local share, a GGX conductor for the mirror share (Schlick's Fresnel of the
//! mirror tint) and a dielectric for the transmission share, both with the material's
//! roughness. The Blinn–Phong ambient and specular terms are the raster pipelines' stand-ins for
//! indirect and glossy light, which the path tracer computes instead. Gaussians keep the splat material model of
//! [`crate::lighting`]. A transparent mesh (an opacity α below 1, per material or per vertex)
//! is sampled as the Gaussians are: each crossing stops the ray with probability α, decided per
//! triangle ([`sampler::surface_decision`]), so that a surface is α × itself + (1 − α) × what
//! lies behind in expectation; shadow rays take the meshes' transmittance Π (1 − αᵢ), as the
//! ray tracer's do.

pub mod bsdf;
pub mod sampler;

use crate::algorithm::Algorithm;
use crate::camera::Camera;
use crate::camera_sampling::{CameraSampling, FrameSample, PixelFilter};
use crate::catalogue::{MethodId, Parameters};
use crate::frame::{Decide, Frames, PixelFrames, Progress, RenderOutput, Sample, render_tiles};
use crate::hit::Ray;
use crate::lighting::{Incident, Light, Shadows};
use crate::mesh::SurfaceHit;
use crate::settings::RenderError;
use crate::trace::{Candidate, MAX_HITS, Method, TraceScene, surface_offset};
use bsdf::Bsdf;
use glam::Vec3;
use sampler::{Dim, PathDecide, PathSampler, SamplerKind, decision, shadow_decision};

/// How the Gaussians of each segment are estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GaussianEstimator {
    /// Algorithm 1 at every segment (Sun et al. 2025).
    Stochastic,
    /// `n` instantiations of Algorithm 1 in one traversal per segment (§3.5).
    StochasticN {
        /// Instantiations per traversal (≤ 64).
        n: u32,
    },
    /// Every hit sorted and composited (Eq. 3), each lit with exact-transmittance shadows: the
    /// oracle of the stochastic estimators.
    Exact,
    /// 3DGRT stochastic depth sampling at secondary segments (the first `k` accepted hits
    /// composited with their alphas; Algorithm 1 on camera rays). Biased: the negative control.
    DepthSampling {
        /// Accepted hits composited.
        k: u32,
    },
}

impl GaussianEstimator {
    /// The estimator of the method `id` with `p`'s parameters; `None` for a method the path
    /// tracer does not run at its segments.
    pub fn of(id: MethodId, p: &Parameters) -> Option<GaussianEstimator> {
        match id.algorithm(p) {
            Algorithm::Trace(method) => GaussianEstimator::of_method(&method),
            Algorithm::Oracle | Algorithm::Raster(..) | Algorithm::Hybrid(..) => None,
        }
    }

    /// The estimator of a ray-tracing method (`m` is ignored: a path segment is one
    /// traversal).
    fn of_method(method: &Method) -> Option<GaussianEstimator> {
        match *method {
            Method::Stochastic => Some(GaussianEstimator::Stochastic),
            Method::StochasticN { n, .. } => Some(GaussianEstimator::StochasticN { n }),
            Method::Exact => Some(GaussianEstimator::Exact),
            Method::DepthSampling { k } => Some(GaussianEstimator::DepthSampling { k: k as u32 }),
            Method::KBuffer { .. } | Method::StochasticPass { .. } | Method::Opaque => None,
        }
    }

    /// The methods the path tracer runs, in catalogue order.
    pub fn methods() -> impl Iterator<Item = MethodId> {
        MethodId::ALL.into_iter().filter(|&id| GaussianEstimator::of(id, &Parameters::default()).is_some())
    }

    /// Its method in the [catalogue](crate::catalogue): its name, and its code in the GPU
    /// kernel (`METHOD_*`, which `path.wgsl` switches on too).
    pub fn id(&self) -> MethodId {
        match self {
            GaussianEstimator::Stochastic => MethodId::Stochastic,
            GaussianEstimator::StochasticN { .. } => MethodId::StochasticN,
            GaussianEstimator::Exact => MethodId::Exact,
            GaussianEstimator::DepthSampling { .. } => MethodId::DepthSampling,
        }
    }
}

/// The environment a path escapes to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Environment {
    /// The same radiance in every direction.
    Constant(Vec3),
    /// `horizon` at and below the horizon, blending linearly in the up component of the
    /// direction to `zenith` straight up.
    Gradient {
        /// Radiance at and below the horizon.
        horizon: Vec3,
        /// Radiance straight up.
        zenith: Vec3,
        /// Unit up direction.
        up: Vec3,
    },
}

impl Environment {
    /// Radiance arriving from direction `-dir` (seen along `dir`).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match *self {
            Environment::Constant(c) => c,
            Environment::Gradient { horizon, zenith, up } => horizon.lerp(zenith, dir.dot(up).max(0.0)),
        }
    }

    fn validate(&self) -> Result<(), String> {
        let ok = |c: Vec3| c.is_finite() && c.min_element() >= 0.0;
        match *self {
            Environment::Constant(c) if ok(c) => Ok(()),
            Environment::Gradient { horizon, zenith, up } if ok(horizon) && ok(zenith) && up.is_normalized() => Ok(()),
            _ => Err(format!("environment {self:?} needs finite non-negative colours and a unit up")),
        }
    }
}

/// Default path length limit (bounces off meshes).
pub const DEFAULT_MAX_DEPTH: u32 = 8;
/// Largest path length limit.
pub const MAX_DEPTH: u32 = 64;

/// What the path tracer does besides the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSettings {
    /// Most bounces off meshes; the path ends at the next surface's emission.
    pub max_depth: u32,
    /// Russian roulette on the throughput starts after this many bounces.
    pub roulette_depth: u32,
    /// Estimator of the Gaussians at every segment.
    pub gaussians: GaussianEstimator,
    /// Generator of the path's numbers.
    pub sampler: SamplerKind,
    /// Radiance where a path escapes.
    pub environment: Environment,
}

impl Default for PathSettings {
    fn default() -> Self {
        Self {
            max_depth: DEFAULT_MAX_DEPTH,
            roulette_depth: 3,
            gaussians: GaussianEstimator::Stochastic,
            sampler: SamplerKind::Sobol,
            environment: Environment::Constant(Vec3::ZERO),
        }
    }
}

impl PathSettings {
    /// Check the settings, naming the first bad one.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::Settings(m));
        if self.max_depth > MAX_DEPTH {
            return bad(format!("max depth {} is above {MAX_DEPTH}", self.max_depth));
        }
        match self.gaussians {
            GaussianEstimator::StochasticN { n } if !(1..=MAX_HITS as u32).contains(&n) => {
                return bad(format!("stochastic-n needs 1 ≤ n ≤ {MAX_HITS} (got {n})"));
            }
            GaussianEstimator::DepthSampling { k } if !(1..=MAX_HITS as u32).contains(&k) => {
                return bad(format!("depth sampling needs 1 ≤ k ≤ {MAX_HITS} (got {k})"));
            }
            _ => {}
        }
        self.environment.validate().map_err(RenderError::Settings)?;
        Ok(())
    }
}

/// The emissive triangles, chosen in proportion to their power: area × mean opacity ×
/// luminance of the emission (a transparent emitter sends α Lₑ, [`PathTracer::surface`]).
struct Emitters {
    /// Leaf-order indices of the emissive triangles …
    triangles: Vec<u32>,
    /// … their cumulative selection probabilities …
    cdf: Vec<f32>,
    /// … and, per leaf-order triangle, P(select) / area (0 for the others).
    density: Vec<f32>,
}

impl Emitters {
    fn new(trace: &TraceScene) -> Self {
        let meshes = trace.meshes();
        let (areas, power): (Vec<f32>, Vec<f32>) = meshes
            .triangles()
            .iter()
            .map(|t| {
                let area = 0.5 * t.e1.cross(t.e2).length();
                // The mean of the opacity over the triangle: the mean of its vertices' (it is
                // linear across it).
                let opacity = t.alphas.iter().sum::<f32>() / 3.0;
                (area, area * opacity * luminance(emission(meshes.material(t.mesh))))
            })
            .unzip();
        let total: f64 = power.iter().map(|&p| f64::from(p)).sum();
        let mut density = vec![0.0; power.len()];
        let (mut triangles, mut cdf, mut sum) = (Vec::new(), Vec::new(), 0.0f64);
        for (k, &p) in power.iter().enumerate().filter(|(_, p)| **p > 0.0) {
            sum += f64::from(p);
            triangles.push(k as u32);
            cdf.push((sum / total) as f32);
            density[k] = (f64::from(p) / total) as f32 / areas[k];
        }
        Self { triangles, cdf, density }
    }

    /// The triangle chosen by `u` and its leaf-order index.
    fn pick(&self, u: f32) -> Option<u32> {
        let i = self.cdf.partition_point(|&c| c <= u).min(self.triangles.len().checked_sub(1)?);
        Some(self.triangles[i])
    }
}

/// The emitter table of `trace`'s meshes, as a GPU uploads it: per emissive triangle its
/// cumulative selection probability (f32 bits) and leaf-order index, and per leaf-order triangle
/// P(select) / area.
pub fn emitter_table(trace: &TraceScene) -> (Vec<[u32; 2]>, Vec<f32>) {
    let e = Emitters::new(trace);
    let picks = e.cdf.iter().zip(&e.triangles).map(|(c, &t)| [c.to_bits(), t]).collect();
    (picks, e.density)
}

/// The radiance a mesh material emits: the local share of k_e ⊙ c (what the ray tracer shows).
fn emission(m: &crate::mesh::MeshMaterial) -> Vec3 {
    m.local_share() * m.shading.emissive * m.color
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// The power heuristic (β = 2) weight of a strategy of density `a` against one of density `b`.
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 { a2 / (a2 + b2) } else { 0.0 }
}

/// Whether world direction `w` lies on the side of the face normal `face` that its local z
/// (along the shading normal) says: where interpolated normals disagree with the geometry, a
/// direction would leak through the surface, and it carries nothing.
fn same_side(w: Vec3, face: Vec3, local_z: f32) -> bool {
    (w.dot(face) > 0.0) == (local_z > 0.0)
}

/// An orthonormal frame around a unit normal.
#[derive(Clone, Copy)]
struct Frame {
    t: Vec3,
    b: Vec3,
    n: Vec3,
}

impl Frame {
    fn new(n: Vec3) -> Self {
        let (t, b) = n.any_orthonormal_pair();
        Self { t, b, n }
    }
    fn to_local(self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }
    fn to_world(self, v: Vec3) -> Vec3 {
        v.x * self.t + v.y * self.b + v.z * self.n
    }
}

/// The path tracer over a ray-tracing scene (its splat BVH, lighting and meshes).
pub struct PathTracer<'a> {
    trace: &'a TraceScene<'a>,
    settings: PathSettings,
    emitters: Emitters,
}

/// What the Gaussians of one segment left for the rest of the path.
struct Continuation {
    /// Radiance gathered from the Gaussians (times the throughput so far).
    radiance: Vec3,
    /// Factor of the throughput that continues past them (0 ends the path).
    weight: f32,
}

impl<'a> PathTracer<'a> {
    /// A path tracer for `trace` (validated settings).
    pub fn new(trace: &'a TraceScene<'a>, settings: PathSettings) -> Result<Self, RenderError> {
        settings.validate()?;
        Ok(Self { trace, settings, emitters: Emitters::new(trace) })
    }

    /// The settings.
    pub fn settings(&self) -> &PathSettings {
        &self.settings
    }

    /// The camera ray of sample `s` through pixel (x, y): a random position in the pixel (a
    /// box filter, whatever the settings' filter) and, with the settings' lens, on the lens;
    /// the path's own Sobol dimensions, one sequence per pixel.
    pub fn camera_ray(&self, camera: &Camera, x: u32, y: u32, s: &PathSampler) -> Ray {
        let sampling = CameraSampling { filter: PixelFilter::Box, ..self.trace.settings().sampling };
        let sample = FrameSample { pixel: s.get2(Dim::Pixel.index()), lens: s.get2(Dim::Lens.index()) };
        self.trace.clip(sampling.ray(camera, x, y, &sample))
    }

    /// The radiance of one path starting with `ray`.
    pub fn radiance(&self, ray: Ray, s: &PathSampler) -> Vec3 {
        let meshes = self.trace.meshes();
        let mut ray = ray;
        let (mut beta, mut l) = (Vec3::ONE, Vec3::ZERO);
        // Where the next segment starts looking for meshes, and the BSDF density of its
        // direction (None after a delta lobe or at the camera: emission counts in full).
        let (mut mesh_t_min, mut prev_pdf) = (ray.t_min, None::<f32>);
        for bounce in 0..=self.settings.max_depth {
            let surface = self.surface(&Ray { t_min: ray.t_min.max(mesh_t_min), ..ray }, bounce, s);
            let segment = Ray { t_max: surface.map_or(ray.t_max, |h| h.t), ..ray };
            let gauss = self.gaussians(&segment, bounce, s);
            l += beta * gauss.radiance;
            beta *= gauss.weight;
            if beta == Vec3::ZERO {
                break;
            }
            let Some(hit) = surface else {
                l += beta * self.settings.environment.radiance(ray.dir);
                break;
            };
            let x = ray.at(hit.t);
            let material = meshes.material(hit.mesh);
            let le = emission(material);
            if le != Vec3::ZERO {
                let w = prev_pdf.map_or(1.0, |p| power_heuristic(p, self.emitter_pdf(&hit, ray.dir)));
                l += beta * le * w;
            }
            if bounce == self.settings.max_depth {
                break;
            }
            let (face, n, outside) = hit.facing(ray.dir);
            let frame = Frame::new(n);
            let wo = frame.to_local(-ray.dir);
            let eta = if outside { material.ior } else { 1.0 / material.ior };
            let albedo = (material.shading.diffuse * material.color).min(Vec3::ONE);
            let f = Bsdf::new(
                material.local_share(),
                albedo,
                material.mirror,
                material.mirror_tint,
                material.transmission,
                material.roughness,
                eta,
            )
            .with_layer(material.layer_f0());
            if f.has_smooth_part() {
                l += beta * self.direct_at_surface(x, face, &frame, wo, &f, bounce, s);
            }
            let Some(next) = f.sample(wo, s.get(Dim::Lobe(bounce).index()), s.get2(Dim::Direction(bounce).index()))
            else {
                break;
            };
            let dir = frame.to_world(next.wi).normalize();
            if !same_side(dir, face, next.wi.z) {
                break;
            }
            beta *= next.weight;
            prev_pdf = (!next.delta).then_some(next.pdf);
            if bounce + 1 >= self.settings.roulette_depth {
                let q = beta.max_element().min(0.95);
                if s.get(Dim::Roulette(bounce).index()) >= q {
                    break;
                }
                beta /= q;
            }
            ray = Ray { origin: x, dir, view: dir, t_min: 0.0, t_max: self.trace.settings().t_max };
            mesh_t_min = surface_offset(x);
        }
        l
    }

    /// The surface that ends the segment after bounce `bounce`: the closest opaque triangle or
    /// accepted transparent one, each transparent triangle the ray crosses accepted with
    /// probability its opacity α ([`Meshes::closest_accepted`](crate::mesh::Meshes::closest_accepted)).
    /// So a transparent surface is, in expectation, α × (its emission and scattering) + (1 − α)
    /// × the radiance of the same ray past it, the ray tracer's layer of Eq. 3; passing it is no
    /// bounce, and the Gaussians on both sides of it are one segment.
    fn surface(&self, ray: &Ray, bounce: u32, s: &PathSampler) -> Option<SurfaceHit> {
        self.trace.meshes().closest_accepted(ray, |order, alpha| s.surface(order, bounce) < alpha)
    }

    /// The Gaussians of one segment by the chosen estimator.
    fn gaussians(&self, seg: &Ray, bounce: u32, s: &PathSampler) -> Continuation {
        let decide = PathDecide { sampler: s, bounce };
        let trace = self.trace;
        let mut radiance = Vec3::ZERO;
        let estimator = match self.settings.gaussians {
            GaussianEstimator::DepthSampling { .. } if bounce == 0 => GaussianEstimator::Stochastic,
            e => e,
        };
        let weight = match estimator {
            GaussianEstimator::Stochastic => match trace.first_accepted(seg, &decide, decision(bounce, 0)) {
                Some(hit) => {
                    radiance = self.gaussian_radiance(&hit, seg, bounce, s, false);
                    0.0
                }
                None => 1.0,
            },
            GaussianEstimator::StochasticN { n } => {
                let best = trace.first_accepted_n::<MAX_HITS>(seg, &decide, decision(bounce, 0), n as usize);
                let mut empty = 0;
                for hit in &best[..n as usize] {
                    if hit.is_hit() {
                        radiance += self.gaussian_radiance(hit, seg, bounce, s, false);
                    } else {
                        empty += 1;
                    }
                }
                radiance /= n as f32;
                empty as f32 / n as f32
            }
            GaussianEstimator::Exact => {
                let mut t = 1.0f32;
                for hit in trace.sorted_hits(seg) {
                    radiance += t * hit.alpha * self.gaussian_radiance(&hit, seg, bounce, s, true);
                    t *= 1.0 - hit.alpha;
                }
                t
            }
            GaussianEstimator::DepthSampling { k } => {
                let buf = trace.first_k_accepted(seg, &decide, k as usize, decision(bounce, 0));
                let mut t = 1.0f32;
                for hit in buf.as_slice() {
                    radiance += t * hit.alpha * self.gaussian_radiance(hit, seg, bounce, s, false);
                    t *= 1.0 - hit.alpha;
                }
                t
            }
        };
        Continuation { radiance, weight }
    }

    /// The radiance Lᵢ a Gaussian hit sends back along the segment: its SH colour for an
    /// emissive set, else its set's material lit at the hit by every world light and one
    /// emitter sample, each behind a shadow ray (exact transmittance when `exact`).
    fn gaussian_radiance(&self, hit: &Candidate, seg: &Ray, bounce: u32, s: &PathSampler, exact: bool) -> Vec3 {
        let trace = self.trace;
        let lighting = trace.lighting();
        let h = trace.shade(hit.leaf, hit.t, hit.alpha, seg);
        let material = lighting.material(h.index);
        if material.is_emissive() {
            return h.color;
        }
        let decide = PathDecide { sampler: s, bounce };
        let offset = lighting.shadow_offset;
        let sample = |j: usize, _: &Light| decide.light_sample(j as u32, 0);
        let visible = |j: usize, x: Vec3, inc: &Incident| {
            Vec3::splat(self.visibility(x, offset, inc, &decide, shadow_decision(bounce, j as u32), exact))
        };
        let mut lit = lighting.shade_material(material, h.color, seg, hit.t, h.normal, sample, visible);
        let x = seg.at(hit.t);
        if let Some((inc, _)) = self.emitter_sample(x, bounce, s) {
            let direct = material.direct(h.color, h.normal, -seg.dir, &inc);
            if direct != Vec3::ZERO {
                let decision = shadow_decision(bounce, crate::lighting::MAX_LIGHTS as u32);
                lit += direct * self.visibility(x, offset, &inc, &decide, decision, exact);
            }
        }
        lit
    }

    /// Next-event estimation at a mesh vertex: every world light, and one emitter sample
    /// weighted against BSDF sampling by the power heuristic.
    #[allow(clippy::too_many_arguments)]
    fn direct_at_surface(
        &self,
        x: Vec3,
        face: Vec3,
        frame: &Frame,
        wo: Vec3,
        f: &Bsdf,
        bounce: u32,
        s: &PathSampler,
    ) -> Vec3 {
        let decide = PathDecide { sampler: s, bounce };
        let offset = surface_offset(x);
        let mut sum = Vec3::ZERO;
        for (j, light) in self.trace.lighting().lights.iter().enumerate() {
            let Some(inc) = light.incident(x, decide.light_sample(j as u32, 0)) else { continue };
            let wi = frame.to_local(inc.l);
            if !same_side(inc.l, face, wi.z) {
                continue;
            }
            let (fc, _) = f.eval(wo, wi);
            if fc != Vec3::ZERO {
                let v = self.visibility(x, offset, &inc, &decide, shadow_decision(bounce, j as u32), false);
                sum += fc * inc.irradiance * v;
            }
        }
        if let Some((inc, pdf_light)) = self.emitter_sample(x, bounce, s) {
            let wi = frame.to_local(inc.l);
            let (fc, pdf_bsdf) = if same_side(inc.l, face, wi.z) { f.eval(wo, wi) } else { (Vec3::ZERO, 0.0) };
            if fc != Vec3::ZERO {
                let decision = shadow_decision(bounce, crate::lighting::MAX_LIGHTS as u32);
                let v = self.visibility(x, offset, &inc, &decide, decision, false);
                sum += fc * inc.irradiance * v * power_heuristic(pdf_light, pdf_bsdf);
            }
        }
        sum
    }

    /// One point on the emissive meshes seen from `x`, as the irradiance estimate
    /// Lₑ |cos θₗ| / (d² p_A) arriving along l, and the density of its direction per solid angle.
    fn emitter_sample(&self, x: Vec3, bounce: u32, s: &PathSampler) -> Option<(Incident, f32)> {
        let k = self.emitters.pick(s.get(Dim::LightPick(bounce).index()))?;
        let meshes = self.trace.meshes();
        let tri = &meshes.triangles()[k as usize];
        let u = s.get2(Dim::LightPoint(bounce).index());
        let (b1, b2) = if u.x + u.y > 1.0 { (1.0 - u.x, 1.0 - u.y) } else { (u.x, u.y) };
        let p = tri.p0 + b1 * tri.e1 + b2 * tri.e2;
        let to = p - x;
        let distance = to.length();
        if distance.is_nan() || distance <= 0.0 {
            return None;
        }
        let l = to / distance;
        let cos_l = tri.face_normal().dot(l).abs();
        if cos_l.is_nan() || cos_l <= 0.0 {
            return None;
        }
        let pdf = self.emitters.density[k as usize] * distance * distance / cos_l;
        // A transparent emitter stops a ray with probability α there (`surface`): it sends
        // α Lₑ in expectation, whichever strategy finds it.
        let le = emission(meshes.material(tri.mesh)) * tri.alpha_at(b1, b2);
        // The shadow ray stops short of the emitter so that its own triangle does not block it.
        let distance = distance - surface_offset(p);
        Some((Incident { l, distance, irradiance: le / pdf }, pdf))
    }

    /// The density per solid angle with which emitter sampling would have chosen the direction
    /// of a ray that hit emissive surface `hit` (along unit `dir`).
    fn emitter_pdf(&self, hit: &SurfaceHit, dir: Vec3) -> f32 {
        let cos_l = hit.face_normal.dot(dir).abs();
        if cos_l <= 0.0 { 0.0 } else { self.emitters.density[hit.triangle as usize] * hit.t * hit.t / cos_l }
    }

    /// Visibility of a light sample from `x` ([`TraceScene::shadow_visibility`]): 0 behind a
    /// mesh; through the Gaussians the stochastic shadow ray (1 or 0, expectation the
    /// transmittance), or with `exact` the transmittance itself.
    fn visibility(&self, x: Vec3, offset: f32, inc: &Incident, decide: &impl Decide, slot: u32, exact: bool) -> f32 {
        let kind = if exact { Shadows::Exact } else { Shadows::Stochastic };
        self.trace.shadow_visibility(x, offset, inc, decide, slot, kind).x
    }

    /// `frames.count` samples per pixel (sample indices `frames.first`, `frames.first + 1`, …,
    /// the frames of the run seeded by `frames.seed`), each a path, averaged into a [`RenderOutput`] (colour and its per-frame
    /// variance; alpha 1). `progress` receives finished pixel counts.
    pub fn render(&self, camera: &Camera, frames: &Frames, progress: Progress) -> Result<RenderOutput, RenderError> {
        camera.validate()?;
        crate::trace::check_camera(self.trace.settings(), camera)?;
        frames.keys(true)?;
        Ok(render_tiles(
            camera,
            progress,
            |_| (),
            |_, x, y| {
                let mut pixel = PixelFrames::new(frames.accumulation);
                for index in (0..frames.count).map(|f| frames.index(f)) {
                    let s = PathSampler::new(self.settings.sampler, x, y, frames.seed, index).shifted(frames.u_shift);
                    let l = self.radiance(self.camera_ray(camera, x, y, &s), &s);
                    pixel.push(&Sample { alpha: 1.0, ..Sample::background(l) });
                }
                pixel
            },
        ))
    }
}
