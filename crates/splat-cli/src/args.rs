//! What `render`, `converge` and `bench` share: the scene, camera and shading options, the
//! method options and their resolution into a library [`Algorithm`], the backend choice, the
//! scene loader and the progress bar.

use anyhow::{Context, Result, bail};
use clap::builder::TypedValueParser;
use clap::{Args, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
use splat_core::catalogue::{self, Param};
use splat_core::frame::{AccumulationFormat, Frames};
use splat_core::lighting::{Look, Shadows};
use splat_core::mesh::Meshes;
use splat_core::normal::NormalMode;
use splat_core::raster::{Blend, FragmentDepth, RasterSettings, Response, SamplePattern, SplatExtent};
use splat_core::rng::RngScheme;
use splat_core::sh::ShStorage;
use splat_core::trace::Method;
use splat_core::trainer::{self, Preset};
use splat_core::undistort::Undistortion;
use splat_core::{
    Algorithm, Camera, HitDistance, KernelParams, MethodId, Parameters, RenderSettings, Scene, ScreenFilter, World,
};
use splat_io::cameras::{Split, ViewOptions};
use splat_io::similarity::Similarity;
use splat_io::text::{parse_direction, parse_vec3};
use splat_io::world::WorldSpec;
use std::path::PathBuf;

/// The values of `--method` (and `--secondary`, `--methods`): every method of the
/// [catalogue](splat_core::catalogue) by its name, its summary as help.
pub fn method_parser() -> impl TypedValueParser<Value = MethodId> {
    splat_view::choice_parser(&MethodId::ALL, MethodId::name, |m| m.entry().summary)
}

/// Blend order of raster-sorted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BlendArg {
    /// Back to front, C ← αc + (1 − α)C.
    Over,
    /// Front to back, premultiplied; also picks the iso-opacity depth and integrates normals.
    Under,
}

/// Depth of a raster fragment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FragmentDepthArg {
    /// Billboard through the splat centre (3DGS, vk).
    Center,
    /// Maximum-density point along each sample's ray (StochasticSplats' pop-free variant).
    Plane,
}

/// Sub-pixel sample positions of the raster methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplePatternArg {
    /// The Hammersley set: a Latin square at every power of two (S up to 64).
    Hammersley,
    /// The standard MSAA positions of Vulkan, Direct3D and Metal (S up to 16): the GPU's.
    Standard,
}

/// Where rays are traced or splats rasterized.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// A hardware GPU when wgpu finds one, else the CPU (lavapipe, a CPU Vulkan driver, is
    /// slower than the CPU renderers and is used only when asked for with --backend gpu).
    Auto,
    /// The CPU renderers of splat-core (rayon over tiles).
    Cpu,
    /// The wgpu kernels: compute ray tracing, and the splatting render pipeline for
    /// raster-sorted and stochastic-splat (WGPU_BACKEND / WGPU_ADAPTER_NAME choose the adapter).
    Gpu,
}

/// Random number generator of the stochastic methods.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum RngArg {
    /// xxhash32 + PCG (vk_gaussian_splatting), 24-bit uniform.
    Hash,
    /// Trigonometric hash of Sun et al. Eqs. 8–10 (coarse in f32: u on a grid up to 1/256).
    Trig,
}

/// Options of the methods, shared by `render`, `converge` and `bench`.
#[derive(Args, Clone)]
pub struct MethodOptions {
    /// Hits per pass (kbuffer, stochastic-pass) or accepted hits composited (depth-sampling-k).
    #[arg(help_heading = "Method parameters", long, default_value_t = catalogue::DEFAULT_K)]
    pub k: usize,
    /// Pass limit of kbuffer and stochastic-pass.
    #[arg(help_heading = "Method parameters", long, default_value_t = catalogue::DEFAULT_MAX_PASSES)]
    pub max_passes: u32,
    /// kbuffer stops when transmittance falls to this (0: never; exact up to --max-passes).
    #[arg(help_heading = "Method parameters", long, default_value_t = catalogue::DEFAULT_MIN_TRANSMITTANCE)]
    pub min_transmittance: f32,
    /// stochastic-n: samples per traversal (Sun et al. §3.5's N, up to 64).
    #[arg(help_heading = "Method parameters", long, alias = "samples", default_value_t = catalogue::DEFAULT_N)]
    pub samples_per_traversal: u32,
    /// stochastic-n: traversals per frame (m).
    #[arg(help_heading = "Method parameters", long, alias = "passes", default_value_t = catalogue::DEFAULT_M)]
    pub traversals: u32,
    /// Generator of the stochastic decisions.
    #[arg(help_heading = "Method parameters", long, value_enum, default_value = "hash")]
    pub rng: RngArg,
    /// How the running mean is stored between frames (vk_gaussian_splatting's accumulation
    /// formats; the per-frame variance keeps full precision).
    #[arg(help_heading = "Method parameters", long, value_parser = accumulation_parser(), default_value = "f32")]
    pub accumulation: AccumulationFormat,
    /// Raster methods: samples per pixel S (1, 2, 4, 8, 16, 32 or 64; the standard pattern has
    /// up to 16).
    #[arg(help_heading = "Splatting", long, default_value_t = 1)]
    pub raster_samples: u32,
    /// Raster methods: where the samples lie (default: hammersley on the CPU, standard on the
    /// GPU, whose multisampling hardware has no other).
    #[arg(help_heading = "Splatting", long, value_enum)]
    pub sample_pattern: Option<SamplePatternArg>,
    /// Raster methods: depth of each fragment.
    #[arg(help_heading = "Splatting", long, value_enum, default_value = "center")]
    pub fragment_depth: FragmentDepthArg,
    /// Raster methods: which pixels a splat can touch [default: the --preset's, else that of
    /// the trainer whose screen filter the capture names: alpha-cull for gsplat's antialiased
    /// mode, else 3dgs].
    #[arg(help_heading = "Splatting", long, value_parser = extent_parser())]
    pub extent: Option<SplatExtent>,
    /// Raster methods: how a fragment's alpha is evaluated (CPU) [default: the --preset's, else
    /// along-ray for a capture of 2D Gaussians (2DGS), else projected].
    #[arg(help_heading = "Splatting", long, value_parser = response_parser())]
    pub response: Option<Response>,
    /// What the capture's trainer implies where those flags are silent ([`MethodOptions::apply_preset`],
    /// [`MethodOptions::apply_capture`]): not options the user gave.
    #[arg(skip)]
    pub implied: Implied,
    /// raster-sorted: stop a pixel before the splat that takes its transmittance below 1e-4, as
    /// the 3DGS rasterizer does (default off: the exact sum of Eq. 3; CPU only; the stochastic
    /// raster methods have no order to stop in and ignore it).
    #[arg(help_heading = "Splatting", long)]
    pub early_stop: bool,
    /// raster-sorted: blend order (under also yields --depth and --normal).
    #[arg(help_heading = "Splatting", long, value_enum, default_value = "under")]
    pub blend: BlendArg,
    /// stratified: skip the multiply–XOR scramble (the correlated radical inverse that
    /// Laine–Karras warn about; biased, a negative control).
    #[arg(help_heading = "Splatting", long)]
    pub no_scramble: bool,
}

