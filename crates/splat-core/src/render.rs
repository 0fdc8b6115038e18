//! The exact renderer: for every pixel, every hit along its ray, sorted and composited by
//! Eq. 3 in f64. Particles are binned into 16 × 16 pixel tiles by the projection of their
//! bounding boxes, a conservative cull that changes no result (a test checks it against the
//! brute-force [`oracle_ray`]); tiles run in parallel with rayon when the feature is on.

use crate::camera::{Camera, CameraError};
use crate::composite::{Composite, DEFAULT_ISO_THRESHOLD, ShadedHit, composite, sort_front_to_back};
use crate::hit::{DEFAULT_T_MAX, DEFAULT_T_MIN, Hit, HitDistance, PreparedParticle, Ray, intersect};
use crate::image::Image;
use crate::kernel::KernelParams;
use crate::normal::{NormalMode, particle_normal};
use crate::particle::{ParticleError, Scene};
use crate::sh;
use glam::{Vec2, Vec3};
use thiserror::Error;

/// Side of the square pixel tiles that particles are binned into.
pub const TILE: u32 = 16;

/// Everything that decides an exact image besides the scene and camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Particle response.
    pub kernel: KernelParams,
    /// Hit distance convention (§4.1).
    pub hit_distance: HitDistance,
    /// Per-particle normal (seed 003 §2.4).
    pub normal_mode: NormalMode,
    /// Colour behind the particles.
    pub background: Vec3,
    /// Iso-opacity depth threshold on transmittance (seed 003 §1.1).
    pub iso_threshold: f32,
    /// Ray start t_min.
    pub t_min: f32,
    /// Ray end t_max.
    pub t_max: f32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            kernel: KernelParams::default(),
            hit_distance: HitDistance::Mean,
            normal_mode: NormalMode::MaxDensityPlane,
            background: Vec3::ZERO,
            iso_threshold: DEFAULT_ISO_THRESHOLD,
            t_min: DEFAULT_T_MIN,
            t_max: DEFAULT_T_MAX,
        }
    }
}

/// Why a render cannot start.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum RenderError {
    /// A setting is out of range.
    #[error("invalid render setting: {0}")]
    Settings(String),
    /// The camera is invalid.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// A particle is invalid.
    #[error("particle {index}: {error}")]
    Particle {
        /// Its index in the scene.
        index: usize,
        /// What is wrong.
        error: ParticleError,
    },
    /// The scene's SH degree is above 3.
    #[error("SH degree {0} is above 3")]
    ShDegree(u8),
}

impl RenderSettings {
    /// Check every setting, naming the first bad one.
    pub fn validate(&self) -> Result<(), RenderError> {
        self.kernel.validate().map_err(RenderError::Settings)?;
        if !self.background.is_finite() {
            return Err(RenderError::Settings(format!("background {} is not finite", self.background)));
        }
        if !(0.0..=1.0).contains(&self.iso_threshold) {
            return Err(RenderError::Settings(format!("iso threshold {} is outside [0, 1]", self.iso_threshold)));
        }
        if !(self.t_min.is_finite() && self.t_min >= 0.0 && self.t_max > self.t_min) {
            return Err(RenderError::Settings(format!(
                "ray range ({}, {}) is empty or invalid",
                self.t_min, self.t_max
            )));
        }
        Ok(())
    }
}

/// The images of an exact render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOutput {
    /// RGB: L + T × background (Eq. 3).
    pub radiance: Image,
    /// Overall opacity 1 − T.
    pub alpha: Image,
    /// Iso-opacity depth (ray distance t); NaN where the threshold is never reached.
    pub depth: Image,
    /// Unit integrated normal, world space; zero where no particle is hit.
    pub normal: Image,
}

/// A scene ready to trace: the prepared particles beside the scene they came from.
pub struct Tracer<'a> {
    scene: &'a Scene,
    prepared: Vec<PreparedParticle>,
    settings: RenderSettings,
}

