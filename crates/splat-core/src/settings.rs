//! What every renderer of the crate shares besides the scene and camera: the settings that
//! decide an image ([`RenderSettings`]) and why a render cannot start ([`RenderError`]).

use crate::camera::CameraError;
use crate::camera_sampling::CameraSampling;
use crate::composite::DEFAULT_ISO_THRESHOLD;
use crate::hit::{DEFAULT_T_MAX, DEFAULT_T_MIN, HitDistance};
use crate::kernel::KernelParams;
use crate::normal::NormalMode;
use crate::particle::{ParticleError, Scene};
use glam::Vec3;
use thiserror::Error;

/// Everything that decides an image besides the scene, the camera and the method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Particle response.
    pub kernel: KernelParams,
    /// Hit distance convention (§4.1).
    pub hit_distance: HitDistance,
    /// Per-particle normal (vk_gaussian_splatting Lighting §2.4).
    pub normal_mode: NormalMode,
    /// Colour behind the particles.
    pub background: Vec3,
    /// Iso-opacity depth threshold on transmittance of the ray tracers (vk_gaussian_splatting
    /// Lighting §1.1: the ray tracing panel's Depth Iso Threshold).
    pub iso_threshold: f32,
    /// The same threshold of splatting: a separate value, "since the two rendering approaches
    /// may lead to different per-particle hit distances" (§1.1; the rasterization panel's).
    pub raster_iso_threshold: f32,
    /// Splatting's near plane: a particle whose centre is nearer along the view axis (through
    /// another lens, nearer the camera) is culled. 3DGS's `in_frustum` takes 0.2
    /// ([`crate::raster::project::NEAR`], the default), gsplat its `near_plane` 0.01
    /// ([`crate::trainer::Preset::near`]).
    pub near: f32,
    /// Ray start t_min.
    pub t_min: f32,
    /// Ray end t_max.
    pub t_max: f32,
    /// Most mirror and glass bounces after the camera ray ([`crate::mesh`]); a ray that would
    /// bounce once more takes black.
    pub max_bounces: u32,
    /// Where each frame's camera rays pass through the pixel and the lens (a box filter, depth
    /// of field); the pixel centre and a pinhole by default.
    pub sampling: CameraSampling,
    /// How the SH coefficients are stored (f32, or f16: half the GPU's SH memory).
    pub sh_storage: crate::sh::ShStorage,
}

/// Default bounce limit (the title figure of the vk_gaussian_splatting lighting documentation
/// shows 3 reflection and refraction bounces).
pub const DEFAULT_MAX_BOUNCES: u32 = 3;
/// Largest bounce limit (the bounce number is packed into decision slots, [`crate::trace`]).
pub const MAX_BOUNCES: u32 = 15;

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            kernel: KernelParams::default(),
            hit_distance: HitDistance::Mean,
            normal_mode: NormalMode::MaxDensityPlane,
            background: Vec3::ZERO,
            iso_threshold: DEFAULT_ISO_THRESHOLD,
            raster_iso_threshold: DEFAULT_ISO_THRESHOLD,
            near: crate::raster::project::NEAR,
            t_min: DEFAULT_T_MIN,
            t_max: DEFAULT_T_MAX,
            max_bounces: DEFAULT_MAX_BOUNCES,
            sampling: CameraSampling::default(),
            sh_storage: crate::sh::ShStorage::F32,
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
        if !(self.near.is_finite() && self.near > 0.0) {
            return Err(RenderError::Settings(format!("near plane {} must be a positive distance", self.near)));
        }
        if !(0.0..=1.0).contains(&self.raster_iso_threshold) {
            return Err(RenderError::Settings(format!(
                "raster iso threshold {} is outside [0, 1]",
                self.raster_iso_threshold
            )));
        }
        if !(self.t_min.is_finite() && self.t_min >= 0.0 && self.t_max > self.t_min) {
            return Err(RenderError::Settings(format!(
                "ray range ({}, {}) is empty or invalid",
                self.t_min, self.t_max
            )));
        }
        if self.max_bounces > MAX_BOUNCES {
            return Err(RenderError::Settings(format!(
                "{} bounces is more than the {MAX_BOUNCES} supported",
                self.max_bounces
            )));
        }
        self.sampling.validate()
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
