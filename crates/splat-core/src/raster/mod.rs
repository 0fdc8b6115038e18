//! The CPU reference of the splatting path: EWA projection ([`project()`]), the global depth
//! sort, per-pixel blending over S sub-pixel samples, and the sorting-free stochastic
//! rasterizers (vk_gaussian_splatting Stochastic transparency §1; Laine & Karras 2011).
//!
//! A pixel is processed like a multisampled render target. Every splat that reaches the pixel
//! makes one *fragment*: its alpha is evaluated once, at the pixel centre (the shading rate of
//! MSAA), and its coverage is a bit per sample, set where the sample lies inside the splat's
//! footprint ([`SplatExtent`]: the 3DGS rasterizer's tiles, the √8σ ellipse, or gsplat's
//! alpha-cull bounds). Each covered sample has its own fragment depth along the sample's ray: the
//! billboard through the centre ([`FragmentDepth::Center`], what 3DGS and vk use) or the point of
//! maximum density ([`FragmentDepth::MaxDensityPlane`], StochasticSplats' pop-free variant).
//! With one sample (the centre) this is exactly the 3DGS rasterizer.
//!
//! Methods ([`RasterMethod`]): sorted splatting (the raster oracle, back-to-front *over* or
//! front-to-back *under*), StochasticSplats, Enderton et al.'s stochastic transparency and
//! Laine–Karras stratified stochastic transparency. The expectation of each stochastic method
//! is the sorted image with the same samples; depth ties are broken by splat id everywhere, so
//! the order is total and no result depends on the draw order or the thread count.

#[cfg(test)]
mod enumeration;
pub mod project;
pub mod samples;
#[cfg(test)]
mod tests;

use crate::camera::Camera;
use crate::camera_sampling::{CameraSampling, frame_sample};
pub use crate::catalogue::RasterMethod;
use crate::frame::{
    AccumulationFormat, Decide, Frames, PixelFrames, Progress, RenderOutput, Sample, depth_before, fold_frames,
    render_tiles,
};
use crate::hit::{HitDistance, PreparedParticle, Ray, intersect, to_canonical};
use crate::lighting::{Lighting, Look};
use crate::mesh::{Meshes, SurfaceHit};
use crate::normal::particle_normal;
use crate::particle::Scene;
use crate::rng::{
    RayRng, RngScheme, calc_alpha_ref, hilbert_index, hilbert_order, morton_index, sobol_alpha_ref, xxhash32,
};
use crate::settings::{RenderError, RenderSettings, validate_scene};
use crate::tile::{TILE, tile_count};
use crate::trace::{Method, TraceScene};
use glam::{DVec3, Vec2, Vec3};
pub use project::{Splat, SplatExtent, project};
pub use samples::{MAX_SAMPLES, SAMPLE_COUNTS, STANDARD_COUNTS, SamplePattern, sample_positions};
use std::borrow::Cow;

/// Blend order of sorted splatting (vk_gaussian_splatting Lighting §1.5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Blend {
    /// Back to front, C ← α c + (1 − α) C (§1.5.1, the 3DGS default).
    #[default]
    Over,
    /// Front to back with premultiplied alpha, C ← C + (1 − A) α c, A ← A + (1 − A) α (§1.5.2);
    /// also picks the iso-opacity depth and integrates normals.
    Under,
}

/// Depth of a fragment along its sample's ray.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum FragmentDepth {
    /// The camera-facing billboard through the splat centre (vk_gaussian_splatting Lighting §1.4.2): every sample
    /// sees the splats in the order of the global sort of centre depths.
    #[default]
    Center,
    /// The point of maximum density along the sample's ray (StochasticSplats' pop-free
    /// billboards): the order can differ from sample to sample, so sorted splatting sorts
    /// each sample's fragments.
    MaxDensityPlane,
}

/// How a fragment's alpha is evaluated at the pixel centre.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Response {
    /// The projected 2D Gaussian (EWA, or the unscented transform through another lens, with
    /// the scene's screen filter): 3DGS and the rasterizers descended from it.
    #[default]
    Projected,
    /// The particle's maximum response along the pixel centre's ray, in 3D: 3DGUT (Wu et al.
    /// 2025 §4: particles projected only to find their tiles, then evaluated as 3DGRT does,
    /// 3dgrut's `densityHit`), with the particle's own opacity, kernel and cutoff (3DGUT's
    /// minimum response through its preset) and the hit inside (t_min, t_max). A 2D Gaussian
    /// meets the ray in its plane, so for a surfel this is 2DGS's ray–splat intersection
    /// (Huang et al. 2024 §4.2) with 2DGS's low-pass: ρ = min(ρ_3D, ‖x − c‖² / [`SURFEL_LOW_PASS`]),
    /// c the projected centre. Every pixel of the 16 × 16 tiles that the alpha-cull ellipse of
    /// the projection touches is evaluated (3DGUT's tight opacity bounds), whatever the extent.
    AlongRay,
}

/// The variance of 2DGS's screen-space low-pass, px²: its `FilterSize` √2/2 (its
/// `FilterInvSquare` is 2).
pub const SURFEL_LOW_PASS: f32 = 0.5;

impl Response {
    /// Every response.
    pub const ALL: [Response; 2] = [Response::Projected, Response::AlongRay];

    /// Its name on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Response::Projected => "projected",
            Response::AlongRay => "along-ray",
        }
    }

    /// What it evaluates, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            Response::Projected => "the projected 2D Gaussian at the pixel centre (3DGS)",
            Response::AlongRay => {
                "the particle's maximum response along the pixel's ray (3DGUT; for 2D Gaussians, 2DGS's ray–splat intersection)"
            }
        }
    }
}