impl<'a> Tracer<'a> {
    /// Validate the settings and the scene and prepare every particle.
    pub fn new(scene: &'a Scene, settings: RenderSettings) -> Result<Self, RenderError> {
        validate_scene(scene, &settings)?;
        let prepared = scene.particles.iter().map(PreparedParticle::new).collect();
        Ok(Self { scene, prepared, settings })
    }

    /// The settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.prepared.len()
    }

    /// Whether the scene is empty.
    pub fn is_empty(&self) -> bool {
        self.prepared.is_empty()
    }

    /// The ray with the settings' range applied.
    pub fn clip(&self, ray: Ray) -> Ray {
        Ray { t_min: self.settings.t_min, t_max: self.settings.t_max, ..ray }
    }

    /// Intersect and shade particle `index`: colour from SH along the ray direction, normal by
    /// the settings' mode. `None` when the ray misses it (Algorithm 1 without the roulette).
    pub fn shade(&self, index: u32, ray: &Ray) -> Option<ShadedHit> {
        let s = &self.settings;
        let p = &self.prepared[index as usize];
        let hit = intersect(p, index, ray, &s.kernel, s.hit_distance)?;
        Some(shade_hit(self.scene, p, hit, ray, s))
    }

    /// Every hit of `ray` among `candidates`, sorted front to back and composited (Eq. 3).
    /// `scratch` is reused between calls to avoid an allocation per ray.
    pub fn trace(
        &self,
        ray: &Ray,
        candidates: impl IntoIterator<Item = u32>,
        scratch: &mut Vec<ShadedHit>,
    ) -> Composite {
        scratch.clear();
        scratch.extend(candidates.into_iter().filter_map(|i| self.shade(i, ray)));
        sort_front_to_back(scratch);
        composite(scratch, self.settings.iso_threshold)
    }
}

/// Check that a scene can be rendered with these settings: valid settings, SH degree ≤ 3,
/// every particle valid, ids below the ones the RNG reserves.
pub fn validate_scene(scene: &Scene, settings: &RenderSettings) -> Result<(), RenderError> {
    settings.validate()?;
    if scene.sh_degree > crate::particle::SH_MAX_DEGREE {
        return Err(RenderError::ShDegree(scene.sh_degree));
    }
    if scene.particles.len() > crate::rng::MAX_PARTICLES {
        return Err(RenderError::Settings(format!(
            "{} particles is more than the {} supported",
            scene.particles.len(),
            crate::rng::MAX_PARTICLES
        )));
    }
    for (index, p) in scene.particles.iter().enumerate() {
        p.validate().map_err(|error| RenderError::Particle { index, error })?;
    }
    Ok(())
}

/// Shade a hit of particle `hit.index`: colour from its SH along the ray direction, normal by
/// the settings' mode.
pub fn shade_hit(scene: &Scene, p: &PreparedParticle, hit: Hit, ray: &Ray, settings: &RenderSettings) -> ShadedHit {
    let particle = &scene.particles[hit.index as usize];
    ShadedHit {
        t: hit.t,
        alpha: hit.alpha,
        color: sh::eval(&particle.sh, scene.sh_degree, ray.dir),
        normal: particle_normal(p, ray, settings.normal_mode, settings.kernel.cutoff),
        index: hit.index,
    }
}

/// The oracle for one ray: every particle of the scene tested by brute force, hits sorted
/// front to back and composited by Eq. 3 in f64. The ray's own range is replaced by the
/// settings' (t_min, t_max).
pub fn oracle_ray(scene: &Scene, ray: Ray, settings: &RenderSettings) -> Result<Composite, RenderError> {
    let tracer = Tracer::new(scene, *settings)?;
    let n = tracer.len() as u32;
    Ok(tracer.trace(&tracer.clip(ray), 0..n, &mut Vec::new()))
}

