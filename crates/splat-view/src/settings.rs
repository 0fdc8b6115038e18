//! Every choice of the side panel, and how it becomes an [`Algorithm`], [`RenderSettings`] and
//! [`Lighting`]. Kept apart from the window so that the mapping is tested without one.

use splat_core::RenderSettings;
use splat_core::algorithm::Algorithm;
use splat_core::catalogue::{Family, Param};
use splat_core::lighting::{Light, Lighting, Look, Material, Shadows};
use splat_core::raster::{Blend, FragmentDepth, RasterMethod, RasterSettings, Response, SAMPLE_COUNTS};
use splat_core::raster::{SamplePattern, SplatExtent};
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

/// A method parameter's value as the panel and the page edit it.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A number within the catalogue's limits ([`is_count`]: a whole number).
    Number(f64),
    /// One of [`param_choices`], by name.
    Choice(String),
    /// On or off.
    Switch(bool),
}

/// Whether numeric parameter `param` counts (takes whole numbers).
pub fn is_count(param: Param) -> bool {
    param != Param::MinTransmittance
}

/// The blend orders of the menu.
const BLENDS: [Blend; 2] = [Blend::Over, Blend::Under];
/// The sample patterns of the menu.
const PATTERNS: [SamplePattern; 2] = [SamplePattern::Hammersley, SamplePattern::Standard];
/// The fragment depths of the menu.
const DEPTHS: [FragmentDepth; 2] = [FragmentDepth::Center, FragmentDepth::MaxDensityPlane];

/// The names a choice parameter takes, in menu order (empty for numbers and switches).
pub fn param_choices(param: Param) -> Vec<String> {
    let names = |v: &[&str]| v.iter().map(|n| n.to_string()).collect();
    match param {
        Param::Blend => names(&BLENDS.map(blend_name)),
        Param::RasterSamples => SAMPLE_COUNTS.iter().map(u32::to_string).collect(),
        Param::SamplePattern => names(&PATTERNS.map(SamplePattern::name)),
        Param::FragmentDepth => names(&DEPTHS.map(depth_name)),
        Param::Extent => names(&SplatExtent::ALL.map(SplatExtent::name)),
        Param::Response => names(&Response::ALL.map(Response::name)),
        _ => Vec::new(),
    }
}

fn blend_name(blend: Blend) -> &'static str {
    match blend {
        Blend::Over => "back to front",
        Blend::Under => "front to back",
    }
}

fn depth_name(depth: FragmentDepth) -> &'static str {
    match depth {
        FragmentDepth::Center => "centre",
        FragmentDepth::MaxDensityPlane => "max-density plane",
    }
}

/// The value of `param` in `p`.
pub fn param_value(p: &Parameters, param: Param) -> ParamValue {
    use ParamValue::{Choice, Number, Switch};
    let r = &p.raster;
    match param {
        Param::K => Number(p.k as f64),
        Param::MaxPasses => Number(f64::from(p.max_passes)),
        Param::MinTransmittance => Number(f64::from(p.min_transmittance)),
        Param::N => Number(f64::from(p.n)),
        Param::M => Number(f64::from(p.m)),
        Param::EarlyStop => Switch(r.early_stop),
        Param::Scramble => Switch(p.scramble),
        Param::Blend => Choice(blend_name(p.blend).into()),
        Param::RasterSamples => Choice(r.samples.to_string()),
        Param::SamplePattern => Choice(r.sample_pattern.name().into()),
        Param::FragmentDepth => Choice(depth_name(r.fragment_depth).into()),
        Param::Extent => Choice(r.extent.name().into()),
        Param::Response => Choice(r.response.name().into()),
    }
}

/// Set `param` of `p` to `value` (of the kind [`param_value`] gives; numbers are checked
/// against the limits by [`Parameters::validate`]).
pub fn set_param(p: &mut Parameters, param: Param, value: ParamValue) -> Result<(), String> {
    let label = param.info().label;
    match (param_value(p, param), value) {
        (ParamValue::Number(_), ParamValue::Number(x)) if x.is_finite() => match param {
            Param::K => p.k = x as usize,
            Param::MaxPasses => p.max_passes = x as u32,
            Param::MinTransmittance => p.min_transmittance = x as f32,
            Param::N => p.n = x as u32,
            _ => p.m = x as u32,
        },
        (ParamValue::Switch(_), ParamValue::Switch(on)) => match param {
            Param::EarlyStop => p.raster.early_stop = on,
            _ => p.scramble = on,
        },
        (ParamValue::Choice(_), ParamValue::Choice(name)) => {
            let choices = param_choices(param);
            let i = choices
                .iter()
                .position(|c| *c == name)
                .ok_or_else(|| format!("{label}: \"{name}\" is not one of {}", choices.join(", ")))?;
            let r = &mut p.raster;
            match param {
                Param::Blend => p.blend = BLENDS[i],
                Param::RasterSamples => r.samples = SAMPLE_COUNTS[i],
                Param::SamplePattern => r.sample_pattern = PATTERNS[i],
                Param::FragmentDepth => r.fragment_depth = DEPTHS[i],
                Param::Extent => r.extent = SplatExtent::ALL[i],
                _ => r.response = Response::ALL[i],
            }
        }
        (kind, value) => return Err(format!("{label} takes a value like {kind:?}, not {value:?}")),
    }
    Ok(())
}

/// The generators of the menu.
pub const RNGS: [RngScheme; 2] = [RngScheme::Hash, RngScheme::Trig];

/// A generator's menu name.
pub fn rng_name(rng: RngScheme) -> &'static str {
    match rng {
        RngScheme::Hash => "hash",
        RngScheme::Trig => "trig",
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

    /// Every parameter reads back what was set, for every choice and both switch states; a
    /// value of the wrong kind or outside the choices is refused.
    #[test]
    fn every_parameter_value_round_trips() {
        for param in Param::ALL {
            let mut p = Parameters::default();
            let values = match param_value(&p, param) {
                ParamValue::Number(_) => vec![ParamValue::Number(param.info().limits.unwrap().max)],
                ParamValue::Switch(_) => vec![ParamValue::Switch(false), ParamValue::Switch(true)],
                ParamValue::Choice(_) => param_choices(param).into_iter().map(ParamValue::Choice).collect(),
            };
            assert!(!values.is_empty(), "{param:?}");
            for value in values {
                set_param(&mut p, param, value.clone()).unwrap();
                assert_eq!(param_value(&p, param), value, "{param:?}");
                assert!(p.validate().is_ok(), "{param:?} = {value:?}");
            }
            assert!(set_param(&mut p, param, ParamValue::Choice("no such".into())).is_err(), "{param:?}");
        }
        // Each choice is a distinct setting.
        let mut p = Parameters::default();
        set_param(&mut p, Param::Extent, ParamValue::Choice("sqrt8".into())).unwrap();
        assert_eq!(p.raster.extent, SplatExtent::Sqrt8);
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