impl RasterMethod {
    /// Whether frames differ (the method draws random decisions).
    pub fn is_stochastic(&self) -> bool {
        self.id().entry().stochastic
    }
}

/// Raster-specific settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RasterSettings {
    /// Samples per pixel S, one of [`SAMPLE_COUNTS`] ([`STANDARD_COUNTS`] for the standard
    /// pattern).
    pub samples: u32,
    /// Where the samples lie in the pixel.
    pub sample_pattern: SamplePattern,
    /// Fragment depth of each sample.
    pub fragment_depth: FragmentDepth,
    /// Which pixels a splat can touch.
    pub extent: SplatExtent,
    /// How a fragment's alpha is evaluated.
    pub response: Response,
    /// Sorted splatting stops a sample before the fragment that would take its transmittance
    /// below [`EARLY_STOP_T`], as the 3DGS rasterizer does (`false`: the exact sum of Eq. 3).
    pub early_stop: bool,
    /// Laine–Karras stratification as published, or one of the paper's controls.
    pub lk_variant: LkVariant,
}

/// Laine & Karras 2011's stratified transparency as published ([`LkVariant::Paper`]) or with
/// one of the ingredients the paper shows the need for taken away (CPU only).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LkVariant {
    /// Figure 7 with CalcAlphaRef (Figure 4) and the Hilbert pixel index (§3.1).
    #[default]
    Paper,
    /// Figure 6a: no sorting of the covered samples by stored depth (line 9 skipped).
    Unsorted,
    /// §3.1's control: pixel indices along the Morton (Z) curve instead of the Hilbert curve.
    Morton,
    /// Figure 3b: the Sobol sequence (a parity hash, [`crate::rng::sobol_alpha_ref`]) in place of
    /// the multiply–XOR scramble.
    Sobol,
}

impl LkVariant {
    /// Every variant.
    pub const ALL: [LkVariant; 4] = [LkVariant::Paper, LkVariant::Unsorted, LkVariant::Morton, LkVariant::Sobol];

    /// Its name.
    pub const fn name(self) -> &'static str {
        match self {
            LkVariant::Paper => "paper",
            LkVariant::Unsorted => "unsorted",
            LkVariant::Morton => "morton",
            LkVariant::Sobol => "sobol",
        }
    }
}

/// The transmittance below which the 3DGS rasterizer stops compositing a pixel.
pub const EARLY_STOP_T: f64 = 1e-4;

impl Default for RasterSettings {
    fn default() -> Self {
        Self {
            samples: 1,
            sample_pattern: SamplePattern::Hammersley,
            fragment_depth: FragmentDepth::Center,
            extent: SplatExtent::ThreeDgs,
            response: Response::Projected,
            early_stop: false,
            lk_variant: LkVariant::Paper,
        }
    }
}

impl RasterSettings {
    /// Check the settings.
    pub fn validate(&self) -> Result<(), RenderError> {
        if !SAMPLE_COUNTS.contains(&self.samples) {
            return Err(RenderError::Settings(format!(
                "{} samples per pixel is not one of {SAMPLE_COUNTS:?}",
                self.samples
            )));
        }
        if !self.sample_pattern.has(self.samples) {
            return Err(RenderError::Settings(format!(
                "the standard sample pattern has {STANDARD_COUNTS:?} samples per pixel, not {}: use the hammersley pattern",
                self.samples
            )));
        }
        Ok(())
    }
}

/// One splat's or one transparent triangle's fragment in one pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fragment {
    /// What drew it: the index of a splat in [`Rasterizer::splats`] (global depth order), or
    /// [`TRIANGLE`] | the leaf-order index of a transparent triangle of the meshes.
    pub source: u32,
    /// Alpha at the pixel centre.
    pub alpha: f32,
    /// Bit s set when sample s is inside the splat's footprint ([`Splat::covers`]) or its ray
    /// crosses the triangle.
    pub covered: u64,
}

/// The bit of [`Fragment::source`] (and of a transparent triangle's id) that marks a triangle:
/// splat indices and ids stay below it (a scene with transparent meshes is refused from 2³¹
/// particles on), triangle indices below [`crate::mesh::MAX_TRIANGLES`] = 2²⁹.
pub const TRIANGLE: u32 = 1 << 31;

/// The triangle of fragment source `source`, if it is one.
#[inline]
fn triangle_of(source: u32) -> Option<u32> {
    (source & TRIANGLE != 0 && source < MESH).then_some(source & !TRIANGLE)
}

/// The geometry of one pixel's samples.
pub struct PixelSamples {
    /// Pixel column.
    pub x: u32,
    /// Pixel row.
    pub y: u32,
    rays: Vec<Ray>,
    /// The ray through the pixel centre, where alphas are evaluated.
    centre: Ray,
    /// |d_cam| of each sample's ray: a point at view depth z is at t = z |d_cam|.
    stretch: Vec<f32>,
    positions: Vec<Vec2>,
    /// The nearest mesh along each sample's ray (the mesh depth pre-pass).
    surfaces: Vec<Option<SurfaceHit>>,
}

impl PixelSamples {
    /// The nearest opaque mesh along sample `s`'s ray (what the sample holds before any
    /// fragment: the mesh depth pre-pass).
    pub fn surface(&self, s: usize) -> Option<&SurfaceHit> {
        self.surfaces.get(s)?.as_ref()
    }

    /// The number of samples.
    pub fn len(&self) -> usize {
        self.rays.len()
    }

    /// Whether the pixel has no samples (never: a rasterizer has at least one).
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }
}

