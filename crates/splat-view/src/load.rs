//! What `splat view` opens: a scene file, a world file or the built-in demo, with the views
//! of a cameras.json or COLMAP model — read before any window opens, so that bad input is an
//! error on the terminal, not an empty window.

use anyhow::{Context, Result};
use splat_core::glam::Vec3;
use splat_core::mesh::Meshes;
use splat_core::particle::Aabb;
use splat_core::raster::{Response, SplatExtent};
use splat_core::trainer::{Preset, Trained};
use splat_core::{Camera, RenderSettings, World};
use splat_io::cameras::ViewOptions;
use std::path::Path;

/// A scene ready to view.
pub struct Loaded {
    /// What renders.
    pub world: World,
    /// What the window needs to know of it.
    pub info: SceneInfo,
}

/// What the window knows of the scene.
pub struct SceneInfo {
    /// The settings the file gives (background, bounce limit) on the defaults.
    pub render: RenderSettings,
    /// The file's own camera (a world's `[camera]`, the demo's).
    pub camera: Option<Camera>,
    /// Named views to step through.
    pub views: Vec<(String, Camera)>,
    /// The central part of the scene (2 % quantiles of the means).
    pub bounds: Aabb,
    /// The scene's name for the window.
    pub name: String,
    /// Particles.
    pub particles: usize,
    /// SH degree.
    pub sh_degree: u8,
    /// The capture's screen-space filter.
    pub screen_filter: splat_core::ScreenFilter,
    /// The splat extent and response its splats are drawn with until the panel changes them
    /// ([`splat_core::trainer::capture_splatting`]: its trainer's).
    pub splatting: (SplatExtent, Response),
}

/// Read `scene` (`.ply`, compressed `.ply`, `.splat`, `.spz`, a world `.toml`, or the demo
/// when `None`) with the reader's `options`, and the views of `cameras` as `views` change them;
/// where `cameras` says so, moved into the gsplat world of the scene's splats
/// ([`splat_io::gsplat_world`]). A `preset` replaces the renderer the capture was trained
/// through ([`Trained::instead`]), so that the window starts with that renderer's settings.
pub fn load(
    scene: Option<&Path>,
    cameras: Option<(&Path, bool)>,
    views: splat_io::cameras::ViewOptions,
    options: splat_io::ReadOptions,
    preset: Option<Preset>,
) -> Result<Loaded> {
    let mut opened = splat_io::world::open_world(scene, options)?;
    if let Some(preset) = preset {
        opened.world.scene.trained = Some(Trained::instead(opened.world.scene.trained, preset));
    }
    if let Some(path) = scene {
        if let Some(warning) = splat_io::skipped_properties_warning(path, &opened.skipped_properties) {
            eprintln!("warning: {warning}");
        }
        for note in &opened.notes {
            eprintln!("note: {}", splat_io::file_note(path, note));
        }
    }
    let (world, name) = (opened.world, opened.name);
    let views = match cameras {
        Some((path, gsplat_world)) => {
            let views = ViewOptions { gsplat_world: gsplat_world.then_some(&world.scene), ..views };
            splat_io::cameras::read_views_in(path, views)?
        }
        None => Vec::new(),
    };
    let cameras = cameras.map(|(path, _)| path);
    if cameras.is_some() && views.is_empty() {
        anyhow::bail!("{}: no cameras", cameras.unwrap_or(Path::new("")).display());
    }
    let render = world.settings(RenderSettings::default());
    let splat_io::world::WorldSpec { scene, lighting, camera, meshes, .. } = world;
    let meshes = Meshes::new(&meshes).map_err(|e| anyhow::anyhow!("{e}")).context("the world's meshes")?;
    let bounds = scene.robust_bounds(0.02);
    let (particles, sh_degree, screen_filter) = (scene.particles.len(), scene.sh_degree, scene.screen_filter);
    let splatting = splat_core::trainer::capture_splatting(&scene);
    let info = SceneInfo { render, camera, views, bounds, name, particles, sh_degree, screen_filter, splatting };
    Ok(Loaded { world: World::new(scene, meshes, lighting)?, info })
}

impl SceneInfo {
    /// Centre and radius of the central part of the scene.
    pub fn sphere(&self) -> (Vec3, f32) {
        if self.bounds.is_empty() || !self.bounds.min.is_finite() || !self.bounds.max.is_finite() {
            return (Vec3::ZERO, 1.0);
        }
        (self.bounds.center(), (0.5 * (self.bounds.max - self.bounds.min).length()).max(1e-3))
    }
}