/// The values of `--response`: every [`Response`] by its name, described.
fn response_parser() -> impl TypedValueParser<Value = Response> {
    splat_view::choice_parser(&Response::ALL, Response::name, Response::describe)
}

/// The values of `--accumulation`: every [`AccumulationFormat`] by its name, described.
fn accumulation_parser() -> impl TypedValueParser<Value = AccumulationFormat> {
    splat_view::choice_parser(&AccumulationFormat::ALL, AccumulationFormat::name, AccumulationFormat::describe)
}

/// The values of `--hit-distance`: every [`HitDistance`] by its name, described.
fn hit_distance_parser() -> impl TypedValueParser<Value = HitDistance> {
    splat_view::choice_parser(&HitDistance::ALL, HitDistance::name, HitDistance::describe)
}

/// The values of `--pixel-filter`: every [`PixelFilter`] by its name.
fn pixel_filter_parser() -> impl TypedValueParser<Value = PixelFilter> {
    splat_view::choice_parser(&PixelFilter::ALL, PixelFilter::name, PixelFilter::describe)
}

/// A pixel "x,y": two whole numbers.
fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    match s.split(',').map(|c| c.trim().parse::<u32>()).collect::<Result<Vec<_>, _>>().as_deref() {
        Ok([x, y]) => Ok((*x, *y)),
        _ => Err(format!("'{s}' is not a pixel: give two whole numbers x,y")),
    }
}

/// The values of `--extent`: every [`SplatExtent`] by its name, described.
fn extent_parser() -> impl TypedValueParser<Value = SplatExtent> {
    splat_view::choice_parser(&SplatExtent::ALL, SplatExtent::name, SplatExtent::describe)
}

/// The splatting settings a capture's trainer implies.
#[derive(Clone, Copy, Debug, Default)]
pub struct Implied {
    /// The trainer's splat extent.
    pub extent: Option<SplatExtent>,
    /// The trainer's splat response.
    pub response: Option<Response>,
}

impl MethodOptions {
    /// Imply the trainer's extent and response ([`Preset::extent`], [`Preset::response`]).
    pub fn apply_preset(&mut self, preset: Option<Preset>) {
        self.implied.extent = self.implied.extent.or(preset.map(Preset::extent));
        self.implied.response = self.implied.response.or(preset.map(Preset::response));
    }

    /// Where `--preset` implied no extent or response, imply those the capture is drawn with
    /// ([`trainer::capture_splatting`]: its trainer's, as its file names it).
    pub fn apply_capture(&mut self, scene: &Scene) {
        let (extent, response) = trainer::capture_splatting(scene);
        self.implied.extent = self.implied.extent.or(Some(extent));
        self.implied.response = self.implied.response.or(Some(response));
    }

    /// The value of every method parameter these options give.
    pub fn parameters(&self) -> Parameters {
        Parameters {
            k: self.k,
            max_passes: self.max_passes,
            min_transmittance: self.min_transmittance,
            n: self.samples_per_traversal,
            m: self.traversals,
            blend: match self.blend {
                BlendArg::Over => Blend::Over,
                BlendArg::Under => Blend::Under,
            },
            scramble: !self.no_scramble,
            raster: self.raster_settings(),
        }
    }

    /// The library's algorithm for a method, with these options' parameters.
    pub fn resolve(&self, m: MethodId) -> Algorithm {
        m.algorithm(&self.parameters())
    }

    /// The options given away from their defaults that `algorithm` does not read, each as its
    /// flag: which parameters a method reads is the catalogue's word.
    pub fn unused(&self, algorithm: &Algorithm) -> Vec<String> {
        let typed = Self { implied: Implied::default(), ..self.clone() };
        let (given, defaults) = (typed.parameters(), Parameters::default());
        Param::ALL
            .into_iter()
            .filter(|&p| given.differs(&defaults, p) || (p == Param::SamplePattern && self.sample_pattern.is_some()))
            .filter(|&p| !algorithm.reads(p))
            .map(|p| format!("--{}", p.info().flag))
            .collect()
    }

    /// The ray-tracing method for a CLI method; an error names any other.
    pub fn method(&self, m: MethodId) -> Result<Method> {
        match self.resolve(m) {
            Algorithm::Trace(method) => Ok(method),
            _ => bail!("{} is not a ray-tracing method (it has no BVH to time)", m.name()),
        }
    }