/// A scene projected for one camera and binned into tiles, ready to rasterize.
pub struct Rasterizer<'a> {
    scene: &'a Scene,
    camera: Camera,
    settings: RenderSettings,
    raster: RasterSettings,
    splats: Vec<Splat>,
    prepared: Vec<PreparedParticle>,
    bins: Vec<Vec<u32>>,
    offsets: Vec<Vec2>,
    hilbert_order: u32,
    lighting: Cow<'a, Lighting>,
    meshes: Cow<'a, Meshes>,
    /// The hybrid pipeline's ray tracer and the method of its secondary rays.
    hybrid: Option<(&'a TraceScene<'a>, Method)>,
}

/// Reserved splat id of the hash that orders a stochastic frame's draws (scene ids stay below
/// [`crate::rng::MAX_PARTICLES`]).
pub const ORDER_ID: u32 = u32::MAX - 2;
/// Reserved splat id of the hash that gives a frame's first Laine–Karras surface id.
pub const SURFACE_ID: u32 = u32::MAX - 3;
/// Slot of Enderton's ξ; the random choice of samples uses the slots after it.
pub const ENDERTON_XI_SLOT: u32 = MAX_SAMPLES;
/// What a sample buffer holds where a mesh was drawn (as splat index and as id; every particle
/// id is below it, so a splat at the mesh's exact depth stays in front).
pub const MESH: u32 = u32::MAX - 1;

impl<'a> Rasterizer<'a> {
    /// Validate, project every particle (EWA), sort the splats by (centre depth, id) and bin
    /// them into tiles in that order.
    pub fn new(
        scene: &'a Scene,
        camera: &Camera,
        settings: RenderSettings,
        raster: RasterSettings,
    ) -> Result<Self, RenderError> {
        validate_scene(scene, &settings)?;
        camera.validate()?;
        raster.validate()?;
        let mut splats: Vec<Splat> = (0..scene.particles.len() as u32)
            .filter_map(|i| project(scene, i, camera, &settings, raster.extent, raster.response))
            .collect();
        splats.sort_by(|a, b| a.depth.total_cmp(&b.depth).then(a.id.cmp(&b.id)));
        let prepared = splats.iter().map(|s| PreparedParticle::new(&scene.particles[s.id as usize])).collect();
        let bins = bin_tiles(camera, &splats);
        Ok(Self {
            scene,
            camera: *camera,
            settings,
            raster,
            splats,
            prepared,
            bins,
            offsets: sample_positions(raster.samples, raster.sample_pattern),
            hilbert_order: hilbert_order(camera.width, camera.height),
            lighting: Cow::Owned(Lighting::default()),
            meshes: Cow::Owned(Meshes::none()),
            hybrid: None,
        })
    }

    /// The same rasterizer among `meshes` (vk_gaussian_splatting Lighting §1.5.3 and §3): a
    /// depth pre-pass finds the nearest mesh of every sample, splat fragments behind it fail the
    /// depth test, and the mesh's forward-shaded colour (lit, no shadows, no bounces: its mirror
    /// and glass shares see the background) is blended under the splats with (1 − α_dst).
    pub fn with_meshes(mut self, meshes: impl Into<Cow<'a, Meshes>>) -> Self {
        self.meshes = meshes.into();
        self
    }

    /// The hybrid pipeline (vk_gaussian_splatting Lighting §5): rasterized splats and mesh depth
    /// give the first hit, and `trace` continues from it: the pick is lit with shadow rays,
    /// meshes are shaded by the ray tracer with shadows and bounces traced by `method`. The
    /// meshes and lighting are the tracer's.
    pub fn hybrid(mut self, trace: &'a TraceScene<'a>, method: Method) -> Result<Self, RenderError> {
        method.validate()?;
        self = self.with_lighting(trace.lighting())?.with_meshes(trace.meshes());
        self.hybrid = Some((trace, method));
        Ok(self)
    }

    /// Whether frames of `method` differ: a stochastic method, or the hybrid pipeline's ray
    /// tracer drawing decisions (a stochastic secondary method, stochastic shadows, area lights).
    pub fn is_random(&self, method: &RasterMethod) -> bool {
        method.is_stochastic() || self.hybrid.is_some_and(|(trace, m)| m.is_stochastic() || trace.is_random())
    }

    /// The colour of sample `s` behind the splats and whether a mesh is there: the background,
    /// or the mesh forward-shaded (raster) or ray traced (hybrid).
    fn behind(&self, px: &PixelSamples, s: usize, decide: &impl Decide) -> DVec3 {
        let Some(hit) = &px.surfaces[s] else { return self.settings.background.as_dvec3() };
        self.surface_color(px, s, hit, decide)
    }

    /// The shaded colour S of mesh surface `hit` on sample `s`'s ray: forward-shaded (raster:
    /// lit without shadows, its mirror and glass shares seeing the background) or ray traced
    /// (hybrid).
    fn surface_color(&self, px: &PixelSamples, s: usize, hit: &SurfaceHit, decide: &impl Decide) -> DVec3 {
        let ray = &px.rays[s];
        if let Some((trace, method)) = &self.hybrid {
            return trace.surface(method, ray, hit, decide).color;
        }
        let m = self.meshes.material(hit.mesh);
        let (_, n, _) = hit.facing(ray.dir);
        let local = self.lighting.shade_material_unshadowed(&m.shading, m.color, ray, hit.t, n);
        let background = m.background_share((-ray.dir.dot(n)).clamp(0.0, 1.0));
        f64::from(m.local_share()) * local.as_dvec3() + background.as_dvec3() * self.settings.background.as_dvec3()
    }

    /// A sample buffer with the meshes drawn in (their depth, for the depth test).
    fn sample_buffer(&self, px: &PixelSamples) -> SampleBuffer {
        let mut buf = SampleBuffer::new(self.offsets.len());
        for (s, hit) in px.surfaces.iter().enumerate() {
            if let Some(hit) = hit {
                buf.write(s, hit.t, MESH, MESH);
            }
        }
        buf
    }

