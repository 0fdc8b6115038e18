//! Every choice of the side panel, and how it becomes an [`Algorithm`], [`RenderSettings`] and
//! [`Lighting`]. Kept apart from the window so that the mapping is tested without one.

use splat_core::RenderSettings;
use splat_core::algorithm::Algorithm;
use splat_core::catalogue::Family;
use splat_core::lighting::{Light, Lighting, Look, Material, Shadows};
use splat_core::raster::{RasterMethod, RasterSettings};
use splat_core::rng::RngScheme;
use splat_core::trace::Method;
use splat_core::{MethodId, Parameters};
#[cfg(test)]
use splat_gpu::DisplayMode;
use splat_gpu::{AccumulationFormat, DisplayTransform};

/// Which family renders (vk_gaussian_splatting's pipeline selector).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pipeline {
    /// Ray tracing through the BVH.
    RayTracing,
    /// Splatting.
    Raster,
    /// Splatting for the first hit, ray tracing after it (vk_gaussian_splatting Lighting §5).
    Hybrid,
}

impl Pipeline {
    /// Every pipeline, in menu order.
    pub const ALL: [Pipeline; 3] = [Pipeline::RayTracing, Pipeline::Raster, Pipeline::Hybrid];

    /// Its menu name.
    pub fn name(self) -> &'static str {
        match self {
            Pipeline::RayTracing => "ray tracing",
            Pipeline::Raster => "raster",
            Pipeline::Hybrid => "hybrid",
        }
    }
}

/// The looks of the menu.
pub const LOOKS: [Look; 2] = [Look::Surface, Look::Volumetric];

/// A look's menu name.
pub fn look_name(look: Look) -> &'static str {
    match look {
        Look::Surface => "surface",
        Look::Volumetric => "volumetric",
    }
}

/// The shadows of the menu (sorted shadows with vk_gaussian_splatting's defaults).
pub const SHADOWS: [Shadows; 4] = [Shadows::None, Shadows::SORTED, Shadows::Stochastic, Shadows::Exact];

/// Shadows' menu name.
pub fn shadows_name(shadows: Shadows) -> &'static str {
    match shadows {
        Shadows::None => "no shadows",
        Shadows::Sorted { .. } => "sorted shadows",
        Shadows::Stochastic => "stochastic shadows",
        Shadows::Exact => "exact shadows",
    }
}

/// Where frames are rendered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// The wgpu ray-tracing kernel, accumulating on the device.
    Gpu,
    /// The `splat-core` renderers on the CPU (rayon).
    Cpu,
}

/// Everything the side panel sets.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Which family renders.
    pub pipeline: Pipeline,
    /// The ray-tracing method (also the hybrid pipeline's secondary method): one of the
    /// catalogue's [`Family::Trace`] methods ([`Settings::trace_menu`]).
    pub trace: MethodId,
    /// The splatting method: one of the catalogue's [`Family::Raster`] methods.
    pub raster: MethodId,
    /// Every method parameter, kept while the user switches methods.
    pub params: Parameters,
    /// Generator of the decisions.
    pub rng: RngScheme,
    /// Seed of the frames.
    pub seed: u32,
    /// Storage of the running mean (on either backend).
    pub accumulation: AccumulationFormat,
    /// The scene's settings.
    pub render: RenderSettings,
    /// Integration of sorted methods under lighting.
    pub look: Look,
    /// Visibility of the lights.
    pub shadows: Shadows,
    /// The lights (the world's, as edited).
    pub lights: Vec<Light>,
    /// The material of each splat set (the world's, as edited).
    pub materials: Vec<Material>,
    /// What the view shows.
    pub display: DisplayTransform,
    /// Where frames are rendered.
    pub backend: Backend,
    /// Rendered pixels per window pixel (0.125 to 1).
    pub scale: f32,
    /// The accumulation stops after this many frames.
    pub max_frames: u32,
    /// Show the RMSE of the running mean against the exact image of the view.
    pub rmse: bool,
    /// Stop rendering (keep what is accumulated).
    pub paused: bool,
}

impl Settings {
    /// Algorithm 1 and StochasticSplats, with the catalogue's defaults of the parameters.
    pub fn new(render: RenderSettings, lighting: &Lighting, backend: Backend) -> Self {
        Self {
            pipeline: Pipeline::RayTracing,
            trace: MethodId::Stochastic,
            raster: MethodId::StochasticSplat,
            params: Parameters::default(),
            rng: RngScheme::Hash,
            seed: 0,
            accumulation: AccumulationFormat::F32,
            render,
            look: lighting.look,
            shadows: lighting.shadows,
            lights: lighting.lights.clone(),
            materials: lighting.sets.iter().map(|set| set.material).collect(),
            display: DisplayTransform::default(),
            backend,
            scale: if backend == Backend::Gpu { 1.0 } else { 0.5 },
            max_frames: 1024,
            rmse: false,
            paused: false,
        }
    }

