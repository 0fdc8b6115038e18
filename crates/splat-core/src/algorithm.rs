//! Which renderer makes an image: the oracle, a ray-tracing estimator or a splatting estimator.
//! The one name that the CLI, the golden images and the GPU backend dispatch on.

use crate::camera::Camera;
use crate::frame::{Frames, Progress, RenderOutput};
use crate::lighting::Lighting;
use crate::mesh::Meshes;
use crate::oracle::render_oracle;
use crate::particle::Scene;
use crate::raster::{RasterMethod, RasterSettings, Rasterizer, render_raster};
use crate::settings::{RenderError, RenderSettings};
use crate::trace::{Method, TraceScene, render_frames};

/// A renderer of either family, with its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Algorithm {
    /// The brute-force oracle: every particle for every pixel, Eq. 3 ([`crate::oracle`]).
    Oracle,
    /// A ray-tracing method through the BVH ([`crate::trace`]).
    Trace(Method),
    /// A splatting method with its sample set ([`crate::raster`]).
    Raster(RasterMethod, RasterSettings),
    /// The hybrid pipeline (vk_gaussian_splatting Lighting §5): the splatting method gives the
    /// first hit, the ray tracer continues with shadow rays and mesh bounces traced by the
    /// ray-tracing method ([`Rasterizer::hybrid`]).
    Hybrid(RasterMethod, RasterSettings, Method),
}

impl Algorithm {
    /// Whether frames differ (the method draws random decisions).
    pub fn is_stochastic(&self) -> bool {
        match self {
            Algorithm::Oracle => false,
            Algorithm::Trace(m) => m.is_stochastic(),
            Algorithm::Raster(m, _) => m.is_stochastic(),
            Algorithm::Hybrid(m, _, secondary) => m.is_stochastic() || secondary.is_stochastic(),
        }
    }

    /// Render `frames` on the CPU (one frame for a deterministic method), unlit. `progress`
    /// receives finished pixel counts.
    pub fn render(
        &self,
        scene: &Scene,
        camera: &Camera,
        settings: &RenderSettings,
        frames: &Frames,
        progress: Progress,
    ) -> Result<RenderOutput, RenderError> {
        self.render_lit(scene, camera, settings, &Lighting::default(), frames, progress)
    }

    /// Render `frames` on the CPU lit by `lighting` ([`crate::lighting`]); with the default
    /// (emissive) lighting this is exactly [`Algorithm::render`]. The brute-force oracle renders
    /// radiance only: lit references are `exact` in each look.
    pub fn render_lit(
        &self,
        scene: &Scene,
        camera: &Camera,
        settings: &RenderSettings,
        lighting: &Lighting,
        frames: &Frames,
        progress: Progress,
    ) -> Result<RenderOutput, RenderError> {
        self.render_world(scene, &Meshes::none(), camera, settings, lighting, frames, progress)
    }

    /// Render `frames` on the CPU of the splats among `meshes` ([`crate::mesh`]), lit by
    /// `lighting`; without meshes this is exactly [`Algorithm::render_lit`].
    #[allow(clippy::too_many_arguments)]
    pub fn render_world(
        &self,
        scene: &Scene,
        meshes: &Meshes,
        camera: &Camera,
        settings: &RenderSettings,
        lighting: &Lighting,
        frames: &Frames,
        progress: Progress,
    ) -> Result<RenderOutput, RenderError> {
        match self {
            Algorithm::Oracle if !meshes.is_empty() => Err(RenderError::Settings(
                "the brute-force oracle renders splats alone; render meshes with a ray-tracing method".into(),
            )),
            Algorithm::Oracle if lighting.is_on() => Err(RenderError::Settings(
                "the brute-force oracle renders unlit radiance; render lit references with the exact method".into(),
            )),
            Algorithm::Oracle => render_oracle(scene, camera, settings, progress),
            Algorithm::Trace(method) => {
                let trace =
                    TraceScene::new(scene, *settings)?.with_lighting(lighting.clone())?.with_meshes(meshes.clone());
                render_frames(&trace, camera, method, frames, progress)
            }
            Algorithm::Raster(method, raster) => {
                let r = Rasterizer::new(scene, camera, *settings, *raster)?
                    .with_lighting(lighting.clone())?
                    .with_meshes(meshes.clone());
                render_raster(&r, method, frames, progress)
            }
            Algorithm::Hybrid(method, raster, secondary) => {
                let trace =
                    TraceScene::new(scene, *settings)?.with_lighting(lighting.clone())?.with_meshes(meshes.clone());
                let r = Rasterizer::new(scene, camera, *settings, *raster)?.hybrid(&trace, *secondary)?;
                render_raster(&r, method, frames, progress)
            }
        }
    }
}