    /// The raster settings these options describe.
    pub fn raster_settings(&self) -> RasterSettings {
        RasterSettings {
            samples: self.raster_samples,
            sample_pattern: match self.sample_pattern {
                None | Some(SamplePatternArg::Hammersley) => SamplePattern::Hammersley,
                Some(SamplePatternArg::Standard) => SamplePattern::Standard,
            },
            fragment_depth: match self.fragment_depth {
                FragmentDepthArg::Center => FragmentDepth::Center,
                FragmentDepthArg::Plane => FragmentDepth::MaxDensityPlane,
            },
            extent: self.extent.or(self.implied.extent).unwrap_or_default(),
            response: self.response.or(self.implied.response).unwrap_or_default(),
            early_stop: self.early_stop,
            lk_variant: splat_core::raster::LkVariant::Paper,
        }
    }

    /// `algorithm` as the GPU renders it: without `--sample-pattern`, at the standard pattern.
    pub fn on_gpu(&self, algorithm: Algorithm) -> Algorithm {
        let standard = |raster: RasterSettings| match self.sample_pattern {
            None => RasterSettings { sample_pattern: SamplePattern::Standard, ..raster },
            Some(_) => raster,
        };
        match algorithm {
            Algorithm::Raster(method, raster) => Algorithm::Raster(method, standard(raster)),
            Algorithm::Hybrid(method, raster, secondary) => Algorithm::Hybrid(method, standard(raster), secondary),
            other => other,
        }
    }

    /// The generator.
    pub fn rng(&self) -> RngScheme {
        match self.rng {
            RngArg::Hash => RngScheme::Hash,
            RngArg::Trig => RngScheme::Trig,
        }
    }

    /// `count` frames from `seed`, drawn and stored as these options say.
    pub fn frames(&self, count: u32, seed: u32) -> Frames {
        Frames { count, seed, rng: self.rng(), accumulation: self.accumulation, ..Frames::default() }
    }
}

/// Per-particle normal (vk_gaussian_splatting Lighting §2.4).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum NormalArg {
    /// Normal of the max-density plane, Σ⁻¹(μ − o).
    Plane,
    /// Normal of the cutoff ellipsoid where the ray enters it.
    Ellipsoid,
}

/// Integration of the sorted methods when lit.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum LookArg {
    /// Integrate radiance and normal, light once at the iso-opacity depth (hard, surface-like).
    Surface,
    /// Light every hit, then integrate (soft; the expectation of the stochastic methods).
    Volumetric,
}

/// Shadow rays of the ray-tracing methods.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ShadowsArg {
    /// No shadows.
    None,
    /// vk_gaussian_splatting: one pass of --k sorted hits, in shadow below transmittance 0.8.
    Sorted,
    /// One traversal, Russian roulette on α, blocked at the first accept (unbiased).
    Stochastic,
    /// The exact transmittance Π(1 − α) (the stochastic shadow's expectation).
    Exact,
}

/// A world staged for a command: what renders, with the options applied, the chosen camera and
/// the render settings.
pub struct Staged {
    /// The splats, meshes and lighting (emissive splats alone for a bare scene file).
    pub world: World,
    /// The camera.
    pub camera: Camera,
    /// Render settings, with the world's background unless --background is given.
    pub settings: RenderSettings,
    /// The world's environment for the path tracer, if it gives one.
    pub environment: Option<splat_core::path::Environment>,
    /// Every view of --camera as read (named, before --width and --height size them), the
    /// camera among them; none without --camera.
    pub views: Vec<(String, Camera)>,
}

impl Staged {
    /// What one render of this world reads, on either backend.
    pub fn shot(&self) -> splat_core::Shot<'_> {
        self.world.shot(&self.camera, &self.settings)
    }
}