    /// The ray-tracing methods of the menu: the catalogue's, without the CPU's cost baseline
    /// (not an image anyone looks at).
    pub fn trace_menu() -> Vec<MethodId> {
        MethodId::of(Family::Trace).filter(|&m| m != MethodId::Opaque).collect()
    }

    /// The splatting methods of the menu: the catalogue's.
    pub fn raster_menu() -> Vec<MethodId> {
        MethodId::of(Family::Raster).collect()
    }

    /// The ray-tracing method with its parameters.
    pub fn method(&self) -> Method {
        match self.trace.algorithm(&self.params) {
            Algorithm::Trace(method) => method,
            other => unreachable!("the ray-tracing menu holds {other:?}"),
        }
    }

    /// The splatting method with its parameters and settings.
    fn raster_method(&self) -> (RasterMethod, RasterSettings) {
        match self.raster.algorithm(&self.params) {
            Algorithm::Raster(method, settings) => (method, settings),
            other => unreachable!("the splatting menu holds {other:?}"),
        }
    }

    /// The renderer the settings name.
    pub fn algorithm(&self) -> Algorithm {
        let (raster, settings) = self.raster_method();
        match self.pipeline {
            Pipeline::RayTracing => Algorithm::Trace(self.method()),
            Pipeline::Raster => Algorithm::Raster(raster, settings),
            Pipeline::Hybrid => Algorithm::Hybrid(raster, settings, self.method()),
        }
    }

    /// `base` with the panel's look, shadows, lights and materials.
    pub fn lighting(&self, base: &Lighting) -> Lighting {
        let mut sets = base.sets.clone();
        for (set, material) in sets.iter_mut().zip(&self.materials) {
            set.material = *material;
        }
        Lighting { look: self.look, shadows: self.shadows, lights: self.lights.clone(), sets, ..base.clone() }
    }

    /// Whether the GPU progressive tracer renders these settings (else the CPU does).
    pub fn on_gpu(&self) -> bool {
        self.backend == Backend::Gpu && self.pipeline == Pipeline::RayTracing
    }

    /// What the scene's BVH and the kind of view depend on: a change rebuilds both.
    pub fn scene_key(&self) -> (RenderSettings, bool) {
        (self.render, self.on_gpu())
    }

    /// What the lighting depends on: a change relights the scene (its BVH stays) and restarts.
    pub fn lighting_key(&self) -> (Look, Shadows, &[Light], &[Material]) {
        (self.look, self.shadows, &self.lights, &self.materials)
    }

    /// What the accumulated frames depend on besides the camera and the scene: a change
    /// restarts the accumulation.
    pub fn frames_key(&self) -> (Algorithm, RngScheme, u32, AccumulationFormat, bool) {
        (self.algorithm(), self.rng, self.seed, self.accumulation, self.rmse)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_choice_is_a_valid_method_with_the_papers_defaults() {
        let mut s = Settings::new(RenderSettings::default(), &Lighting::default(), Backend::Cpu);
        for trace in Settings::trace_menu() {
            s.trace = trace;
            s.method().validate().unwrap_or_else(|e| panic!("{trace:?}: {e}"));
            assert_eq!(s.method().id(), trace);
        }
        s.trace = MethodId::KBuffer;
        assert_eq!(s.method(), Method::KBUFFER);
        for pipeline in Pipeline::ALL {
            s.pipeline = pipeline;
            for raster in Settings::raster_menu() {
                s.raster = raster;
                assert!(!s.on_gpu());
                assert_eq!(s.raster_method().0.id(), raster);
                let _ = s.algorithm();
            }
        }
        s.pipeline = Pipeline::RayTracing;
        s.backend = Backend::Gpu;
        assert!(s.on_gpu());
    }

    #[test]
    fn a_display_change_keeps_the_frames_and_a_method_change_does_not() {
        let s = Settings::new(RenderSettings::default(), &Lighting::default(), Backend::Cpu);
        let display = Settings { display: DisplayTransform { mode: DisplayMode::Depth, ..s.display }, ..s.clone() };
        assert_eq!(display.frames_key(), s.frames_key());
        assert_eq!(display.scene_key(), s.scene_key());
        let method = Settings { trace: MethodId::Exact, ..s.clone() };
        assert_ne!(method.frames_key(), s.frames_key());
        let degree = Settings { render: RenderSettings { iso_threshold: 0.3, ..s.render }, ..s.clone() };
        assert_ne!(degree.scene_key(), s.scene_key());
        let shadows = Settings { shadows: Shadows::Exact, ..s.clone() };
        assert_eq!(shadows.scene_key(), s.scene_key());
        assert_ne!(shadows.lighting_key(), s.lighting_key());
        // On the GPU, leaving ray tracing changes the kind of view.
        let gpu = Settings { backend: Backend::Gpu, ..s.clone() };
        let raster = Settings { pipeline: Pipeline::Raster, ..gpu.clone() };
        assert_ne!(raster.scene_key(), gpu.scene_key());
    }
}
