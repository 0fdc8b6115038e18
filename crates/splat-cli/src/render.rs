//! `splat render`: one exact image of a scene.

use crate::info::load_scene;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use splat_core::normal::NormalMode;
use splat_core::raster::{Blend, FragmentDepth, RasterMethod, RasterSettings, Rasterizer, render_raster};
use splat_core::render::{RenderSettings, render_exact};
use splat_core::rng::RngScheme;
use splat_core::trace::{Frames, Method, TraceOutput, TraceScene, render_frames};
use splat_core::{Camera, HitDistance, KernelParams, Scene, scenes};
use splat_io::image::{ImageFormat, depth_for_display, normal_for_display, write_image};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Rendering method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Every hit along each ray through the BVH, sorted, composited by Eq. 3.
    Exact,
    /// The brute-force oracle: every particle tested for every pixel (no BVH), Eq. 3.
    Oracle,
    /// 3DGRT / vk multi-pass k-buffer: --k hits per pass, up to --max-passes passes.
    Kbuffer,
    /// Sun et al. Algorithm 1: one traversal, one accepted hit, one shading per ray.
    Stochastic,
    /// Sun et al. §3.5: --passes traversals of --samples samples each per frame.
    StochasticN,
    /// vk stochastic pass: --k sorted hits a pass, accepted with probability 1 − T_pass.
    StochasticPass,
    /// 3DGRT stochastic depth sampling of the first --k accepted hits (biased; a control).
    DepthSamplingK,
    /// Every particle as an opaque ellipsoid (closest hit): a mesh-like cost baseline.
    Opaque,
    /// 3DGS splatting: EWA projection, global depth sort, --blend over|under per sample (the
    /// raster oracle; under also gives iso depth and normals).
    RasterSorted,
    /// StochasticSplats: no sort, depth-tested stochastic discard, --raster-samples per pixel.
    StochasticSplat,
    /// Enderton et al. stochastic transparency: ⌊αS + ξ⌋ random samples of S per fragment.
    Enderton,
    /// Laine–Karras stratified stochastic transparency (CalcAlphaRef, surface tracking, sorting).
    Stratified,
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

/// A method of either family, as the library takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Resolved {
    /// The brute-force ray-traced oracle.
    Oracle,
    /// A ray-tracing method.
    Trace(Method),
    /// A rasterization method.
    Raster(RasterMethod),
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
    #[arg(long, default_value_t = splat_core::trace::DEFAULT_K)]
    pub k: usize,
    /// Pass limit of kbuffer and stochastic-pass.
    #[arg(long, default_value_t = splat_core::trace::DEFAULT_MAX_PASSES)]
    pub max_passes: u32,
    /// kbuffer stops when transmittance falls to this (0: never; exact up to --max-passes).
    #[arg(long, default_value_t = splat_core::trace::DEFAULT_MIN_TRANSMITTANCE)]
    pub min_transmittance: f32,
    /// stochastic-n: samples per traversal (n, up to 64).
    #[arg(long, default_value_t = 16)]
    pub samples: u32,
    /// stochastic-n: traversals per frame (m).
    #[arg(long, default_value_t = 1)]
    pub passes: u32,
    /// Generator of the stochastic decisions.
    #[arg(long, value_enum, default_value = "hash")]
    pub rng: RngArg,
    /// Raster methods: samples per pixel S (1, 2, 4, 8, 16, 32 or 64), at Hammersley positions.
    #[arg(long, default_value_t = 1)]
    pub raster_samples: u32,
    /// Raster methods: depth of each fragment.
    #[arg(long, value_enum, default_value = "center")]
    pub fragment_depth: FragmentDepthArg,
    /// raster-sorted: blend order (default under, which also yields --depth and --normal).
    #[arg(long, value_enum, default_value = "under")]
    pub blend: BlendArg,
    /// stratified: skip the multiply–XOR scramble (the correlated radical inverse that
    /// Laine–Karras warn about; biased, a negative control).
    #[arg(long)]
    pub no_scramble: bool,
}

impl MethodArg {
    /// The method's name on the command line (`stochastic-n`, …).
    pub fn name(self) -> String {
        clap::ValueEnum::to_possible_value(&self).map(|v| v.get_name().to_string()).unwrap_or_default()
    }
}