/// Scene, camera and shading options shared by `render`, `converge` and `bench`.
#[derive(Args, Clone)]
pub struct SceneArgs {
    /// Scene file (.ply, compressed .ply, .splat, .spz, PlayCanvas SOG (.sog, or a meta.json
    /// beside its images), GaussianSplats3D .ksplat, OpenUSD .usda (ParticleField3DGaussianSplat
    /// prims), trainers' checkpoints (3DGS's .pth, gsplat's and 3DGRUT's .pt, Nerfstudio's .ckpt),
    /// or .glb / .gltf with KHR_gaussian_splatting and any meshes beside the splats) or world
    /// file (.toml: splat sets, materials, lights, camera; see the README). Without one, the
    /// built-in demo scene is used.
    pub scene: Option<PathBuf>,
    /// Cameras: an INRIA cameras.json, a COLMAP model (a sparse/0 folder, or its
    /// images.bin / images.txt; views sorted by image name as 3DGS lists them) or a
    /// transforms.json (NeRF-synthetic, Nerfstudio; the file or its folder); distorted,
    /// fisheye and equirectangular models render through their lens with the ray-tracing
    /// methods. Without it the camera frames the scene (or the demo's own camera).
    #[arg(help_heading = "Camera", long)]
    pub camera: Option<PathBuf>,
    /// Which camera of --camera to use (0-based).
    #[arg(help_heading = "Camera", long, default_value_t = 0, requires = "camera")]
    pub camera_index: usize,
    /// A Nerfstudio training run's dataparser_transforms.json: moves the cameras of a
    /// transforms.json (--camera) into the run's normalised world, where splatfacto's exported
    /// splats (ns-export gaussian-splat) live.
    #[arg(help_heading = "Camera", long, requires = "camera")]
    pub dataparser_transforms: Option<PathBuf>,
    /// The splats are gsplat simple_trainer's, in the normalised world it trains in by default
    /// (normalize_world_space): moves the cameras of a COLMAP model (--camera, with its
    /// points3D) into that world, the frame numpy's eigenvectors leave open chosen by where the
    /// 3D points lie on the splats.
    #[arg(help_heading = "Camera", long, requires = "camera", conflicts_with = "dataparser_transforms")]
    pub gsplat_world: bool,
    /// A 4 × 4 (or 3 × 4) matrix [s R | t] from the world of --camera to the splats' world
    /// (a .npy as numpy.save writes it, or its numbers as text, as numpy.savetxt writes them),
    /// such as gsplat's parser.transform: moves every camera by it.
    #[arg(
        help_heading = "Camera",
        long,
        value_name = "FILE",
        requires = "camera",
        conflicts_with_all = ["dataparser_transforms", "gsplat_world"],
        value_parser = splat_view::world_transform_parser
    )]
    pub world_transform: Option<Similarity>,
    /// Render each camera of --camera as the pinhole this trainer undistorts its photos to
    /// (their training and evaluation images are of it): OpenCV's choice, as the trainer
    /// calls it; gsplat's fisheye, the ideal fisheye its own map resamples to.
    #[arg(help_heading = "Camera", long, requires = "camera", value_parser = splat_view::undistort_parser())]
    pub undistort: Option<Undistortion>,
    /// Keep only a trainer's split of the views of --camera (its held-out views, to score
    /// renders as it does), in its order: --camera-index and --all-cameras then count in it.
    #[arg(help_heading = "Camera", long, requires = "camera", value_parser = splat_view::split_parser())]
    pub split: Option<Split>,
    /// The trainer read images downscaled by F (images_F/, gsplat's --data_factor, Nerfstudio's
    /// downscale factor): each camera of --camera takes K / F and its sides floored, as they
    /// do (--width and --height, which keep the field of view as 3DGS's -r does, then scale
    /// from there, as gsplat scales K to the photographs it finds).
    #[arg(help_heading = "Camera", long, requires = "camera", value_parser = clap::value_parser!(u32).range(1..))]
    pub data_factor: Option<u32>,
    /// Image width in pixels (1 to 16384); rescales the camera's intrinsics [default: the
    /// camera's, else the command's framing size: 640 for render]. With --undistort, the
    /// photographs' width: the cameras are scaled to it before they are undistorted.
    #[arg(help_heading = "Camera", long, value_parser = parse_side, allow_negative_numbers = true)]
    pub width: Option<u32>,
    /// Image height in pixels (1 to 16384); rescales the camera's intrinsics [default: the
    /// camera's, else the command's framing size: 480 for render]. With --undistort, the
    /// photographs' height.
    #[arg(help_heading = "Camera", long, value_parser = parse_side, allow_negative_numbers = true)]
    pub height: Option<u32>,
    /// Look-at camera position "x,y,z" (with --target; world up from --up).
    #[arg(
        help_heading = "Camera",
        long,
        value_parser = parse_vec3,
        requires = "target",
        conflicts_with = "camera",
        allow_hyphen_values = true
    )]
    pub eye: Option<Vec3>,
    /// Look-at target "x,y,z".
    #[arg(help_heading = "Camera", long, value_parser = parse_vec3, requires = "eye", allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    /// World up "x,y,z" for --eye/--target and for framing (COLMAP captures: 0,-1,0; `splat
    /// info SCENE --camera CAMERAS` measures it) [default: 0,1,0].
    #[arg(
        help_heading = "Camera",
        long,
        value_parser = parse_direction,
        conflicts_with = "camera",
        allow_hyphen_values = true
    )]
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees for --eye/--target.
    #[arg(help_heading = "Camera", long, default_value_t = splat_core::camera::DEFAULT_FOV_Y, requires = "eye")]
    pub fov: f32,
    /// Where each frame's rays pass through the pixel: its centre, or a point drawn per frame
    /// from a Sobol sequence (a box filter: edges anti-aliased over the frames; Sun et al.
    /// §4.2). The path tracer always samples the box [default: the world's, else center].
    #[arg(help_heading = "Camera", long, value_parser = pixel_filter_parser())]
    pub pixel_filter: Option<PixelFilter>,
    /// Thin-lens radius in world units: depth of field, integrated over the frames by every
    /// pipeline (overrides the world's camera) [default: the world's, else none].
    #[arg(help_heading = "Camera", long)]
    pub aperture: Option<f32>,
    /// Distance of the plane in focus along the view [default: the world's, else what the
    /// centre pixel shows (auto-focus)].
    #[arg(help_heading = "Camera", long, conflicts_with = "focus_at")]
    pub focus_distance: Option<f32>,
    /// Auto-focus on what pixel "x,y" shows: its iso-opacity depth (vk_gaussian_splatting
    /// Lighting §1.5).
    #[arg(help_heading = "Camera", long, value_parser = parse_pixel)]
    pub focus_at: Option<(u32, u32)>,
    /// Background colour "r,g,b" behind the particles [default: the world's, else the one the
    /// capture's run composites over (3DGS's white_background, splatfacto's background_color,
    /// 3DGRUT's), else 0,0,0].
    #[arg(help_heading = "Scene and shading", long, value_parser = parse_vec3)]
    pub background: Option<Vec3>,
    /// Drop the SH bands above this degree (0–3), removing some baked lighting before relighting.
    #[arg(help_heading = "Scene and shading", long, value_parser = clap::value_parser!(u8).range(..=3))]
    pub sh_degree: Option<u8>,
    /// Lit worlds: integration of the sorted methods [default: the world's, else surface].
    #[arg(help_heading = "Scene and shading", long, value_enum)]
    pub look: Option<LookArg>,
    /// Lit worlds: shadow rays of the ray-tracing methods [default: the world's, else none].
    #[arg(help_heading = "Scene and shading", long, value_enum)]
    pub shadows: Option<ShadowsArg>,
    /// Sorted shadows: hits of the shadow pass [default: the world's, else 18].
    #[arg(help_heading = "Scene and shading", long)]
    pub shadow_k: Option<usize>,
    /// Sorted shadows: the transmittance below which a point is in shadow [default: the
    /// world's, else 0.8].
    #[arg(help_heading = "Scene and shading", long)]
    pub shadow_threshold: Option<f32>,
    /// Sorted shadows: coloured-shadow strength in [0, 1] [default: the world's, else 0].
    #[arg(help_heading = "Scene and shading", long)]
    pub shadow_colored: Option<f32>,
    /// Lit worlds: how far along the normal shadow rays start [default: the world's, else 0.2].
    #[arg(help_heading = "Scene and shading", long)]
    pub shadow_offset: Option<f32>,
    /// Hit distance of the ray tracers: where along the ray a particle is hit, for sorting and
    /// picking (Sun et al. §4.1, vk_gaussian_splatting Lighting §1.4).
    #[arg(help_heading = "Scene and shading", long, value_parser = hit_distance_parser(), default_value = "mean")]
    pub hit_distance: HitDistance,
    /// Per-particle normal.
    #[arg(help_heading = "Scene and shading", long, value_enum, default_value = "plane")]
    pub normals: NormalArg,
    /// How the SH coefficients are stored (vk_gaussian_splatting's SH formats): f16 halves the
    /// GPU's largest scene array, u8 quarters it, each rounding the colours; the CPU reads the
    /// same stored values [default: the world's, else f32].
    #[arg(help_heading = "Scene and shading", long, value_parser = splat_view::sh_storage_parser())]
    pub sh_storage: Option<ShStorage>,
    /// Kernel degree n of the generalized Gaussian exp(−4.5 (d/3)ⁿ), 1..=8 [default: the
    /// --preset's, else the one the capture's file names (a 3DGRUT checkpoint's), else 2].
    #[arg(help_heading = "Scene and shading", long)]
    pub kernel_degree: Option<u32>,
    /// Cutoff in standard deviations (Eq. 2) [default: the --preset's, else the one the
    /// capture's file names (a 3DGRUT checkpoint's minimum response), else 3].
    #[arg(help_heading = "Scene and shading", long)]
    pub cutoff: Option<f32>,
    /// The splatting methods' near plane: a splat whose centre is nearer the camera along its
    /// axis is culled [default: the --preset's, else the capture's run's (a gsplat run's
    /// near_plane; gsplat's checkpoints 0.01), else 0.2, 3DGS's].
    #[arg(help_heading = "Scene and shading", long)]
    pub near_plane: Option<f32>,
    /// The ray tracers' iso-opacity depth threshold on transmittance [default: the world's,
    /// else 0.7].
    #[arg(help_heading = "Scene and shading", long)]
    pub iso_threshold: Option<f32>,
    /// Splatting's iso-opacity depth threshold, a value of its own (vk_gaussian_splatting's
    /// rasterization panel) [default: the world's, else 0.7].
    #[arg(help_heading = "Scene and shading", long)]
    pub raster_iso_threshold: Option<f32>,
    /// Most mirror and glass bounces of a ray among meshes (default: the world's, else 3).
    #[arg(help_heading = "Scene and shading", long, value_parser = clap::value_parser!(u32).range(0..=i64::from(splat_core::settings::MAX_BOUNCES)))]
    pub max_bounces: Option<u32>,
    /// Worker threads (default: all cores). The image does not depend on it.
    #[arg(help_heading = "Machine", long)]
    pub threads: Option<usize>,
    /// Where rays are traced.
    #[arg(help_heading = "Machine", long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// How scene files are read.
    #[command(flatten)]
    pub read: ReadArgs,
}