    /// The same rasterizer lit by `lighting` (no shadows: the raster pipelines have none,
    /// vk_gaussian_splatting Lighting §3).
    pub fn with_lighting(mut self, lighting: impl Into<Cow<'a, Lighting>>) -> Result<Self, RenderError> {
        let lighting = lighting.into();
        lighting.validate(self.scene.particles.len()).map_err(RenderError::Settings)?;
        self.lighting = lighting;
        Ok(self)
    }

    /// Refuse what the rasterizer would draw wrong among transparent meshes: sorted splatting's
    /// surface look lights the splats' blended radiance once, at one picked particle, and has no
    /// place for the already shaded colour of a transparent triangle between them (the
    /// volumetric look and unlit splats composite it as a fragment); and particle ids must stay
    /// below the [`TRIANGLE`] bit that marks triangle ids.
    pub fn check_meshes(&self) -> Result<(), RenderError> {
        if !self.meshes.has_transparent() {
            return Ok(());
        }
        if self.lighting.is_on() && !self.volumetric() {
            return Err(RenderError::Settings("transparent meshes among lit splats need the volumetric look".into()));
        }
        if self.scene.particles.len() >= TRIANGLE as usize {
            return Err(RenderError::Settings(format!(
                "{} particles among transparent meshes: at most {} fit beside the triangles' ids",
                self.scene.particles.len(),
                TRIANGLE
            )));
        }
        Ok(())
    }

    /// Whether every fragment is lit before blending ([`Look::Volumetric`]).
    fn volumetric(&self) -> bool {
        self.lighting.is_on() && self.lighting.look == Look::Volumetric
    }

    /// The colour of fragment source `source` written at depth `t` of sample `s`: a splat's SH
    /// colour, lit at that point with its normal when lighting is on: without shadows in the
    /// raster pipeline (vk_gaussian_splatting Lighting §3), with the ray tracer's shadow rays in
    /// the hybrid one (§5: after the raster first hit, lighting and shadows as in pure ray
    /// tracing); a transparent triangle's shaded surface colour S ([`Rasterizer::surface_color`]).
    fn lit_color(&self, px: &PixelSamples, source: u32, s: usize, t: f32, decide: &impl Decide) -> DVec3 {
        if let Some(k) = triangle_of(source) {
            let hit = self.meshes.hit_triangle(k, &px.rays[s]);
            return hit.map_or(DVec3::ZERO, |hit| self.surface_color(px, s, &hit, decide));
        }
        let c = self.splats[source as usize].color;
        if !self.lighting.is_on() {
            return c.as_dvec3();
        }
        let (id, ray, n) = (self.splats[source as usize].id, &px.rays[s], self.normal(px, source));
        match &self.hybrid {
            Some((trace, _)) => trace.light_pick(c, id, t, n, ray, decide).as_dvec3(),
            None => self.lighting.shade_unshadowed(c, id, ray, t, n).as_dvec3(),
        }
    }

    /// The projected splats in global depth order.
    pub fn splats(&self) -> &[Splat] {
        &self.splats
    }

    /// The raster settings.
    pub fn raster_settings(&self) -> &RasterSettings {
        &self.raster
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        self.scene
    }

    /// The geometry of pixel (x, y)'s samples.
    pub fn pixel(&self, x: u32, y: u32) -> PixelSamples {
        let c = &self.camera;
        let positions: Vec<Vec2> = self.offsets.iter().map(|&o| Vec2::new(x as f32, y as f32) + o).collect();
        let rays: Vec<Ray> = self.offsets.iter().map(|&o| self.clip(c.ray(x, y, o))).collect();
        // Splat depths are view z through the pinhole (a point at depth z is at t = z |d_cam|)
        // and distances through other lenses (t = depth along a unit ray).
        let stretch = positions.iter().map(|&p| if c.is_pinhole() { c.direction(p).length() } else { 1.0 }).collect();
        let surfaces = if self.meshes.is_empty() {
            vec![None; rays.len()]
        } else {
            rays.iter().map(|r| self.meshes.closest_opaque(r)).collect()
        };
        let centre = self.clip(c.pixel_ray(x, y));
        PixelSamples { x, y, rays, centre, stretch, positions, surfaces }
    }

    fn clip(&self, ray: Ray) -> Ray {
        Ray { t_min: self.settings.t_min, t_max: self.settings.t_max, ..ray }
    }

    /// The fragments of pixel `px`, in global depth order.
    pub fn fragments(&self, px: &PixelSamples) -> Vec<Fragment> {
        let tiles_x = self.camera.width.div_ceil(TILE);
        let tile = (px.y / TILE) * tiles_x + px.x / TILE;
        let centre = Vec2::new(px.x as f32 + 0.5, px.y as f32 + 0.5);
        let kernel = &self.settings.kernel;
        self.bins[tile as usize]
            .iter()
            .filter_map(|&k| {
                let s = &self.splats[k as usize];
                let [x0, y0, x1, y1] = s.rect;
                if px.x < x0 || px.x >= x1 || px.y < y0 || px.y >= y1 {
                    return None;
                }
                let alpha = match self.raster.response {
                    Response::Projected => kernel.alpha(s.opacity, kernel.response(s.mahalanobis(centre)))?,
                    Response::AlongRay => self.alpha_along_ray(k, &px.centre, centre)?,
                };
                let covered =
                    px.positions.iter().enumerate().filter(|(_, p)| s.covers(**p)).fold(0u64, |m, (i, _)| m | 1 << i);
                (covered != 0).then_some(Fragment { source: k, alpha, covered })
            })
            .chain(self.triangle_fragments(px))
            .collect()
    }