/// Render every pixel exactly (rays through pixel centres). `progress` is called with the
/// number of pixels finished since its last call.
pub fn render_exact(
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<RenderOutput, RenderError> {
    camera.validate()?;
    let tracer = Tracer::new(scene, *settings)?;
    let bins = TileBins::new(scene, camera, settings.kernel.cutoff);
    let results = map_tiles(camera, |tile| {
        let pixels = tile_pixels(camera, tile, &tracer, &bins);
        progress(pixels.len() as u64);
        pixels
    });
    Ok(assemble(camera, &results))
}

/// Number of [`TILE`] × [`TILE`] tiles covering a camera's image.
pub fn tile_count(camera: &Camera) -> u32 {
    camera.width.div_ceil(TILE) * camera.height.div_ceil(TILE)
}

/// Pixel range [x0, x1) × [y0, y1) of tile `tile` (row-major) of a camera's image.
pub fn tile_rect(camera: &Camera, tile: u32) -> (u32, u32, u32, u32) {
    let tiles_x = camera.width.div_ceil(TILE);
    let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
    (x0, y0, (x0 + TILE).min(camera.width), (y0 + TILE).min(camera.height))
}

/// The pixels (x, y) of tile `tile`, row by row.
pub fn tile_coords(camera: &Camera, tile: u32) -> impl Iterator<Item = (u32, u32)> {
    let (x0, y0, x1, y1) = tile_rect(camera, tile);
    (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y)))
}

/// `f` of every tile, in tile order; tiles run in parallel with the `rayon` feature. Each
/// tile's result depends only on the tile, so the output does not depend on the thread count.
pub fn map_tiles<T: Send>(camera: &Camera, f: impl Fn(u32) -> T + Sync + Send) -> Vec<T> {
    let tiles = 0..tile_count(camera);
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        tiles.into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "rayon"))]
    {
        tiles.map(f).collect()
    }
}

/// What one pixel writes to the output images: RGB, alpha, depth, normal.
type PixelValues = [f32; 8];

/// Trace the pixels of one tile, row by row, into their output values.
fn tile_pixels(camera: &Camera, tile: u32, tracer: &Tracer, bins: &TileBins) -> Vec<PixelValues> {
    let (x0, y0, x1, y1) = tile_rect(camera, tile);
    let candidates = bins.candidates(tile);
    let background = tracer.settings().background;
    let mut scratch = Vec::new();
    let mut out = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
    for y in y0..y1 {
        for x in x0..x1 {
            let ray = tracer.clip(camera.ray(x, y, Vec2::splat(0.5)));
            let c = tracer.trace(&ray, candidates.iter().copied(), &mut scratch);
            let rgb = c.color_over(background).as_vec3();
            let n = c.unit_normal(ray.dir);
            let depth = c.depth.unwrap_or(f32::NAN);
            out.push([rgb.x, rgb.y, rgb.z, c.alpha() as f32, depth, n.x, n.y, n.z]);
        }
    }
    out
}

/// Scatter the tiles' pixel values into the output images.
fn assemble(camera: &Camera, tiles: &[Vec<PixelValues>]) -> RenderOutput {
    let (w, h) = (camera.width, camera.height);
    let mut out = RenderOutput {
        radiance: Image::filled(w, h, 3, 0.0),
        alpha: Image::filled(w, h, 1, 0.0),
        depth: Image::filled(w, h, 1, f32::NAN),
        normal: Image::filled(w, h, 3, 0.0),
    };
    for (tile, values) in tiles.iter().enumerate() {
        for ((x, y), v) in tile_coords(camera, tile as u32).zip(values) {
            out.radiance.pixel_mut(x, y).copy_from_slice(&v[0..3]);
            out.alpha.pixel_mut(x, y)[0] = v[3];
            out.depth.pixel_mut(x, y)[0] = v[4];
            out.normal.pixel_mut(x, y).copy_from_slice(&v[5..8]);
        }
    }
    out
}

/// Particles binned into screen tiles by the projection of their bounding boxes.
///
/// A hit lies inside the particle's cutoff ellipsoid (Eq. 2), hence inside its AABB, so the
/// ray of any pixel that can hit the particle passes through the AABB and its sample point
/// projects inside the convex hull of the projected corners. Boxes that reach behind the
/// camera are put in every tile. The cull is therefore exact, not an approximation.
pub struct TileBins {
    bins: Vec<Vec<u32>>,
}

