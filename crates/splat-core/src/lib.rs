//! `splat-core`: the pure-Rust oracle for rendering transparent 3D Gaussians.
//!
//! Everything here is math, in layers (docs/architecture.md):
//!
//! - the particle and its response: [`particle`], [`kernel`], [`hit`], [`sh`], [`normal`],
//!   [`camera`] with each frame's [`camera_sampling`] (pixel filter, thin lens), and the
//!   screen-space [`filter`] of a capture;
//! - exact compositing, Eq. 3 of Sun et al. ([`composite`]) and the stochastic estimator of
//!   Eqs. 4–6 with its exact expectations ([`estimator`]);
//! - the floor every renderer stands on: [`settings`] and errors, screen [`tile`]s, and the
//!   [`frame`] loop with its one output type, [`RenderOutput`];
//! - three siblings on that floor: the brute-force [`oracle`], the ray-tracing estimators
//!   ([`trace`], through the [`bvh`]) and the splatting estimators ([`raster`]), named together
//!   by [`Algorithm`], each method declared once in the [`catalogue`];
//! - a Monte Carlo [`path`] tracer in which Gaussians sit beside meshes;
//! - decisions ([`rng`]), statistics ([`stats`]) and built-in scenes ([`scenes`]);
//! - each trainer's conventions as a [`trainer::Preset`].
//!
//! No I/O, no GPU.
//!
//! ```
//! use splat_core::{Algorithm, RenderSettings, frame::Frames, scenes};
//! let (scene, camera) = scenes::layers();
//! let camera = camera.rescaled(32, 24).unwrap();
//! let out = Algorithm::Oracle.render(&scene, &camera, &RenderSettings::default(), &Frames::default(), &|_| {}).unwrap();
//! assert_eq!(out.mean.width(), 32);
//! ```

pub mod algorithm;
pub mod bvh;
pub mod camera;
pub mod camera_sampling;
pub mod catalogue;
pub mod composite;
pub mod estimator;
pub mod filter;
pub mod frame;
pub mod hit;
pub mod host;
pub mod image;
pub mod kernel;
pub mod lens;
pub mod lighting;
pub mod lk_scenes;
pub mod mesh;
pub mod normal;
pub mod oracle;
pub mod par;
pub mod particle;
pub mod path;
pub mod raster;
pub mod rng;
pub mod scenes;
pub mod settings;
pub mod sh;
pub mod ssim;
pub mod stats;
pub mod tile;
pub mod trace;
pub mod trainer;
pub mod undistort;

/// The vector math of the public API (`Vec3`, `Quat`, `Mat3`), re-exported so that users need
/// not match its version.
pub use glam;

pub use algorithm::{Algorithm, Shot, ViewRenderer, World};
pub use camera::Camera;
pub use catalogue::{MethodId, Parameters};
pub use filter::ScreenFilter;
pub use frame::{Frames, RenderOutput};
pub use hit::{HitDistance, Ray};
pub use image::Image;
pub use kernel::KernelParams;
pub use oracle::render_oracle;
pub use particle::{Particle, ParticleError, Scene, Sh};
pub use settings::{RenderError, RenderSettings};