impl MethodOptions {
    /// The library method of either family for a CLI method.
    pub fn resolve(&self, m: MethodArg) -> Resolved {
        let raster = |r| Resolved::Raster(r);
        match m {
            MethodArg::Oracle => Resolved::Oracle,
            MethodArg::RasterSorted => raster(RasterMethod::Sorted {
                blend: match self.blend {
                    BlendArg::Over => Blend::Over,
                    BlendArg::Under => Blend::Under,
                },
            }),
            MethodArg::StochasticSplat => raster(RasterMethod::StochasticSplat),
            MethodArg::Enderton => raster(RasterMethod::Enderton),
            MethodArg::Stratified => raster(RasterMethod::Stratified { scramble: !self.no_scramble }),
            _ => self.method(m).map_or(Resolved::Oracle, Resolved::Trace),
        }
    }

    /// The raster settings these options describe.
    pub fn raster_settings(&self) -> RasterSettings {
        RasterSettings {
            samples: self.raster_samples,
            fragment_depth: match self.fragment_depth {
                FragmentDepthArg::Center => FragmentDepth::Center,
                FragmentDepthArg::Plane => FragmentDepth::MaxDensityPlane,
            },
        }
    }

    /// The ray-tracing method for a CLI method (`None` for the oracle and raster methods).
    pub fn method(&self, m: MethodArg) -> Option<Method> {
        Some(match m {
            MethodArg::Oracle
            | MethodArg::RasterSorted
            | MethodArg::StochasticSplat
            | MethodArg::Enderton
            | MethodArg::Stratified => return None,
            MethodArg::Exact => Method::Exact,
            MethodArg::Kbuffer => {
                Method::KBuffer { k: self.k, max_passes: self.max_passes, min_transmittance: self.min_transmittance }
            }
            MethodArg::Stochastic => Method::Stochastic,
            MethodArg::StochasticN => Method::StochasticN { m: self.passes, n: self.samples },
            MethodArg::StochasticPass => Method::StochasticPass { k: self.k, max_passes: self.max_passes },
            MethodArg::DepthSamplingK => Method::DepthSampling { k: self.k },
            MethodArg::Opaque => Method::Opaque,
        })
    }

    /// The generator.
    pub fn rng(&self) -> RngScheme {
        match self.rng {
            RngArg::Hash => RngScheme::Hash,
            RngArg::Trig => RngScheme::Trig,
        }
    }
}

/// Hit distance convention (Sun et al. §4.1).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum HitArg {
    /// Maximum density along the ray (3DGRT).
    Mean,
    /// Particle centre projected on the camera's view direction (3DGS rasterizer depth).
    Center,
}

/// Per-particle normal (seed 003 §2.4).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum NormalArg {
    /// Normal of the max-density plane, Σ⁻¹(μ − o).
    Plane,
    /// Normal of the cutoff ellipsoid where the ray enters it.
    Ellipsoid,
}