/// How scene files are read.
#[derive(Args, Clone, Copy, Debug, Default)]
#[command(next_help_heading = "Reading scene files")]
pub struct ReadArgs {
    /// Refuse `.ply` vertex properties this reader does not know (by default they are skipped
    /// with one warning line naming them; Mip-Splatting's filter_3D is known and applied).
    #[arg(long)]
    pub strict: bool,
    /// Axes of `.spz` data: as-stored (what splat-transform, spz-js and the spz library's
    /// ply_to_spz write from a 3DGS .ply) or rub (right-up-back, converted to the 3DGS axes).
    #[arg(long, value_enum, default_value = "as-stored")]
    pub spz_axes: SpzAxesArg,
    /// Accepted for compatibility: unknown properties are now skipped unless --strict.
    #[arg(long, hide = true)]
    pub allow_unknown_properties: bool,
    /// The screen-space filter the capture was trained with, which the splatting methods apply
    /// (default: the --preset's, else the one its file names, by a `SplatRenderMode` or
    /// `antialiased` comment, a `filter_3D` property or the `.spz` antialiased flag; else 3dgs).
    #[arg(long, value_parser = splat_view::screen_filter_parser())]
    pub screen_filter: Option<ScreenFilter>,
    /// The trainer of the capture: its screen filter, splat extent and response, near plane,
    /// kernel degree and cutoff, unless given on their own (3dgrt: kernel degree 4; 3dgrt and
    /// 3dgut: the cutoff of their minimum response) [default: the one the capture's file names:
    /// a trainer's checkpoint, gsplat's rasterizer for gsplat's and splatfacto's, 3DGRUT's
    /// renderer and kernel as its config names them].
    #[arg(long, value_parser = splat_view::preset_parser())]
    pub preset: Option<Preset>,
}

impl ReadArgs {
    /// The reader's options.
    pub fn options(&self) -> splat_io::ReadOptions {
        let screen_filter = self.screen_filter.or(self.preset.and_then(Preset::screen_filter));
        let progress = splat_io::Progress(Some(&load_progress));
        splat_io::ReadOptions { strict: self.strict, spz_axes: self.spz_axes.into(), screen_filter, progress }
    }
}