    /// The fragments of the transparent triangles in pixel `px`, in the order the meshes list
    /// their triangles: a triangle covers the samples whose rays cross it (the mesh pre-pass's
    /// ray cast), its alpha is its opacity where the pixel centre's ray meets its plane.
    fn triangle_fragments(&self, px: &PixelSamples) -> Vec<Fragment> {
        if !self.meshes.has_transparent() {
            return Vec::new();
        }
        let (mut hits, mut covered) = (Vec::new(), Vec::<(u32, u64)>::new());
        for (s, ray) in px.rays.iter().enumerate() {
            self.meshes.transparent_hits(ray, &mut hits);
            for &k in &hits {
                match covered.iter_mut().find(|(j, _)| *j == k) {
                    Some((_, mask)) => *mask |= 1 << s,
                    None => covered.push((k, 1 << s)),
                }
            }
        }
        let triangles = self.meshes.triangles();
        covered.sort_by_key(|&(k, _)| triangles[k as usize].order);
        covered
            .into_iter()
            .filter_map(|(k, covered)| {
                let tri = &triangles[k as usize];
                let alpha = tri.plane_barycentrics(&px.centre).map_or(tri.alphas[0], |(b1, b2)| tri.alpha_at(b1, b2));
                (alpha > 0.0).then_some(Fragment { source: TRIANGLE | k, alpha, covered })
            })
            .collect()
    }

