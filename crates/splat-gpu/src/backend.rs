//! The GPU backend's entry point: whether it renders an [`Algorithm`] of a [`Shot`]
//! ([`supports`]) and the render itself ([`render`]), so that a host renders a world on the GPU
//! as it does on the CPU ([`Algorithm::render_world`]) without knowing which kernels run. The
//! refusals carry their [`Remedy`]; each front end words them.

use crate::{GpuContext, GpuError, GpuRasterizer, GpuTracer, RasterPipelines, RasterScene, Remedy, TracePipeline};
use splat_core::frame::{Frames, RenderOutput};
use splat_core::raster::RasterMethod;
use splat_core::trace::TraceScene;
use splat_core::{Algorithm, Shot};

/// The images a render is asked for besides colour, alpha and variance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Extras {
    /// The depth image.
    pub depth: bool,
    /// The normal image.
    pub normal: bool,
}

/// Whether the GPU renders `algorithm` with `extras`, before anything is uploaded: the
/// kernels' own rules ([`GpuTracer::supports`], [`GpuRasterizer::supports`]) and what the
/// backend composes from them.
pub fn supports(algorithm: &Algorithm, extras: Extras) -> Result<(), GpuError> {
    match algorithm {
        Algorithm::Oracle => Err(oracle_refused()),
        Algorithm::Hybrid(method, raster, secondary) => {
            GpuRasterizer::supports(method, raster)?;
            GpuRasterizer::supports_first_hits(raster)?;
            GpuTracer::supports(secondary)
        }
        Algorithm::Trace(method) => GpuTracer::supports(method),
        Algorithm::Raster(method, raster) => {
            GpuRasterizer::supports(method, raster)?;
            let sorted = matches!(method, RasterMethod::Sorted { .. });
            if (extras.depth || extras.normal) && !sorted {
                return Err(GpuError::refused(
                    "on the GPU, depth and normal images come from raster-sorted only",
                    &[Remedy::Cpu],
                ));
            }
            Ok(())
        }
    }
}

/// Whether the GPU draws the world's `meshes` in `algorithm`, checked before anything is
/// uploaded: opaque meshes in every pipeline, transparent triangles (an opacity below 1) in the
/// ray tracer and the raster operations of Enderton and Laine–Karras (sorted splatting and
/// StochasticSplats blend or depth-test splats only, the hybrid draws every triangle as an
/// opaque surface).
pub fn supports_meshes(algorithm: &Algorithm, meshes: &splat_core::mesh::Meshes) -> Result<(), GpuError> {
    let what = match algorithm {
        Algorithm::Raster(RasterMethod::Enderton | RasterMethod::Stratified { .. }, _)
        | Algorithm::Trace(_)
        | Algorithm::Oracle => return Ok(()),
        Algorithm::Raster(method, _) => format!("{} on the GPU", method.id().name()),
        Algorithm::Hybrid(..) => "the GPU hybrid".to_string(),
    };
    crate::layout::check_opaque(meshes, &what)
}

/// Render `frames` of `algorithm` of `shot` on `ctx` (what [`supports`] accepts): the tracer for
/// ray-tracing methods, lit or not; the rasterizer for splatting methods, with its compute tile
/// rasterizer's depth pick where `extras` asks for depth or normals; both for the hybrid.
pub fn render(
    ctx: &GpuContext,
    algorithm: &Algorithm,
    shot: &Shot,
    extras: Extras,
    frames: &Frames,
) -> Result<RenderOutput, GpuError> {
    render_views(ctx, algorithm, shot, extras, |render| render(shot.camera, frames))?
}

/// One world's GPU renderer through any camera ([`render_views`]): `render(camera, frames)`.
pub type GpuViewRenderer<'a> = dyn Fn(&splat_core::Camera, &Frames) -> Result<RenderOutput, GpuError> + 'a;

