//! Which renderer makes an image: the oracle, a ray-tracing estimator or a splatting estimator.
//! The one name that the CLI, the golden images and the GPU backend dispatch on.

use crate::camera::Camera;
use crate::camera_sampling::CameraSampling;
use crate::frame::{Frames, Progress, RenderOutput};
use crate::lighting::Lighting;
use crate::mesh::Meshes;
use crate::oracle::render_oracle;
use crate::particle::Scene;
use crate::raster::{RasterMethod, RasterSettings, Rasterizer, render_raster, render_raster_frames};
use crate::settings::{RenderError, RenderSettings};
use crate::trace::{Method, TraceScene, render_frames};

/// What renders: the splats, the meshes among them and their lighting, checked against one
/// another. The one world type of every front end (the CLI's and the viewer's); a file's
/// description of a world is `splat_io::world::WorldSpec`.
#[derive(Clone, Debug)]
pub struct World {
    /// The splats of every set, in one id space.
    pub scene: Scene,
    /// The meshes among them, with their BVH ([`Meshes::none`] for none).
    pub meshes: Meshes,
    /// Materials per splat set, lights, shadows and look ([`Lighting::default`]: emissive).
    pub lighting: Lighting,
}

impl World {
    /// A world of these parts, refused where the lighting names sets the scene does not hold.
    pub fn new(scene: Scene, meshes: Meshes, lighting: Lighting) -> Result<Self, RenderError> {
        lighting.validate(scene.particles.len()).map_err(RenderError::Settings)?;
        Ok(Self { scene, meshes, lighting })
    }

    /// One render of this world through `camera` with `settings`.
    pub fn shot<'a>(&'a self, camera: &'a Camera, settings: &'a RenderSettings) -> Shot<'a> {
        Shot { scene: &self.scene, meshes: &self.meshes, lighting: &self.lighting, camera, settings }
    }
}

/// One render's inputs: the splats and the meshes among them, their lighting, the camera and
/// the settings. What both backends read: [`Algorithm::render_world`] on the CPU,
/// `splat_gpu::render` on the GPU.
#[derive(Clone, Copy)]
pub struct Shot<'a> {
    /// The splats.
    pub scene: &'a Scene,
    /// The meshes among them ([`Meshes::none`] for none).
    pub meshes: &'a Meshes,
    /// Materials, lights, shadows and look ([`Lighting::default`]: emissive).
    pub lighting: &'a Lighting,
    /// The camera.
    pub camera: &'a Camera,
    /// Kernel, hit distance, normals, background, bounce limit.
    pub settings: &'a RenderSettings,
}