/// The load's progress bar: shown once a read has taken a second (and stderr is a terminal),
/// cleared when it ends.
fn load_progress(done: u64, total: u64) {
    use std::sync::Mutex;
    use std::time::{Duration, Instant};
    static LOAD: Mutex<Option<(Instant, Option<ProgressBar>)>> = Mutex::new(None);
    let mut load = LOAD.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if done == 0 {
        *load = Some((Instant::now(), None));
        return;
    }
    let Some((start, bar)) = load.as_mut() else { return };
    if bar.is_none() && start.elapsed() > Duration::from_secs(1) && done < total {
        let style = ProgressStyle::with_template(
            "{spinner} reading [{bar:40}] {binary_bytes}/{binary_total_bytes} {elapsed} (eta {eta})",
        )
        .expect("valid template")
        .progress_chars("=> ");
        *bar = Some(ProgressBar::new(total).with_style(style));
    }
    if let Some(bar) = bar {
        bar.set_position(done);
        if done >= total {
            bar.finish_and_clear();
        }
    }
}

/// Axes of `.spz` data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum SpzAxesArg {
    /// The file's axes are the scene's (no conversion).
    #[default]
    AsStored,
    /// Right-up-back: y and z flipped with respect to the 3DGS axes.
    Rub,
}

impl From<SpzAxesArg> for splat_io::spz::SpzAxes {
    fn from(a: SpzAxesArg) -> Self {
        match a {
            SpzAxesArg::AsStored => Self::AsStored,
            SpzAxesArg::Rub => Self::Rub,
        }
    }
}

/// Every camera of a cameras.json, COLMAP model or transforms.json, with its image name, as
/// `options` change them.
pub fn load_cameras(path: &std::path::Path, options: ViewOptions) -> Result<Vec<(String, Camera)>> {
    Ok(splat_io::cameras::read_views_in(path, options)?)
}

impl SceneArgs {
    /// The files these options read (the scene, the cameras, a run's dataparser transforms),
    /// which no output may replace ([`check_outputs`]).
    pub fn inputs(&self) -> Vec<&std::path::Path> {
        [&self.scene, &self.camera, &self.dataparser_transforms].into_iter().filter_map(|p| p.as_deref()).collect()
    }

    /// How --camera's views are read.
    ///
    /// With --undistort, --width and --height size the cameras before they are undistorted (the
    /// photographs' size, as gsplat scales K to it and then undistorts), and [`Self::sized`]
    /// leaves the undistorted views as they are.
    ///
    /// `scene` holds the splats whose gsplat world --gsplat-world moves the cameras to.
    pub fn view_options<'a>(&'a self, scene: &'a Scene) -> ViewOptions<'a> {
        ViewOptions {
            dataparser: self.dataparser_transforms.as_deref(),
            gsplat_world: self.gsplat_world.then_some(scene),
            world_transform: self.world_transform,
            undistort: self.undistort,
            split: self.split,
            factor: self.data_factor,
            size: if self.undistort.is_some() { (self.width, self.height) } else { (None, None) },
        }
    }

    /// Load the scene (or the demo) and choose the camera; `width` × `height` is the size of
    /// a look-at or framing camera when none is given.
    pub fn load(&self, width: u32, height: u32) -> Result<(Scene, Camera, RenderSettings)> {
        let staged = self.load_world(width, height)?;
        if staged.world.lighting.is_on() {
            bail!("this command renders unlit radiance; a lit world renders with `splat render`");
        }
        Ok((staged.world.scene, staged.camera, staged.settings))
    }

    /// Load the scene, world file or demo with its lighting, apply --sh-degree, --look,
    /// --shadows and --background, and choose the camera.
    pub fn load_world(&self, width: u32, height: u32) -> Result<Staged> {
        let opened = splat_io::world::open_world(self.scene.as_deref(), self.read.options())?;
        if let Some(path) = &self.scene {
            warn_skipped_properties(path, &opened.skipped_properties);
            print_notes(path, &opened.notes);
        }
        self.stage(opened.world, width, height)
    }

    /// Stage a world already read (or built from arrays): these options applied over it as
    /// [`SceneArgs::load_world`] applies them to a file's, the camera chosen with the world's
    /// own camera (if any) in place of framing, at `width` × `height` where neither the
    /// options nor the camera give a size.
    pub fn stage(&self, world: WorldSpec, width: u32, height: u32) -> Result<Staged> {
        let mut settings = self.settings_over(world.settings(RenderSettings::default()));
        let WorldSpec { mut scene, mut lighting, camera, meshes, environment, lens, .. } = world;
        let meshes = Meshes::new(&meshes).map_err(|e| anyhow::anyhow!("{e}"))?;
        if let Some(degree) = self.sh_degree {
            splat_io::world::truncate_sh(&mut scene, degree);
        }
        if let Some(look) = self.look {
            lighting.look = match look {
                LookArg::Surface => Look::Surface,
                LookArg::Volumetric => Look::Volumetric,
            };
        }
        if let Some(shadows) = self.shadows {
            lighting.shadows = match (shadows, lighting.shadows) {
                (ShadowsArg::None, _) => Shadows::None,
                // The world's sorted shadows keep their k, threshold and tint.
                (ShadowsArg::Sorted, sorted @ Shadows::Sorted { .. }) => sorted,
                (ShadowsArg::Sorted, _) => Shadows::SORTED,
                (ShadowsArg::Stochastic, _) => Shadows::Stochastic,
                (ShadowsArg::Exact, _) => Shadows::Exact,
            };
        }
        self.apply_shadow_options(&mut lighting)?;
        let (camera, views) = self.choose_camera(&scene, camera, width, height)?;
        settings.sampling.lens = self.lens(lens, &scene, &camera, &settings)?;
        Ok(Staged { world: World::new(scene, meshes, lighting)?, camera, settings, environment, views })
    }