    /// [`Response::AlongRay`]: the alpha of splat `k` (index into [`Rasterizer::splats`]) on
    /// the pixel-centre ray `ray` through pixel position `centre`: the ray tracers' hit
    /// ([`crate::hit::intersect`] at the point of maximum response), and for a surfel the larger
    /// of that and 2DGS's low-pass response.
    fn alpha_along_ray(&self, k: u32, ray: &Ray, centre: Vec2) -> Option<f32> {
        let (kernel, s) = (&self.settings.kernel, &self.splats[k as usize]);
        let p = &self.prepared[k as usize];
        let in_3d = intersect(p, s.id, ray, kernel, HitDistance::Mean).map(|h| h.alpha);
        if !self.scene.particles[s.id as usize].is_surfel() {
            return in_3d;
        }
        let low_pass = kernel.alpha(p.opacity, kernel.response((centre - s.mean).length_squared() / SURFEL_LOW_PASS));
        match (in_3d, low_pass) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        }
    }

    /// Depth of fragment `f` at sample `s`: distance along the sample's ray.
    #[inline]
    pub fn depth(&self, px: &PixelSamples, f: &Fragment, s: usize) -> f32 {
        if let Some(k) = triangle_of(f.source) {
            return self.meshes.hit_triangle(k, &px.rays[s]).map_or(f32::INFINITY, |h| h.t);
        }
        match self.raster.fragment_depth {
            FragmentDepth::Center => self.splats[f.source as usize].depth * px.stretch[s],
            FragmentDepth::MaxDensityPlane => {
                let (o, d) = to_canonical(&self.prepared[f.source as usize], &px.rays[s]);
                -o.dot(d) / d.length_squared()
            }
        }
    }

    /// The id that orders a fragment among equal depths and keys its decisions: the particle's
    /// id, or [`TRIANGLE`] | the triangle's place in the meshes' order.
    fn id(&self, f: &Fragment) -> u32 {
        match triangle_of(f.source) {
            Some(k) => TRIANGLE | self.meshes.triangles()[k as usize].order,
            None => self.splats[f.source as usize].id,
        }
    }

    /// The particle a fragment source picks (none for a triangle).
    fn picked(&self, source: u32) -> Option<u32> {
        triangle_of(source).is_none().then(|| self.splats[source as usize].id)
    }

    /// The colour a fragment blends at sample `s` and depth `t`: lit first in the volumetric
    /// look; a triangle's is its surface's shaded colour S.
    fn color(&self, px: &PixelSamples, f: &Fragment, s: usize, t: f32, decide: &impl Decide) -> DVec3 {
        if self.volumetric() || triangle_of(f.source).is_some() {
            self.lit_color(px, f.source, s, t, decide)
        } else {
            self.splats[f.source as usize].color.as_dvec3()
        }
    }

    /// Unit normal of fragment source `source` along sample 0's ray: the splat's, or the
    /// triangle's shading normal facing the ray.
    fn normal(&self, px: &PixelSamples, source: u32) -> Vec3 {
        let ray = &px.rays[0];
        if let Some(k) = triangle_of(source) {
            return self.meshes.hit_triangle(k, ray).map_or(Vec3::ZERO, |h| h.facing(ray.dir).1);
        }
        let s = &self.settings;
        particle_normal(&self.prepared[source as usize], ray, s.normal_mode, s.kernel.cutoff)
    }

    /// The draw order of a stochastic frame: the transparent triangles first, in the order the
    /// meshes list them (the submission order of Laine & Karras's renderer, which its surface
    /// tracking follows), then the splats ordered by a hash of (splat id, frame), one random
    /// permutation of the splats shared by every pixel of the frame.
    pub fn shuffle(&self, fragments: &mut [Fragment], frame_key: u32) {
        let seed = xxhash32([frame_key, ORDER_ID, 0]);
        fragments.sort_by_cached_key(|f| {
            let id = self.id(f);
            if triangle_of(f.source).is_some() { (false, id, id) } else { (true, xxhash32([id, seed, 0]), id) }
        });
    }

    /// One frame of `method` at pixel `px` from its fragments (in draw order: the global sort
    /// for [`RasterMethod::Sorted`], any order for the others). Stochastic decisions come from
    /// `decide` (slot = sample index); the stratified method uses `frame_key` for its sequence.
    pub fn draw(
        &self,
        method: &RasterMethod,
        px: &PixelSamples,
        fragments: &[Fragment],
        decide: &impl Decide,
        frame_key: u32,
    ) -> Sample {
        match *method {
            RasterMethod::Sorted { blend } => self.sorted(px, fragments, blend, decide),
            RasterMethod::StochasticSplat => self.resolve(px, &self.stochastic_splat(px, fragments, decide), decide),
            RasterMethod::Enderton => self.resolve(px, &self.enderton(px, fragments, decide), decide),
            RasterMethod::Stratified { scramble } => {
                self.resolve(px, &self.stratified(px, fragments, decide, frame_key, scramble), decide)
            }
        }
    }

    /// Sorted splatting of every sample (Eq. 3 over the fragments in depth order, in front of
    /// the sample's mesh, over its colour). Lit, the blend is front to back
    /// (vk_gaussian_splatting Lighting §1.5: the picked surface needs it); the surface look
    /// lights the pixel once ([`Rasterizer::light_surface`]). Where no splat reaches the iso
    /// threshold, the mesh of sample 0 gives depth and normal (depth consolidation, §1.5.3).
    fn sorted(&self, px: &PixelSamples, fragments: &[Fragment], blend: Blend, decide: &impl Decide) -> Sample {
        let blend = if self.lighting.is_on() { Blend::Under } else { blend };
        let surface_look = self.lighting.is_on() && !self.volumetric();
        let iso = f64::from(self.settings.raster_iso_threshold);
        let mut out = Sample { color: DVec3::ZERO, alpha: 0.0, depth: None, normal: Vec3::ZERO, picked: None };
        let mut order: Vec<(f32, u32, usize)> = Vec::with_capacity(fragments.len());
        let mut normal = DVec3::ZERO;
        let mut drawn = false;
        // Σ_s T_s behind_s and Σ_s behind_s, for the surface look.
        let (mut seen_behind, mut behind_sum) = (DVec3::ZERO, DVec3::ZERO);
        for s in 0..self.offsets.len() {
            let behind = self.behind(px, s, decide);
            let bg = if surface_look { DVec3::ZERO } else { behind };
            let t_mesh = px.surfaces[s].map_or(f32::INFINITY, |h| h.t);
            order.clear();
            order.extend(
                fragments
                    .iter()
                    .enumerate()
                    .filter(|(_, f)| f.covered >> s & 1 == 1)
                    .map(|(i, f)| (self.depth(px, f, s), self.id(f), i))
                    .filter(|&(t, _, _)| t < t_mesh),
            );
            if self.raster.fragment_depth == FragmentDepth::MaxDensityPlane || self.meshes.has_transparent() {
                order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            }
            if self.raster.early_stop {
                order.truncate(early_stop_len(order.iter().map(|&(_, _, i)| fragments[i].alpha)));
            }
            let mut transmittance = 1.0f64;
            let color = match blend {
                Blend::Over => {
                    let mut c = bg;
                    for &(t, _, i) in order.iter().rev() {
                        let a = f64::from(fragments[i].alpha);
                        c = a * self.color(px, &fragments[i], s, t, decide) + (1.0 - a) * c;
                        transmittance *= 1.0 - a;
                    }
                    c
                }
                Blend::Under => {
                    let mut c = DVec3::ZERO;
                    for &(t, _, i) in &order {
                        let f = &fragments[i];
                        let w = transmittance * f64::from(f.alpha);
                        c += w * self.color(px, f, s, t, decide);
                        transmittance *= 1.0 - f64::from(f.alpha);
                        if s == 0 {
                            normal += w * self.normal(px, f.source).as_dvec3();
                            drawn = true;
                            if out.depth.is_none() && transmittance < iso {
                                (out.depth, out.picked) = (Some(t), self.picked(f.source));
                            }
                        }
                    }
                    c + transmittance * bg
                }
            };
            out.color += color;
            let mesh = if px.surfaces[s].is_some() { 1.0 } else { 0.0 };
            out.alpha += 1.0 - transmittance + transmittance * mesh;
            seen_behind += transmittance * behind;
            behind_sum += behind;
        }
        let n = self.offsets.len() as f64;
        out.color /= n;
        out.alpha /= n;
        if drawn {
            out.normal = crate::composite::integrated_normal(normal, px.rays[0].dir);
        }
        if let (None, Some(hit)) = (out.depth, &px.surfaces[0]) {
            (out.depth, out.normal) = (Some(hit.t), hit.facing(px.rays[0].dir).1);
        }
        if surface_look { self.light_surface(px, out, seen_behind / n, behind_sum / n, decide) } else { out }
    }

    /// The surface look of sorted splatting (vk_gaussian_splatting Lighting §1.1, §2.1, §3 step
    /// 6): `blended` holds the pixel's radiance L without what lies behind, the picked depth and
    /// particle and the integrated normal; L is lit once at the picked depth along sample 0's
    /// ray with the picked particle's material (with shadow rays in the hybrid pipeline), then
    /// `seen_behind` = mean of T_s × behind_s is added. A pixel whose transmittance never
    /// reached the threshold shows what lies behind, `behind`.
    fn light_surface(
        &self,
        px: &PixelSamples,
        blended: Sample,
        seen_behind: DVec3,
        behind: DVec3,
        decide: &impl Decide,
    ) -> Sample {
        let (Some(t), Some(id)) = (blended.depth, blended.picked) else {
            let meshes = px.surfaces.iter().filter(|h| h.is_some()).count();
            if meshes == 0 {
                return Sample::background(self.settings.background);
            }
            let alpha = meshes as f64 / px.surfaces.len() as f64;
            return Sample { color: behind, alpha, picked: None, ..blended };
        };
        let (c, ray, n) = (blended.color.as_vec3(), &px.rays[0], blended.normal);
        let lit = match &self.hybrid {
            Some((trace, _)) => trace.light_pick(c, id, t, n, ray, decide),
            None => self.lighting.shade_unshadowed(c, id, ray, t, n),
        };
        Sample { color: lit.as_dvec3() + seen_behind, ..blended }
    }

    /// StochasticSplats: each covered sample that passes the depth test draws u = hash(pixel,
    /// frame, splat id, sample) and is written opaque when u < α, else discarded.
    fn stochastic_splat(&self, px: &PixelSamples, fragments: &[Fragment], decide: &impl Decide) -> SampleBuffer {
        let mut buf = self.sample_buffer(px);
        for f in fragments {
            let id = self.id(f);
            for s in bits(f.covered) {
                let t = self.depth(px, f, s);
                if buf.passes(s, t, id) && decide.accepts(id, decide.particle(id, s as u32, Vec3::ZERO), f.alpha) {
                    buf.write(s, t, id, f.source);
                }
            }
        }
        buf
    }

    /// Enderton et al.: the m covered samples that pass the depth test get R = ⌊α m + ξ⌋
    /// writes, on a uniformly random subset (partial Fisher–Yates); each is written with
    /// probability E[R]/m = α.
    fn enderton(&self, px: &PixelSamples, fragments: &[Fragment], decide: &impl Decide) -> SampleBuffer {
        let mut buf = self.sample_buffer(px);
        let mut alive: Vec<(usize, f32)> = Vec::with_capacity(self.offsets.len());
        for f in fragments {
            let id = self.id(f);
            self.surviving(px, f, &buf, &mut alive);
            let m = alive.len();
            let xi = decide.particle(id, ENDERTON_XI_SLOT, Vec3::ZERO);
            let r = ((f.alpha * m as f32 + xi).floor() as usize).min(m);
            for j in 0..r {
                let u = decide.particle(id, ENDERTON_XI_SLOT + 1 + j as u32, Vec3::ZERO);
                let pick = j + ((u * (m - j) as f32) as usize).min(m - j - 1);
                alive.swap(j, pick);
                let (s, t) = alive[j];
                buf.write(s, t, id, f.source);
            }
        }
        buf
    }

    /// The covered samples of `f` that pass the depth test, with their depths, into `alive`.
    fn surviving(&self, px: &PixelSamples, f: &Fragment, buf: &SampleBuffer, alive: &mut Vec<(usize, f32)>) {
        let id = self.id(f);
        alive.clear();
        alive.extend(bits(f.covered).map(|s| (s, self.depth(px, f, s))).filter(|&(s, t)| buf.passes(s, t, id)));
    }

    /// Laine & Karras 2011, Figure 7 (DrawFragment), line by line. The surface id of every
    /// pixel starts at a per-frame hash so that frames are independent.
    fn stratified(
        &self,
        px: &PixelSamples,
        fragments: &[Fragment],
        decide: &impl Decide,
        frame_key: u32,
        scramble: bool,
    ) -> SampleBuffer {
        let spp = self.offsets.len() as u32;
        let variant = self.raster.lk_variant;
        let pixel_id = match variant {
            LkVariant::Morton => morton_index(px.x, px.y),
            _ => hilbert_index(self.hilbert_order, px.x, px.y),
        };
        let alpha_ref = |n, surface_id| match variant {
            LkVariant::Sobol => sobol_alpha_ref(n, pixel_id, surface_id, spp),
            _ => calc_alpha_ref(n, pixel_id, surface_id, spp, scramble),
        };
        let mut buf = self.sample_buffer(px);
        let mut covered = 0u64;
        let mut surface_id = xxhash32([frame_key, SURFACE_ID, 0]);
        let mut alive: Vec<(usize, f32)> = Vec::with_capacity(self.offsets.len());
        for f in fragments {
            let id = self.id(f);
            // Lines 1–3: early per-sample depth test.
            self.surviving(px, f, &buf, &mut alive);
            // Lines 4–7: a conflict with the current surface's coverage starts a new surface.
            let mask = alive.iter().fold(0u64, |m, &(s, _)| m | 1 << s);
            if mask & covered != 0 {
                surface_id = surface_id.wrapping_add(1);
                covered = 0;
            }
            // Line 9: order by the depth previously stored at each sample (ties by sample).
            if variant != LkVariant::Unsorted {
                alive.sort_by(|a, b| buf.cmp_stored(a.0, b.0));
            }
            // Lines 8, 10–17: opacity test against the reference values, in that order, the
            // surface's sequence continuing where it stopped (n starts at the bits set).
            for (n, &(s, t)) in (covered.count_ones()..).zip(&alive) {
                if decide.covers(f.alpha, alpha_ref(n, surface_id)) {
                    buf.write(s, t, id, f.source);
                }
            }
            // Line 18.
            covered |= mask;
        }
        buf
    }

    /// Average the samples of a stochastic frame; sample 0 gives depth, normal and pick.
    fn resolve(&self, px: &PixelSamples, buf: &SampleBuffer, decide: &impl Decide) -> Sample {
        let bg = self.settings.background.as_dvec3();
        let mut color = DVec3::ZERO;
        let mut written = 0usize;
        for s in 0..buf.len {
            match buf.splat[s] {
                u32::MAX => color += bg,
                MESH => {
                    color += self.behind(px, s, decide);
                    written += 1;
                }
                k => {
                    color += self.lit_color(px, k, s, buf.t[s], decide);
                    written += 1;
                }
            }
        }
        let n = buf.len as f64;
        let (depth, normal, picked) = match buf.splat[0] {
            u32::MAX => (None, Vec3::ZERO, None),
            MESH => (Some(buf.t[0]), px.surfaces[0].map_or(Vec3::ZERO, |h| h.facing(px.rays[0].dir).1), None),
            k => (Some(buf.t[0]), self.normal(px, k), self.picked(k)),
        };
        Sample { color: color / n, alpha: written as f64 / n, depth, normal, picked }
    }
}