impl TileBins {
    /// Bin every particle of `scene` for `camera` at cutoff `cutoff`.
    pub fn new(scene: &Scene, camera: &Camera, cutoff: f32) -> Self {
        let tiles_x = camera.width.div_ceil(TILE);
        let tiles_y = camera.height.div_ceil(TILE);
        let mut bins = vec![Vec::new(); (tiles_x * tiles_y) as usize];
        for (index, p) in scene.particles.iter().enumerate() {
            let Some((tx0, ty0, tx1, ty1)) = tile_range(camera, &p.aabb(cutoff), tiles_x, tiles_y) else {
                continue;
            };
            for ty in ty0..=ty1 {
                for tx in tx0..=tx1 {
                    bins[(ty * tiles_x + tx) as usize].push(index as u32);
                }
            }
        }
        Self { bins }
    }

    /// Particles that may be hit by a ray of this tile.
    pub fn candidates(&self, tile: u32) -> &[u32] {
        &self.bins[tile as usize]
    }
}

/// Inclusive tile range covered by the projection of `aabb`, `None` when it is off screen.
fn tile_range(
    camera: &Camera,
    aabb: &crate::particle::Aabb,
    tiles_x: u32,
    tiles_y: u32,
) -> Option<(u32, u32, u32, u32)> {
    let padded = aabb.padded();
    let mut lo = Vec2::splat(f32::INFINITY);
    let mut hi = Vec2::splat(f32::NEG_INFINITY);
    for corner in padded.corners() {
        let c = camera.to_camera(corner);
        if c.z <= 1e-6 {
            return Some((0, 0, tiles_x - 1, tiles_y - 1));
        }
        let p = camera.project_camera(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    // A pixel's samples lie in [x, x + 1): pixels floor(lo) − 1 ..= floor(hi) can see the box.
    let (w, h) = (camera.width as f32, camera.height as f32);
    if hi.x < -1.0 || hi.y < -1.0 || lo.x > w + 1.0 || lo.y > h + 1.0 || !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let px = |v: f32, max: f32| v.floor().clamp(0.0, max - 1.0) as u32 / TILE;
    Some((px(lo.x - 1.0, w), px(lo.y - 1.0, h), px(hi.x + 1.0, w), px(hi.y + 1.0, h)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenes;
    use approx::assert_relative_eq;

    /// Every pixel of the tiled render against the brute-force trace over all particles,
    /// from outside the cloud and from inside it (boxes behind and around the camera).
    #[test]
    fn tiled_render_equals_brute_force_oracle() {
        let (scene, camera) = scenes::cloud();
        let inside =
            Camera::look_at(Vec3::new(0.1, 0.0, 0.3), Vec3::new(0.0, 0.0, -1.0), Vec3::Y, 70.0, 40, 30).unwrap();
        let settings = RenderSettings { background: Vec3::new(0.1, 0.2, 0.3), ..Default::default() };
        let tracer = Tracer::new(&scene, settings).unwrap();
        let all = 0..scene.particles.len() as u32;
        for camera in [camera.rescaled(40, 30).unwrap(), inside] {
            let out = render_exact(&scene, &camera, &settings, &|_| {}).unwrap();
            for y in 0..camera.height {
                for x in 0..camera.width {
                    let ray = tracer.clip(camera.pixel_ray(x, y));
                    let rgb = tracer.trace(&ray, all.clone(), &mut Vec::new()).color_over(settings.background);
                    for k in 0..3 {
                        assert_relative_eq!(out.radiance.pixel(x, y)[k], rgb[k] as f32, epsilon = 1e-6);
                    }
                }
            }
        }
    }

    #[test]
    fn invalid_settings_are_refused() {
        let (scene, camera) = scenes::layers();
        let bad = RenderSettings { iso_threshold: 2.0, ..Default::default() };
        assert!(matches!(render_exact(&scene, &camera, &bad, &|_| {}), Err(RenderError::Settings(_))));
        let mut broken = scene.clone();
        broken.particles[1].scale.y = 0.0;
        assert!(matches!(
            render_exact(&broken, &camera, &RenderSettings::default(), &|_| {}),
            Err(RenderError::Particle { index: 1, .. })
        ));
    }
}