/// The world of `shot` (its camera aside) rendered on `ctx` from many cameras: `views` gets a
/// renderer, `render(camera, frames)` = [`render`] through that camera, and what does not
/// depend on the camera (the BVH, the scene's device arrays, the compiled pipelines) is built
/// and uploaded once for all of them (`splat render --all-cameras --backend gpu`).
pub fn render_views<R>(
    ctx: &GpuContext,
    algorithm: &Algorithm,
    shot: &Shot,
    extras: Extras,
    views: impl FnOnce(&GpuViewRenderer) -> R,
) -> Result<R, GpuError> {
    supports(algorithm, extras)?;
    supports_meshes(algorithm, shot.meshes)?;
    let Shot { scene, meshes, lighting, settings, .. } = *shot;
    let trace = || -> Result<TraceScene, GpuError> {
        // A scene the GPU cannot bind is refused before its BVH is built.
        crate::TraceSplit::at_least(ctx, scene, settings)?;
        Ok(TraceScene::new(scene, *settings)?.with_lighting(lighting)?.with_meshes(meshes))
    };
    let raster_scene = || -> Result<RasterScene, GpuError> {
        RasterScene::new_lit(ctx, scene, settings, lighting)?.with_meshes(ctx, meshes)
    };
    Ok(match algorithm {
        Algorithm::Trace(method) => {
            let trace = trace()?;
            let pipeline = TracePipeline::new(ctx)?;
            let tracer = GpuTracer::new(ctx, &pipeline, &trace)?;
            views(&|camera, frames| Ok(tracer.render(camera, method, frames)?.0))
        }
        Algorithm::Hybrid(first, raster_settings, secondary) => {
            let trace = trace()?;
            let pipeline = TracePipeline::new(ctx)?;
            let tracer = GpuTracer::new(ctx, &pipeline, &trace)?;
            let pipes = RasterPipelines::new(ctx)?;
            let gpu_scene = raster_scene()?;
            let raster = |c: &splat_core::Camera| GpuRasterizer::new(ctx, &pipes, &gpu_scene, c, raster_settings);
            views(&|camera, frames| Ok(tracer.render_hybrid(&raster, camera, first, secondary, frames)?.0))
        }
        Algorithm::Raster(method, raster_settings) if settings.sampling.is_random() => {
            let pipes = RasterPipelines::new(ctx)?;
            let gpu_scene = raster_scene()?;
            views(&|camera, frames| {
                // A camera drawn per frame (splat_core::camera_sampling): each frame projected
                // through its own pinhole camera, folded as the CPU folds them.
                let keys = frames.keys(true)?;
                let one = Frames { accumulation: splat_core::frame::AccumulationFormat::F32, ..*frames };
                splat_core::frame::fold_frames(camera, &keys, frames.accumulation, &|_| {}, |f, key| {
                    let sample = splat_core::camera_sampling::frame_sample(frames.seed, frames.index(f));
                    let frame_camera = settings.sampling.pinhole(camera, &sample)?;
                    let raster = GpuRasterizer::new(ctx, &pipes, &gpu_scene, &frame_camera, raster_settings)?;
                    let mut out = raster.render_keys(method, &[key], &one)?.0;
                    // Frame 0's depth and normal, as every render keeps them.
                    if f == 0 {
                        picked_extras(&raster, &gpu_scene, method, extras, &mut out)?;
                    }
                    Ok(out)
                })
            })
        }
        Algorithm::Raster(method, raster_settings) => {
            let pipes = RasterPipelines::new(ctx)?;
            let gpu_scene = raster_scene()?;
            views(&|camera, frames| {
                let raster = GpuRasterizer::new(ctx, &pipes, &gpu_scene, camera, raster_settings)?;
                let mut out = raster.render(method, frames)?.0;
                picked_extras(&raster, &gpu_scene, method, extras, &mut out)?;
                Ok(out)
            })
        }
        Algorithm::Oracle => return Err(oracle_refused()),
    })
}

/// The depth and normal images `extras` asks for, from the compute tile rasterizer's depth
/// pick, unless the frame drew them already (lit sorted splatting runs on the tile rasterizer,
/// depth and normal included).
fn picked_extras(
    raster: &GpuRasterizer,
    gpu_scene: &RasterScene,
    method: &RasterMethod,
    extras: Extras,
    out: &mut RenderOutput,
) -> Result<(), GpuError> {
    let picked = gpu_scene.is_lit() && matches!(method, RasterMethod::Sorted { .. });
    if (extras.depth || extras.normal) && !picked {
        let pick = raster.depth_pick()?;
        out.depth = pick.depth_image();
        out.normal = pick.normal;
    }
    Ok(())
}

/// The brute-force oracle is the CPU's alone; the exact method renders the same image.
fn oracle_refused() -> GpuError {
    GpuError::refused(
        format!("the brute-force {} runs on the CPU only", splat_core::MethodId::Oracle.name()),
        &[Remedy::ExactMethod, Remedy::Cpu],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::catalogue::Family;
    use splat_core::raster::{RasterSettings, SamplePattern};
    use splat_core::{MethodId, Parameters};

    /// The backend takes exactly the catalogue's GPU methods (default parameters at the
    /// hardware's sample pattern, an unlit scene), and refuses the others with the CPU as the
    /// way out: the catalogue's `gpu` column cannot drift from the kernels' rules.
    #[test]
    fn the_gpu_runs_what_the_catalogue_says() {
        let standard = RasterSettings { sample_pattern: SamplePattern::Standard, ..RasterSettings::default() };
        let p = Parameters { raster: standard, ..Parameters::default() };
        for id in MethodId::ALL {
            let verdict = supports(&id.algorithm(&p), Extras::default());
            assert_eq!(verdict.is_ok(), id.entry().gpu, "{}: {verdict:?}", id.name());
            if let Err(e) = verdict {
                assert!(e.remedies().contains(&Remedy::Cpu), "{}: {e}", id.name());
            }
        }
        // The hybrid's secondary rays: every GPU ray-tracing method.
        let sorted = MethodId::RasterSorted.algorithm(&p);
        let Algorithm::Raster(first, raster) = sorted else { unreachable!() };
        for id in MethodId::of(Family::Trace) {
            let Algorithm::Trace(secondary) = id.algorithm(&p) else { unreachable!() };
            let verdict = supports(&Algorithm::Hybrid(first, raster, secondary), Extras::default());
            assert_eq!(verdict.is_ok(), id.entry().gpu, "hybrid with {}: {verdict:?}", id.name());
        }
    }
}