/// Scene, camera and shading options shared by `render`, `converge` and `bench`.
#[derive(Args, Clone)]
pub struct SceneArgs {
    /// Scene file (.ply or .splat). Without one, the built-in demo scene is used.
    pub scene: Option<PathBuf>,
    /// INRIA cameras.json; without it the camera frames the scene (or the demo's own camera).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Which entry of the cameras.json to use.
    #[arg(long, default_value_t = 0)]
    pub camera_index: usize,
    /// Image width; rescales the camera's intrinsics.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height; rescales the camera's intrinsics.
    #[arg(long)]
    pub height: Option<u32>,
    /// Look-at camera position "x,y,z" (with --target; world up from --up).
    #[arg(long, value_parser = parse_vec3, requires = "target")]
    pub eye: Option<Vec3>,
    /// Look-at target "x,y,z".
    #[arg(long, value_parser = parse_vec3, requires = "eye")]
    pub target: Option<Vec3>,
    /// World up "x,y,z" for --eye/--target and for framing (COLMAP captures: 0,-1,0).
    #[arg(long, value_parser = parse_vec3, default_value = "0,1,0")]
    pub up: Vec3,
    /// Vertical field of view in degrees for --eye/--target.
    #[arg(long, default_value_t = 50.0)]
    pub fov: f32,
    /// Background colour "r,g,b" behind the particles.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0")]
    pub background: Vec3,
    /// Hit distance convention.
    #[arg(long, value_enum, default_value = "mean")]
    pub hit_distance: HitArg,
    /// Per-particle normal.
    #[arg(long, value_enum, default_value = "plane")]
    pub normals: NormalArg,
    /// Kernel degree n of the generalized Gaussian exp(−4.5 (d/3)ⁿ), 1..=8.
    #[arg(long, default_value_t = splat_core::kernel::DEFAULT_DEGREE)]
    pub kernel_degree: u32,
    /// Cutoff in standard deviations (Eq. 2).
    #[arg(long, default_value_t = splat_core::kernel::DEFAULT_CUTOFF)]
    pub cutoff: f32,
    /// Iso-opacity depth threshold on transmittance.
    #[arg(long, default_value_t = splat_core::composite::DEFAULT_ISO_THRESHOLD)]
    pub iso_threshold: f32,
    /// Worker threads (default: all cores). The image does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Where rays are traced.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Skip unknown `.ply` vertex properties instead of refusing the file.
    #[arg(long)]
    pub allow_unknown_properties: bool,
}

impl SceneArgs {
    /// Load the scene (or the demo) and choose the camera; `width` × `height` is the size of
    /// a look-at or framing camera when none is given.
    pub fn load(&self, width: u32, height: u32) -> Result<(Scene, Camera)> {
        let (scene, default_camera) = match &self.scene {
            Some(path) => (load_scene(path, self.allow_unknown_properties)?, None),
            None => {
                let (scene, camera) = scenes::demo();
                (scene, Some(camera))
            }
        };
        let camera = self.choose_camera(&scene, default_camera, width, height)?;
        Ok((scene, camera))
    }

    /// The render settings these options describe.
    pub fn settings(&self) -> RenderSettings {
        RenderSettings {
            kernel: KernelParams { degree: self.kernel_degree, cutoff: self.cutoff, ..KernelParams::default() },
            hit_distance: match self.hit_distance {
                HitArg::Mean => HitDistance::Mean,
                HitArg::Center => HitDistance::Center,
            },
            normal_mode: match self.normals {
                NormalArg::Plane => NormalMode::MaxDensityPlane,
                NormalArg::Ellipsoid => NormalMode::KernelEllipsoid,
            },
            background: self.background,
            iso_threshold: self.iso_threshold,
            ..RenderSettings::default()
        }
    }

    fn choose_camera(&self, scene: &Scene, default_camera: Option<Camera>, width: u32, height: u32) -> Result<Camera> {
        let (w, h) = (self.width.unwrap_or(width), self.height.unwrap_or(height));
        let camera = if let Some(path) = &self.camera {
            let cameras = splat_io::cameras::read_cameras(path)?;
            let n = cameras.len();
            *cameras.get(self.camera_index).with_context(|| {
                format!("{}: --camera-index {} but the file has {n} cameras", path.display(), self.camera_index)
            })?
        } else if let (Some(eye), Some(target)) = (self.eye, self.target) {
            Camera::look_at(eye, target, self.up, self.fov, w, h)?
        } else if let Some(camera) = default_camera {
            camera
        } else {
            Camera::framing(&scene.robust_bounds(0.02), self.up, w, h)?
        };
        let (w, h) = (self.width.unwrap_or(camera.width), self.height.unwrap_or(camera.height));
        if w == 0 || h == 0 {
            bail!("--width and --height must be positive");
        }
        Ok(camera.rescaled(w, h)?)
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

/// Arguments of `splat render`.
#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output image; the format follows the extension: .png (8-bit), .exr or .npy (f32).
    #[arg(short, long, default_value = "render.png")]
    pub output: PathBuf,
    /// Rendering method.
    #[arg(long, value_enum, default_value = "exact")]
    pub method: MethodArg,
    /// Frames (samples per pixel) averaged; stochastic methods converge as 1/√spp.
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Seed of the random stream: the same seed gives the same image, two seeds independent ones.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Also write the per-frame variance of the radiance (.exr or .npy recommended).
    #[arg(long)]
    pub variance: Option<PathBuf>,
    /// Also write the overall opacity 1 − T (.png, .exr or .npy).
    #[arg(long)]
    pub alpha: Option<PathBuf>,
    /// Also write the iso-opacity depth (NaN where none; PNG is normalised near = bright).
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Also write the integrated unit normal (PNG maps n to n/2 + 1/2).
    #[arg(long)]
    pub normal: Option<PathBuf>,
    #[command(flatten)]
    pub options: MethodOptions,
}

fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> =
        s.split(',').map(|c| c.trim().parse::<f32>()).collect::<Result<_, _>>().map_err(|e| format!("'{s}': {e}"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("'{s}' is not three finite numbers x,y,z")),
    }
}