/// How many of the front-to-back alphas the 3DGS rasterizer composites: it stops before the
/// first fragment that would take the transmittance below [`EARLY_STOP_T`].
fn early_stop_len(alphas: impl Iterator<Item = f32>) -> usize {
    let mut transmittance = 1.0f64;
    let mut len = 0;
    for alpha in alphas {
        transmittance *= 1.0 - f64::from(alpha);
        if transmittance < EARLY_STOP_T {
            break;
        }
        len += 1;
    }
    len
}

/// Per-sample depth and colour buffer of one pixel: the nearest written fragment of each
/// sample, by (depth, splat id).
struct SampleBuffer {
    len: usize,
    t: [f32; MAX_SAMPLES as usize],
    id: [u32; MAX_SAMPLES as usize],
    splat: [u32; MAX_SAMPLES as usize],
}

impl SampleBuffer {
    fn new(len: usize) -> Self {
        const N: usize = MAX_SAMPLES as usize;
        Self { len, t: [f32::INFINITY; N], id: [u32::MAX; N], splat: [u32::MAX; N] }
    }

    /// The depth test: (t, id) strictly in front of what sample `s` holds.
    #[inline]
    fn passes(&self, s: usize, t: f32, id: u32) -> bool {
        depth_before(t, id, self.t[s], self.id[s])
    }