/// One world's renderer through any camera ([`Algorithm::render_views`]): `render(camera,
/// frames, progress)`.
pub type ViewRenderer<'a> = dyn Fn(&Camera, &Frames, Progress) -> Result<RenderOutput, RenderError> + 'a;

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

    /// Whether frames differ with this `lighting` and, where `meshes`, meshes, and this camera
    /// `sampling`: a stochastic method, a traced sample whose lighting draws (stochastic
    /// shadows, area lights; [`Lighting::draws_for`]; rasterized splats cast no shadow rays),
    /// or a camera drawn per frame.
    pub fn is_random(&self, lighting: &Lighting, meshes: bool, sampling: &CameraSampling) -> bool {
        sampling.is_random()
            || match self {
                Algorithm::Raster(m, _) => m.is_stochastic(),
                Algorithm::Oracle => false,
                _ => self.is_stochastic() || lighting.draws_for(meshes),
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
        let meshes = Meshes::none();
        self.render_world(&Shot { scene, meshes: &meshes, lighting, camera, settings }, frames, progress)
    }

    /// Render `frames` on the CPU of the splats among the shot's meshes ([`crate::mesh`]), lit
    /// by its lighting; without meshes this is exactly [`Algorithm::render_lit`].
    pub fn render_world(&self, shot: &Shot, frames: &Frames, progress: Progress) -> Result<RenderOutput, RenderError> {
        self.render_views(shot, |render| render(shot.camera, frames, progress))?
    }

    /// The world of `shot` (its camera aside) rendered from many cameras: `views` gets a
    /// renderer, `render(camera, frames, progress)` = [`Algorithm::render_world`] through that
    /// camera, and what does not depend on the camera (the ray-tracing algorithms' BVH) is built
    /// once for all of them (`splat render --all-cameras`).
    pub fn render_views<R>(&self, shot: &Shot, views: impl FnOnce(&ViewRenderer) -> R) -> Result<R, RenderError> {
        let Shot { scene, meshes, lighting, settings, .. } = *shot;
        Ok(match self {
            Algorithm::Oracle => views(&|camera, frames, progress| oracle(&Shot { camera, ..*shot }, frames, progress)),
            Algorithm::Trace(_) | Algorithm::Hybrid(..) => {
                let trace = TraceScene::new(scene, *settings)?.with_lighting(lighting)?.with_meshes(meshes);
                views(&|camera, frames, progress| self.render_on(&trace, camera, frames, progress))
            }
            Algorithm::Raster(method, raster) => views(&|camera, frames, progress| {
                let build = |camera: &Camera| {
                    Ok(Rasterizer::new(scene, camera, *settings, *raster)?.with_lighting(lighting)?.with_meshes(meshes))
                };
                render_raster_frames(camera, &settings.sampling, method, frames, progress, build)
            }),
        })
    }

    /// Render `frames` on the CPU of the scene, settings, lighting and meshes of `trace`, whose
    /// BVH a caller that renders many times (a viewer, frame after frame) builds once. The same
    /// image as [`Algorithm::render_world`] of the same world.
    pub fn render_on(
        &self,
        trace: &TraceScene,
        camera: &Camera,
        frames: &Frames,
        progress: Progress,
    ) -> Result<RenderOutput, RenderError> {
        self.prepare(trace, camera)?.render(frames, progress)
    }

    /// This algorithm set up for one view of `trace` through `camera`: what does not change
    /// from frame to frame while the camera holds still (a splatting method's projected,
    /// depth-sorted and binned splats) is built once, here, and each
    /// [`PreparedView::render`] draws frames of it.
    pub fn prepare<'a>(&self, trace: &'a TraceScene<'a>, camera: &Camera) -> Result<PreparedView<'a>, RenderError> {
        let prepared = match *self {
            Algorithm::Oracle => Prepared::Oracle,
            Algorithm::Trace(method) => Prepared::Trace(method),
            Algorithm::Raster(method, _) | Algorithm::Hybrid(method, ..) if trace.settings().sampling.is_random() => {
                Prepared::MovingRaster(*self, method)
            }
            Algorithm::Raster(method, _) | Algorithm::Hybrid(method, ..) => {
                Prepared::Raster(Box::new(self.rasterizer(trace, camera)?), method)
            }
        };
        Ok(PreparedView { trace, camera: *camera, prepared })
    }

    /// The rasterizer of a splatting or hybrid algorithm for one view of `trace` (its splats
    /// projected through `camera`); an error for the others.
    fn rasterizer<'a>(&self, trace: &'a TraceScene<'a>, camera: &Camera) -> Result<Rasterizer<'a>, RenderError> {
        let (scene, settings) = (trace.scene(), *trace.settings());
        match *self {
            Algorithm::Raster(_, raster) => Ok(Rasterizer::new(scene, camera, settings, raster)?
                .with_lighting(trace.lighting())?
                .with_meshes(trace.meshes())),
            Algorithm::Hybrid(_, raster, secondary) => {
                Rasterizer::new(scene, camera, settings, raster)?.hybrid(trace, secondary)
            }
            Algorithm::Oracle | Algorithm::Trace(_) => {
                Err(RenderError::Settings(format!("{self:?} does not rasterize")))
            }
        }
    }
}

/// An [`Algorithm`] set up for one view of a kept [`TraceScene`] ([`Algorithm::prepare`]).
pub struct PreparedView<'a> {
    trace: &'a TraceScene<'a>,
    camera: Camera,
    prepared: Prepared<'a>,
}