/// Run `splat render`.
pub fn run(args: RenderArgs) -> Result<()> {
    let outputs =
        [Some(&args.output), args.alpha.as_ref(), args.depth.as_ref(), args.normal.as_ref(), args.variance.as_ref()];
    for path in outputs.into_iter().flatten() {
        ImageFormat::from_path(path)?;
    }
    let (scene, camera) = args.scene.load(640, 480)?;
    let settings = args.scene.settings();
    let pool = args.scene.pool()?;
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let bar = progress_bar(pixels);
    let start = Instant::now();
    let out = pool.install(|| render(&args, &scene, &camera, &settings, &|n| bar.inc(n)))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    write_outputs(&args, &out)?;
    eprintln!(
        "rendered {} particles at {}×{}, {:?}, {} spp in {seconds:.2} s → {}",
        scene.particles.len(),
        camera.width,
        camera.height,
        args.method,
        args.spp,
        args.output.display()
    );
    Ok(())
}

/// A progress bar over `pixels` pixels (hidden when stderr is not a terminal).
pub fn progress_bar(pixels: u64) -> ProgressBar {
    ProgressBar::new(pixels).with_style(
        ProgressStyle::with_template("{spinner} rendering [{bar:40}] {percent:>3}% {elapsed} (eta {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    )
}

/// Render with the chosen method: the brute-force oracle, the BVH tracer over frames, or the
/// GPU kernels.
fn render(
    args: &RenderArgs,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput> {
    let method = match args.options.resolve(args.method) {
        Resolved::Trace(method) => method,
        Resolved::Raster(method) => {
            let gpu_method = matches!(method, RasterMethod::Sorted { .. } | RasterMethod::StochasticSplat);
            if args.scene.backend == BackendArg::Gpu && !gpu_method {
                bail!(
                    "{:?} rasterizes on the CPU only: use --backend cpu (the GPU rasterizes raster-sorted and stochastic-splat)",
                    args.method
                );
            }
            if gpu_method && let Some(ctx) = gpu_context(args.scene.backend)? {
                return raster_gpu(args, &ctx, scene, camera, settings, &method, progress);
            }
            let raster = Rasterizer::new(scene, camera, *settings, args.options.raster_settings())?;
            let frames = Frames { count: args.spp, seed: args.seed, rng: args.options.rng() };
            return Ok(render_raster(&raster, &method, &frames, progress)?.frames);
        }
        Resolved::Oracle => return oracle(args, scene, camera, settings, progress),
    };
    let trace = TraceScene::new(scene, *settings)?;
    let frames = Frames { count: args.spp, seed: args.seed, rng: args.options.rng() };
    if let Some(ctx) = gpu_context(args.scene.backend)? {
        if args.depth.is_some() || args.normal.is_some() {
            bail!("--depth and --normal are produced by the CPU backend only: add --backend cpu");
        }
        eprintln!("tracing on {}", ctx.describe());
        let gpu_scene = splat_gpu::GpuScene::new(&ctx, &trace)?;
        let out = splat_gpu::render(&ctx, &gpu_scene, &trace, camera, &method, &frames)?;
        progress(u64::from(camera.width) * u64::from(camera.height));
        let nan = splat_core::Image::filled(camera.width, camera.height, 1, f32::NAN);
        let zero = splat_core::Image::filled(camera.width, camera.height, 3, 0.0);
        return Ok(TraceOutput { mean: out.mean, variance: out.variance, alpha: out.alpha, depth: nan, normal: zero });
    }
    Ok(render_frames(&trace, camera, &method, &frames, progress)?)
}

/// A raster method on the GPU: sorted splatting or StochasticSplats through the render
/// pipeline; `--depth` of sorted splatting from the compute tile rasterizer.
fn raster_gpu(
    args: &RenderArgs,
    ctx: &splat_gpu::GpuContext,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    method: &RasterMethod,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput> {
    splat_gpu::raster::check_settings(&args.options.raster_settings())?;
    let sorted = matches!(method, RasterMethod::Sorted { .. });
    if args.normal.is_some() || (args.depth.is_some() && !sorted) {
        bail!("on the GPU, --depth comes from raster-sorted only and --normal from the CPU backend: add --backend cpu");
    }
    eprintln!("rasterizing on {}", ctx.describe());
    let pipes = splat_gpu::RasterPipelines::new(ctx)?;
    let gpu_scene = splat_gpu::RasterScene::new(ctx, scene, settings)?;
    let raster = splat_gpu::GpuRasterizer::new(ctx, &pipes, &gpu_scene, camera)?;
    let frames = Frames { count: args.spp, seed: args.seed, rng: args.options.rng() };
    let out = raster.render(method, &frames)?;
    let depth = match &args.depth {
        Some(_) => {
            let pick = raster.depth_pick()?;
            let data = pick.depth.iter().map(|d| d.unwrap_or(f32::NAN)).collect();
            splat_core::Image::from_data(camera.width, camera.height, 1, data).context("depth image")?
        }
        None => splat_core::Image::filled(camera.width, camera.height, 1, f32::NAN),
    };
    progress(u64::from(camera.width) * u64::from(camera.height));
    let normal = splat_core::Image::filled(camera.width, camera.height, 3, 0.0);
    Ok(TraceOutput { mean: out.mean, variance: out.variance, alpha: out.alpha, depth, normal })
}

/// The brute-force oracle (CPU only).
fn oracle(
    args: &RenderArgs,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput> {
    if args.scene.backend == BackendArg::Gpu {
        bail!("the brute-force oracle runs on the CPU only: use --method exact on the GPU");
    }
    let out = render_exact(scene, camera, settings, progress)?;
    let variance = splat_core::Image::filled(camera.width, camera.height, 3, 0.0);
    Ok(TraceOutput { mean: out.radiance, variance, alpha: out.alpha, depth: out.depth, normal: out.normal })
}

/// The GPU context the backend choice asks for: `None` for the CPU.
pub fn gpu_context(backend: BackendArg) -> Result<Option<splat_gpu::GpuContext>> {
    match backend {
        BackendArg::Cpu => Ok(None),
        BackendArg::Gpu => Ok(Some(splat_gpu::GpuContext::new()?)),
        BackendArg::Auto => {
            Ok(splat_gpu::GpuContext::new().ok().filter(|c| c.info.device_type != splat_gpu::wgpu::DeviceType::Cpu))
        }
    }
}

fn write_outputs(args: &RenderArgs, out: &TraceOutput) -> Result<()> {
    write_image(&args.output, &out.mean)?;
    if let Some(path) = &args.variance {
        write_image(path, &out.variance)?;
    }
    if let Some(path) = &args.alpha {
        write_image(path, &out.alpha)?;
    }
    if let Some(path) = &args.depth {
        write_image(path, &display_if_png(path, &out.depth, depth_for_display))?;
    }
    if let Some(path) = &args.normal {
        write_image(path, &display_if_png(path, &out.normal, normal_for_display))?;
    }
    Ok(())
}

/// PNG is for looking at: map data to a viewable range; float formats keep the raw values.
fn display_if_png(
    path: &Path,
    image: &splat_core::Image,
    to_display: fn(&splat_core::Image) -> splat_core::Image,
) -> splat_core::Image {
    match ImageFormat::from_path(path) {
        Ok(ImageFormat::Png) => to_display(image),
        _ => image.clone(),
    }
}
