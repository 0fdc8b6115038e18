//! `splat-core`: the pure-Rust oracle for rendering transparent 3D Gaussians.
//!
//! Everything here is math: particles and their covariance ([`particle`]), the ray–particle
//! response ([`kernel`], [`hit`]), view-dependent colour ([`sh`]), cameras ([`camera`]), the
//! exact sorted compositing of Eq. 3 of Sun et al. ([`composite`]), normals and iso-opacity depth
//! (seed 003, [`normal`], [`composite`]), the stochastic binary-opacity estimator of Eqs. 4–6
//! ([`estimator`]) and a brute-force exact renderer ([`render`]). No I/O, no GPU.
//!
//! ```
//! use splat_core::{camera::Camera, render::{render_exact, RenderSettings}, scenes};
//! let (scene, camera) = scenes::layers();
//! let camera = camera.rescaled(32, 24).unwrap();
//! let out = render_exact(&scene, &camera, &RenderSettings::default(), &|_| {}).unwrap();
//! assert_eq!(out.radiance.width(), 32);
//! ```

pub mod bvh;
pub mod camera;
pub mod composite;
pub mod estimator;
pub mod hit;
pub mod image;
pub mod kernel;
pub mod normal;
pub mod particle;
pub mod raster;
pub mod render;
pub mod rng;
pub mod scenes;
pub mod sh;
pub mod stats;
pub mod trace;

pub use camera::Camera;
pub use hit::{HitDistance, Ray};
pub use image::Image;
pub use kernel::KernelParams;
pub use particle::{Particle, ParticleError, Scene};
pub use render::{RenderOutput, RenderSettings, render_exact};
