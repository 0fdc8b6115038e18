//! The oracle: for every pixel, every hit along its ray, sorted and composited by Eq. 3 of Sun
//! et al. in f64, with no BVH and no randomness. Every other renderer is tested against it
//! (directly, or through `exact`, which a test proves equal to it). Particles are binned into
//! screen tiles by the projection of their bounding boxes, a conservative cull that changes no
//! result (a test checks it against the brute-force [`oracle_ray`]).

use crate::camera::Camera;
use crate::camera_sampling::frame_sample;
use crate::composite::{Composite, ShadedHit, composite, shade_hit, sort_front_to_back};
use crate::frame::{
    AccumulationFormat, Frames, PixelFrames, Progress, RenderOutput, Sample, fold_frames, render_tiles,
};
use crate::hit::{PreparedParticle, Ray, intersect};
use crate::particle::Scene;
use crate::settings::{RenderError, RenderSettings, validate_scene};
use crate::tile::TILE;
use glam::Vec2;

/// The brute-force oracle of a scene: the prepared particles beside the scene they came from.
pub struct Oracle<'a> {
    scene: &'a Scene,
    prepared: Vec<PreparedParticle>,
    settings: RenderSettings,
}

impl<'a> Oracle<'a> {
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

impl Oracle<'_> {
    /// Auto-focus (vk_gaussian_splatting Lighting §1.5: the picked surface sets the plane in
    /// focus): the depth along `camera`'s axis of the iso-opacity hit of the ray through the
    /// centre of pixel (x, y), every particle tested; `None` where the ray's transmittance
    /// never falls to the iso threshold.
    pub fn focus_distance(&self, camera: &Camera, x: u32, y: u32) -> Option<f32> {
        let ray = self.clip(camera.pixel_ray(x, y));
        let c = self.trace(&ray, 0..self.prepared.len() as u32, &mut Vec::new());
        c.depth.map(|t| t * ray.dir.dot(camera.forward()))
    }
}

/// The oracle for one ray: every particle of the scene tested by brute force, hits sorted
/// front to back and composited by Eq. 3 in f64. The ray's own range is replaced by the
/// settings' (t_min, t_max).
pub fn oracle_ray(scene: &Scene, ray: Ray, settings: &RenderSettings) -> Result<Composite, RenderError> {
    let oracle = Oracle::new(scene, *settings)?;
    let n = oracle.len() as u32;
    Ok(oracle.trace(&oracle.clip(ray), 0..n, &mut Vec::new()))
}

/// Render every pixel with the oracle: through pixel centres and a pinhole, one frame,
/// variance 0; under a camera drawn per frame (the settings' [`crate::camera_sampling`]),
/// `frames.count` frames through each frame's camera (the filtered oracle: exact for the very
/// frames a stochastic render of the same seed draws). `progress` is called with the number of
/// pixels finished since its last call.
pub fn render_oracle(
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    frames: &Frames,
    progress: Progress,
) -> Result<RenderOutput, RenderError> {
    camera.validate()?;
    camera.require_pinhole("the oracle (its tile culling)")?;
    let oracle = Oracle::new(scene, *settings)?;
    let sampling = settings.sampling;
    if !sampling.is_random() {
        return Ok(oracle_frame(&oracle, scene, camera, progress));
    }
    let keys = frames.keys(true)?;
    fold_frames(camera, &keys, frames.accumulation, progress, |f, _| {
        let frame_camera = sampling.pinhole(camera, &frame_sample(frames.seed, frames.index(f)))?;
        Ok(oracle_frame(&oracle, scene, &frame_camera, &|_| {}))
    })
}

/// One frame of the oracle through a pinhole `camera`, every pixel through its centre.
fn oracle_frame(oracle: &Oracle, scene: &Scene, camera: &Camera, progress: Progress) -> RenderOutput {
    let settings = oracle.settings();
    let bins = TileBins::new(scene, camera, settings.kernel.cutoff);
    let tile_state = |tile| (bins.candidates(tile), Vec::new());
    render_tiles(camera, progress, tile_state, |(candidates, scratch), x, y| {
        let ray = oracle.clip(camera.pixel_ray(x, y));
        let c = oracle.trace(&ray, candidates.iter().copied(), scratch);
        let sample = Sample {
            color: c.color_over(settings.background),
            alpha: c.alpha(),
            depth: c.depth,
            normal: c.unit_normal(ray.dir),
            picked: None,
        };
        PixelFrames::over(&[0], AccumulationFormat::F32, |_| sample)
    })
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
    use glam::Vec3;

    /// Every pixel of the tiled render against the brute-force trace over all particles,
    /// from outside the cloud and from inside it (boxes behind and around the camera).
    #[test]
    fn tiled_render_equals_brute_force_oracle() {
        let (scene, camera) = scenes::cloud();
        let inside =
            Camera::look_at(Vec3::new(0.1, 0.0, 0.3), Vec3::new(0.0, 0.0, -1.0), Vec3::Y, 70.0, 40, 30).unwrap();
        let settings = RenderSettings { background: Vec3::new(0.1, 0.2, 0.3), ..Default::default() };
        let oracle = Oracle::new(&scene, settings).unwrap();
        let all = 0..scene.particles.len() as u32;
        for camera in [camera.rescaled(40, 30).unwrap(), inside] {
            let out = render_oracle(&scene, &camera, &settings, &Frames::default(), &|_| {}).unwrap();
            for y in 0..camera.height {
                for x in 0..camera.width {
                    let ray = oracle.clip(camera.pixel_ray(x, y));
                    let rgb = oracle.trace(&ray, all.clone(), &mut Vec::new()).color_over(settings.background);
                    for k in 0..3 {
                        assert_relative_eq!(out.mean.pixel(x, y)[k], rgb[k] as f32, epsilon = 1e-6);
                    }
                }
            }
        }
    }

    #[test]
    fn invalid_settings_are_refused() {
        let (scene, camera) = scenes::layers();
        let bad = RenderSettings { iso_threshold: 2.0, ..Default::default() };
        assert!(matches!(
            render_oracle(&scene, &camera, &bad, &Frames::default(), &|_| {}),
            Err(RenderError::Settings(_))
        ));
        let mut broken = scene.clone();
        broken.particles[1].scale.y = 0.0;
        assert!(matches!(
            render_oracle(&broken, &camera, &RenderSettings::default(), &Frames::default(), &|_| {}),
            Err(RenderError::Particle { index: 1, .. })
        ));
    }

    #[test]
    fn auto_focus_is_the_picked_depth_along_the_axis() {
        let (scene, camera) = scenes::layers();
        let settings = RenderSettings::default();
        let out = render_oracle(&scene, &camera, &settings, &Frames::default(), &|_| {}).unwrap();
        let oracle = Oracle::new(&scene, settings).unwrap();
        let mut focused = 0;
        for (x, y) in [(80, 60), (30, 40), (120, 90), (0, 0)] {
            let t = out.depth.pixel(x, y)[0];
            let cos = camera.pixel_ray(x, y).dir.dot(camera.forward());
            match oracle.focus_distance(&camera, x, y) {
                Some(d) => {
                    assert!((d - t * cos).abs() < 1e-5, "({x}, {y}): focus {d}, depth {t} × cos {cos}");
                    focused += 1;
                }
                None => assert!(t.is_nan(), "({x}, {y}) shows a surface at {t} but has no focus"),
            }
        }
        assert!(focused >= 2, "the layers' centre pixels show a surface");
    }
}