    /// The thin lens: --aperture over the world's, in focus at --focus-distance, else at what
    /// --focus-at's pixel shows, else at the world's distance, else at what the centre pixel
    /// shows (auto-focus on the splats; a pixel whose ray crosses none is refused).
    fn lens(
        &self,
        world: Option<ThinLens>,
        scene: &Scene,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<Option<ThinLens>> {
        let Some(aperture) = self.aperture.or(world.map(|l| l.aperture)) else {
            if self.focus_distance.is_some() || self.focus_at.is_some() {
                bail!("--focus-distance and --focus-at place the plane in focus of a lens: add --aperture");
            }
            return Ok(None);
        };
        let world_distance = world.map(|l| l.focus_distance).filter(|_| self.focus_at.is_none());
        let focus_distance = match self.focus_distance.or(world_distance) {
            Some(d) => d,
            None => {
                let (x, y) = self.focus_at.unwrap_or((camera.width / 2, camera.height / 2));
                if x >= camera.width || y >= camera.height {
                    bail!("--focus-at {x},{y} is outside the {}×{} image", camera.width, camera.height);
                }
                let oracle = splat_core::oracle::Oracle::new(scene, *settings)?;
                oracle.focus_distance(camera, x, y).with_context(|| {
                    format!(
                        "auto-focus: the ray through pixel {x},{y} crosses no surface of the splats; \
                         give --focus-distance or --focus-at a pixel that shows the scene"
                    )
                })?
            }
        };
        let lens = ThinLens { aperture, focus_distance };
        splat_core::camera_sampling::CameraSampling { lens: Some(lens), ..Default::default() }.validate()?;
        Ok(Some(lens))
    }

    /// --shadow-k, --shadow-threshold and --shadow-colored on sorted shadows (refused on any
    /// other kind, which reads none of them), --shadow-offset on any; `World::new` checks the
    /// values with the rest of the lighting.
    fn apply_shadow_options(&self, lighting: &mut splat_core::lighting::Lighting) -> Result<()> {
        let sorted_options = [
            ("--shadow-k", self.shadow_k.is_some()),
            ("--shadow-threshold", self.shadow_threshold.is_some()),
            ("--shadow-colored", self.shadow_colored.is_some()),
        ];
        match &mut lighting.shadows {
            Shadows::Sorted { k, threshold, colored } => {
                *k = self.shadow_k.unwrap_or(*k);
                *threshold = self.shadow_threshold.unwrap_or(*threshold);
                *colored = self.shadow_colored.unwrap_or(*colored);
            }
            other => {
                if let Some((flag, _)) = sorted_options.iter().find(|(_, given)| *given) {
                    bail!("{flag} sets sorted shadows, and the shadows are {other:?}: add --shadows sorted");
                }
            }
        }
        if let Some(offset) = self.shadow_offset {
            lighting.shadow_offset = offset;
        }
        Ok(())
    }

    /// `base` (the defaults, or what a world or scene file sets: the kernel, near plane and
    /// background of the renderer its trainer drew it through) under these options.
    fn settings_over(&self, base: RenderSettings) -> RenderSettings {
        let preset = self.read.preset;
        RenderSettings {
            kernel: KernelParams {
                degree: self.kernel_degree.or(preset.map(Preset::kernel_degree)).unwrap_or(base.kernel.degree),
                cutoff: self.cutoff.or(preset.map(Preset::cutoff)).unwrap_or(base.kernel.cutoff),
                ..base.kernel
            },
            hit_distance: self.hit_distance,
            normal_mode: match self.normals {
                NormalArg::Plane => NormalMode::MaxDensityPlane,
                NormalArg::Ellipsoid => NormalMode::KernelEllipsoid,
            },
            near: self.near_plane.or(preset.map(Preset::near)).unwrap_or(base.near),
            background: self.background.unwrap_or(base.background),
            max_bounces: self.max_bounces.unwrap_or(base.max_bounces),
            iso_threshold: self.iso_threshold.unwrap_or(base.iso_threshold),
            raster_iso_threshold: self.raster_iso_threshold.unwrap_or(base.raster_iso_threshold),
            sampling: CameraSampling { filter: self.pixel_filter.unwrap_or(base.sampling.filter), ..base.sampling },
            sh_storage: self.sh_storage.unwrap_or(base.sh_storage),
            ..base
        }
    }

    /// The camera, sized, and every view of --camera (none without it).
    fn choose_camera(
        &self,
        scene: &Scene,
        default_camera: Option<Camera>,
        width: u32,
        height: u32,
    ) -> Result<(Camera, Vec<(String, Camera)>)> {
        let (w, h) = (self.width.unwrap_or(width), self.height.unwrap_or(height));
        if let Some(path) = &self.camera {
            let views = load_cameras(path, self.view_options(scene))?;
            let n = views.len();
            let camera = views.get(self.camera_index).map(|(_, c)| *c).with_context(|| {
                format!("--camera-index {} but {} has {n} cameras", self.camera_index, path.display())
            })?;
            return Ok((self.sized(camera)?, views));
        }
        let camera = if let (Some(eye), Some(target)) = (self.eye, self.target) {
            Camera::look_at(eye, target, self.up.unwrap_or(Vec3::Y), self.fov, w, h)?
        } else if let Some(camera) = default_camera {
            camera
        } else {
            if self.up.is_none() && self.scene.as_deref().is_some_and(|p| !splat_io::world::is_world_file(p)) {
                eprintln!(
                    "note: no --camera: framing the scene from +z with +y up; captures trained from COLMAP data are \
                     usually -y up (--up 0,-1,0; `splat info SCENE --camera CAMERAS` measures it)"
                );
            }
            Camera::framing(&scene.robust_bounds(0.02), self.up.unwrap_or(Vec3::Y), w, h)?
        };
        Ok((self.sized(camera)?, Vec::new()))
    }

    /// `camera` at --width × --height (its own size where they are not given); an undistorted
    /// view of --camera as it is, sized before it was undistorted ([`Self::view_options`]).
    pub fn sized(&self, camera: Camera) -> Result<Camera> {
        if self.undistort.is_some() {
            return Ok(camera);
        }
        let (w, h) = (self.width.unwrap_or(camera.width), self.height.unwrap_or(camera.height));
        if w == 0 || h == 0 {
            bail!("--width and --height must be positive");
        }
        Ok(camera.rescaled(w, h)?)
    }

    /// A view to render: `camera` [`Self::sized`], refused when its images cannot fit in memory
    /// ([`check_memory`]).
    pub fn view(&self, camera: Camera) -> Result<Camera> {
        let camera = self.sized(camera)?;
        check_memory(&camera)?;
        Ok(camera)
    }

    /// A rayon pool with --threads workers.
    pub fn pool(&self) -> Result<rayon::ThreadPool> {
        let mut builder = rayon::ThreadPoolBuilder::new();
        if let Some(n) = self.threads {
            if n == 0 {
                bail!("--threads must be at least 1");
            }
            builder = builder.num_threads(n);
        }
        Ok(builder.build()?)
    }
}

/// Read a scene by extension, with the format found; say in one line which unknown `.ply`
/// properties were skipped.
pub fn read_scene(path: &std::path::Path, read: ReadArgs) -> Result<splat_io::SceneRead> {
    let read = splat_io::read_scene_with(path, read.options())?;
    warn_skipped_properties(path, &read.skipped_properties);
    print_notes(path, &read.notes);
    Ok(read)
}

/// Print what the reader noted (`splat_io::SceneRead::notes`).
pub(crate) fn print_notes(path: &std::path::Path, notes: &[String]) {
    for note in notes {
        eprintln!("note: {}", splat_io::file_note(path, note));
    }
}

/// Say which unknown `.ply` properties the reader skipped.
fn warn_skipped_properties(path: &std::path::Path, skipped: &[String]) {
    if let Some(warning) = splat_io::skipped_properties_warning(path, skipped) {
        eprintln!("warning: {warning} (--strict refuses them)");
    }
}

/// Refuse an output path whose folder does not exist, before any work: a render of minutes
/// must not fail at its last step.
pub fn check_output(path: &std::path::Path, flag: &str) -> Result<()> {
    let folder = splat_io::folder_of(path);
    if !folder.is_dir() {
        bail!("{flag} {}: the folder {} does not exist (create it first)", path.display(), folder.display());
    }
    if path.is_dir() {
        bail!("{flag} {} is a folder: give a file name", path.display());
    }
    Ok(())
}

/// Refuse a command's `outputs` (each `(flag, path)`) before any work: each as [`check_output`]
/// does, and any that is the file of another (the later would replace the earlier) or one of
/// the `inputs` the command reads (it would be lost).
pub fn check_outputs(outputs: &[(&str, &std::path::Path)], inputs: &[&std::path::Path]) -> Result<()> {
    for (i, &(flag, path)) in outputs.iter().enumerate() {
        check_output(path, flag)?;
        if let Some((other, _)) = outputs[..i].iter().find(|(_, p)| crate::same_path(p, path)) {
            bail!("{flag} {} is also {other}'s file: give each output its own path", path.display());
        }
        if let Some(input) = inputs.iter().find(|p| crate::same_path(p, path)) {
            bail!(
                "{flag} {} would replace {}, which this command reads: give another path",
                path.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Refuse a render of `camera`'s size whose images cannot fit in the memory available, with
/// the estimate: the frame loop's peak ([`splat_core::frame::BYTES_PER_PIXEL`]) and an 8-bit
/// copy for writing, per pixel.
pub fn check_memory(camera: &Camera) -> Result<()> {
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let per_pixel = splat_core::frame::BYTES_PER_PIXEL + 4;
    let need = pixels * per_pixel;
    let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
    match splat_io::memory::available() {
        Some(available) if need > available => bail!(
            "a {}×{} render needs about {:.1} GiB ({per_pixel} bytes a pixel) and {:.1} GiB of memory is available: \
             render a smaller image (--width, --height)",
            camera.width,
            camera.height,
            gib(need),
            gib(available)
        ),
        _ => Ok(()),
    }
}

/// The largest image side the commands accept: the camera's.
pub const MAX_SIDE: u32 = splat_core::camera::MAX_IMAGE_SIDE;

/// An image side in pixels: one message for every bad size (zero, negative, not a number).
pub fn parse_side(s: &str) -> Result<u32, String> {
    match s.trim().parse::<i64>() {
        Ok(n) if (1..=i64::from(MAX_SIDE)).contains(&n) => Ok(n as u32),
        _ => Err(format!("'{s}' is not an image size: give a whole number of pixels from 1 to {MAX_SIDE}")),
    }
}

/// A progress bar over `pixels` pixels (hidden when stderr is not a terminal).
pub fn progress_bar(pixels: u64) -> ProgressBar {
    ProgressBar::new(pixels).with_style(
        ProgressStyle::with_template("{spinner} rendering [{bar:40}] {percent:>3}% {elapsed} (eta {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    )
}

/// The GPU context the backend choice asks for: `None` for the CPU.
pub fn gpu_context(backend: BackendArg) -> Result<Option<splat_gpu::GpuContext>> {
    match backend {
        BackendArg::Cpu => Ok(None),
        BackendArg::Gpu => Ok(Some(splat_gpu::GpuContext::new()?)),
        BackendArg::Auto => Ok(splat_gpu::GpuContext::hardware().ok().flatten()),
    }
}