/// What each family keeps between frames of one view.
enum Prepared<'a> {
    Oracle,
    Trace(Method),
    Raster(Box<Rasterizer<'a>>, RasterMethod),
    /// Splatting through a camera drawn per frame: a rasterizer per frame.
    MovingRaster(Algorithm, RasterMethod),
}

impl PreparedView<'_> {
    /// Render `frames` of the view on the CPU; the same image as [`Algorithm::render_on`].
    pub fn render(&self, frames: &Frames, progress: Progress) -> Result<RenderOutput, RenderError> {
        let (trace, camera) = (self.trace, &self.camera);
        match &self.prepared {
            Prepared::Oracle => oracle(&trace.shot(camera), frames, progress),
            Prepared::Trace(method) => render_frames(trace, camera, method, frames, progress),
            Prepared::Raster(r, method) => render_raster(r, method, frames, progress),
            Prepared::MovingRaster(algorithm, method) => {
                let sampling = &trace.settings().sampling;
                render_raster_frames(camera, sampling, method, frames, progress, |c| algorithm.rasterizer(trace, c))
            }
        }
    }
}

/// The brute-force oracle of the shot: splats alone, unlit (it refuses meshes and lights).
fn oracle(shot: &Shot, frames: &Frames, progress: Progress) -> Result<RenderOutput, RenderError> {
    if !shot.meshes.is_empty() {
        return Err(RenderError::Settings(
            "the brute-force oracle renders splats alone; render meshes with a ray-tracing method".into(),
        ));
    }
    if shot.lighting.is_on() {
        return Err(RenderError::Settings(
            "the brute-force oracle renders unlit radiance; render lit references with the exact method".into(),
        ));
    }
    render_oracle(shot.scene, shot.camera, shot.settings, frames, progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::Blend;

    #[test]
    fn rendering_on_a_kept_trace_scene_is_rendering_the_world() {
        let (scene, camera) = crate::scenes::cloud();
        let camera = camera.rescaled(24, 18).unwrap();
        let settings = RenderSettings::default();
        let trace = TraceScene::new(&scene, settings).unwrap();
        let frames = Frames { count: 3, ..Frames::default() };
        let raster = RasterSettings::default();
        for algorithm in [
            Algorithm::Trace(Method::Stochastic),
            Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Over }, raster),
            Algorithm::Raster(RasterMethod::StochasticSplat, raster),
            Algorithm::Hybrid(RasterMethod::StochasticSplat, raster, Method::Stochastic),
        ] {
            let kept = algorithm.render_on(&trace, &camera, &frames, &|_| {}).unwrap();
            let world = algorithm.render(&scene, &camera, &settings, &frames, &|_| {}).unwrap();
            assert!(same(&kept, &world), "{algorithm:?}");
            // A prepared view draws the same frames, one call after another, from one projection.
            let view = algorithm.prepare(&trace, &camera).unwrap();
            for seed in [1, 2] {
                let f = Frames { seed, ..frames };
                let again = algorithm.render_on(&trace, &camera, &f, &|_| {}).unwrap();
                assert!(same(&view.render(&f, &|_| {}).unwrap(), &again), "{algorithm:?} seed {seed}");
            }
        }
        // Another seed is another image: the comparison can fail.
        let other = Frames { seed: 1, ..frames };
        let a = Algorithm::Trace(Method::Stochastic);
        let (b, c) =
            (a.render_on(&trace, &camera, &other, &|_| {}), a.render(&scene, &camera, &settings, &frames, &|_| {}));
        assert!(!same(&b.unwrap(), &c.unwrap()));
    }

    /// Bit for bit the same images (NaN depths included) and picks.
    fn same(a: &RenderOutput, b: &RenderOutput) -> bool {
        let bits = |o: &RenderOutput| -> Vec<u32> {
            [&o.mean, &o.variance, &o.alpha, &o.depth, &o.normal]
                .iter()
                .flat_map(|i| i.data())
                .map(|v| v.to_bits())
                .collect()
        };
        bits(a) == bits(b) && a.picked == b.picked
    }
}