    /// Order of two samples by what they hold, (depth, id), then by sample index.
    fn cmp_stored(&self, a: usize, b: usize) -> std::cmp::Ordering {
        self.t[a].total_cmp(&self.t[b]).then(self.id[a].cmp(&self.id[b])).then(a.cmp(&b))
    }

    fn write(&mut self, s: usize, t: f32, id: u32, splat: u32) {
        (self.t[s], self.id[s], self.splat[s]) = (t, id, splat);
    }
}

/// Indices of the set bits of a coverage mask.
fn bits(mask: u64) -> impl Iterator<Item = usize> {
    let mut m = mask;
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let s = m.trailing_zeros() as usize;
            m &= m - 1;
            s
        })
    })
}

/// Splat indices per tile, in global depth order.
fn bin_tiles(camera: &Camera, splats: &[Splat]) -> Vec<Vec<u32>> {
    let t = TILE;
    let tiles_x = camera.width.div_ceil(t);
    let mut bins = vec![Vec::new(); tile_count(camera) as usize];
    for (k, s) in splats.iter().enumerate() {
        let [x0, y0, x1, y1] = s.rect;
        for ty in y0 / t..=(y1 - 1) / t {
            for tx in x0 / t..=(x1 - 1) / t {
                bins[(ty * tiles_x + tx) as usize].push(k as u32);
            }
        }
    }
    bins
}

/// Render `frames.count` frames of `method` (one for sorted splatting) on the frame loop of
/// [`crate::frame`], through the rasterizer's camera every frame. Every decision is a hash, so
/// the result does not depend on the thread count. `progress` receives finished pixel counts.
pub fn render_raster(
    raster: &Rasterizer,
    method: &RasterMethod,
    frames: &Frames,
    progress: Progress,
) -> Result<RenderOutput, RenderError> {
    raster.check_meshes()?;
    let keys = raster_keys(frames, raster.is_random(method))?;
    Ok(render_keys(raster, method, &keys, frames, progress))
}

/// The frame keys of a splatting render (its decisions are hashes only).
fn raster_keys(frames: &Frames, random: bool) -> Result<Vec<u32>, RenderError> {
    if frames.rng != RngScheme::Hash {
        return Err(RenderError::Settings("the raster methods draw their decisions with the hash generator".into()));
    }
    frames.keys(random)
}

/// The frames of keys `keys` through the rasterizer's camera (the decisions' shift and the
/// mean's storage from `frames`).
fn render_keys(
    raster: &Rasterizer,
    method: &RasterMethod,
    keys: &[u32],
    frames: &Frames,
    progress: Progress,
) -> RenderOutput {
    render_tiles(
        &raster.camera,
        progress,
        |_| (),
        |_, x, y| {
            let px = raster.pixel(x, y);
            let mut fragments = raster.fragments(&px);
            PixelFrames::over(keys, frames.accumulation, |key| {
                if method.is_stochastic() {
                    raster.shuffle(&mut fragments, key);
                }
                let rng = RayRng::new(x, y, key, RngScheme::Hash).shifted(frames.u_shift);
                raster.draw(method, &px, &fragments, &rng, key)
            })
        },
    )
}

/// Splatting under the settings' [`crate::camera_sampling`]: through a still camera, the
/// rasterizer `build(camera)` draws every frame; through a camera drawn per frame, frame f is
/// drawn by `build` of that frame's pinhole camera (its splats projected again) and the frames
/// are folded by [`fold_frames`]. Either way frame f has the key of frame f.
pub fn render_raster_frames<'a>(
    camera: &Camera,
    sampling: &CameraSampling,
    method: &RasterMethod,
    frames: &Frames,
    progress: Progress,
    build: impl Fn(&Camera) -> Result<Rasterizer<'a>, RenderError>,
) -> Result<RenderOutput, RenderError> {
    if !sampling.is_random() {
        return render_raster(&build(camera)?, method, frames, progress);
    }
    let keys = raster_keys(frames, true)?;
    fold_frames(camera, &keys, frames.accumulation, progress, |f, key| {
        let raster = build(&sampling.pinhole(camera, &frame_sample(frames.seed, frames.index(f)))?)?;
        raster.check_meshes()?;
        let one = Frames { accumulation: AccumulationFormat::F32, ..*frames };
        Ok(render_keys(&raster, method, &[key], &one, &|_| {}))
    })
}
