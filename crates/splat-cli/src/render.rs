//! `splat render`: one image of a scene, read as four steps: resolve the method, choose the
//! backend, render, write.

use crate::args::{BackendArg, MethodOptions, SceneArgs, Staged, method_parser, progress_bar};
use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::frame::{Frames, Progress, RenderOutput};
use splat_core::mesh::Meshes;
use splat_core::path::sampler::SamplerKind;
use splat_core::path::{Environment, GaussianEstimator, PathSettings, PathTracer};
use splat_core::raster::Response;
use splat_core::trace::TraceScene;
use splat_core::trainer::Preset;
use splat_core::{Algorithm, Camera, MethodId, ScreenFilter, World};
use splat_gpu::{GpuContext, GpuTracer};
use splat_io::image::{ImageFormat, Single, depth_for_display, normal_for_display, write_image, write_image_as};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `splat render`.
#[derive(Args)]
pub struct RenderArgs {
    /// Output image; the format follows the extension: .png (8-bit), .exr or .npy (f32). With
    /// --all-cameras, the folder to write the views into.
    #[arg(help_heading = "Output", short, long, default_value = "render.png")]
    pub output: PathBuf,
    /// Render every camera of --camera (a cameras.json or COLMAP model) into the folder -o,
    /// one image per view named after its image (.png unless --view-format says otherwise).
    #[arg(help_heading = "Output", long, requires = "camera")]
    pub all_cameras: bool,
    /// Image format of --all-cameras views.
    #[arg(help_heading = "Output", long, value_enum, default_value = "png", requires = "all_cameras")]
    pub view_format: ViewFormat,
    /// With --all-cameras, render share I of N of the views (0 ≤ I < N): every view whose index
    /// is I modulo N, named as in the whole set, so that the N tasks of a job array fill one
    /// folder together.
    #[arg(help_heading = "Output", long, value_parser = parse_shard, requires = "all_cameras")]
    pub shard: Option<(usize, usize)>,
    /// Also write the per-frame variance of the radiance (.exr or .npy recommended).
    #[arg(help_heading = "Output", long)]
    pub variance: Option<PathBuf>,
    /// Also write the overall opacity 1 − T (.png, .exr or .npy).
    #[arg(help_heading = "Output", long)]
    pub alpha: Option<PathBuf>,
    /// Also write the iso-opacity depth (NaN where none; PNG is normalised near = bright).
    #[arg(help_heading = "Output", long)]
    pub depth: Option<PathBuf>,
    /// Also write the integrated unit normal (PNG maps n to n/2 + 1/2).
    #[arg(help_heading = "Output", long)]
    pub normal: Option<PathBuf>,
    /// Rendering method (default: exact; raster-sorted with --pipeline raster or hybrid).
    #[arg(help_heading = "Method", long, value_parser = method_parser())]
    pub method: Option<MethodId>,
    /// Pipeline for a world with meshes: rt ray traces splats and meshes (mirror and glass
    /// bounces), raster splats in three passes (mesh depth, splats front to back, meshes under
    /// them), hybrid rasterizes the first hit and ray traces shadows and bounces from it.
    /// Without it, --method decides.
    #[arg(help_heading = "Method", long, value_enum)]
    pub pipeline: Option<PipelineArg>,
    /// Ray-tracing method of the hybrid pipeline's shadow and bounce rays.
    #[arg(help_heading = "Method", long, value_parser = method_parser(), default_value = "exact")]
    pub secondary: MethodId,
    /// Frames (samples per pixel) averaged; stochastic methods converge as 1/√spp.
    #[arg(help_heading = "Method", long, default_value_t = 1)]
    pub spp: u32,
    /// Seed of the random stream: the same seed gives the same image, two seeds independent ones.
    #[arg(help_heading = "Method", long, default_value_t = 0)]
    pub seed: u32,
    /// Render frames A..B (A included, B not) of the run seeded by --seed, a share of it (one
    /// task of a job array), each frame with the decisions it has in the whole run, and write
    /// their accumulation (mean, variance, alpha, frame range) to -o PART.acc for `splat
    /// merge`.
    #[arg(help_heading = "Method", long, value_parser = parse_frame_range, conflicts_with_all = ["spp", "all_cameras"])]
    pub frames: Option<(u32, u32)>,
    /// The scene, camera and shading.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The method's parameters.
    #[command(flatten)]
    pub options: MethodOptions,
    /// The path tracer's options.
    #[command(flatten)]
    pub path: PathOptions,
}

/// Options of the path tracer (`--pipeline path`).
#[derive(Args, Debug)]
#[command(next_help_heading = "Path tracer")]
pub struct PathOptions {
    /// Path tracer: most bounces off meshes.
    #[arg(long, default_value_t = splat_core::path::DEFAULT_MAX_DEPTH)]
    pub max_depth: u32,
    /// Path tracer: Russian roulette on the throughput after this many bounces.
    #[arg(long, default_value_t = 3)]
    pub roulette_depth: u32,
    /// Path tracer: Owen-scrambled Sobol (one sequence per pixel) or the counter-based hash.
    #[arg(long, value_enum, default_value = "sobol")]
    pub sampler: SamplerArg,
}

/// The path tracer's generator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SamplerArg {
    /// Owen-scrambled Sobol (Burley 2020).
    Sobol,
    /// The counter-based hash (independent frames).
    Hash,
}

/// Image format of the --all-cameras views.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewFormat {
    /// 8-bit PNG.
    Png,
    /// 32-bit float OpenEXR.
    Exr,
    /// 32-bit float NumPy array.
    Npy,
}

/// Run `splat render`.
pub fn run(mut args: RenderArgs) -> Result<()> {
    if args.all_cameras {
        return run_all_cameras(args);
    }
    if args.frames.is_some() {
        return run_share(args);
    }
    let files = outputs(&args);
    for (_, path) in &files {
        ImageFormat::from_path(path)?;
    }
    crate::args::check_outputs(&files, &args.scene.inputs())?;
    let staged = args.scene.load_world(640, 480)?;
    args.options.apply_capture(&staged.world.scene);
    let args = args;
    crate::args::check_memory(&staged.camera)?;
    if args.pipeline == Some(PipelineArg::Path) {
        return run_path(&args, &staged);
    }
    let Staged { world: World { scene, lighting, meshes }, camera, .. } = &staged;
    let bar = progress_bar(u64::from(camera.width) * u64::from(camera.height));
    let start = Instant::now();
    let Rendered { out, algorithm, .. } = render_frames(&args, &staged, extras(&args), &|n| bar.inc(n))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    write_outputs(&args, &out)?;
    eprintln!(
        "rendered {} particles at {}×{}, {}, {} in {seconds:.2} s → {}",
        scene.particles.len(),
        camera.width,
        camera.height,
        describe(&args),
        frames_done(args.spp, algorithm.is_random(lighting, !meshes.is_empty(), &staged.settings.sampling)),
        written(&args)
    );
    if args.scene.camera.is_some() && shows_nothing(&out) {
        eprintln!("note: the view shows none of the splats (coverage under 1 % at every pixel). {ANOTHER_WORLD}");
    }
    Ok(())
}

/// Whether a render shows none of the splats: coverage under 1 % at every pixel.
fn shows_nothing(out: &RenderOutput) -> bool {
    out.alpha.data().iter().all(|&a| a < 0.01)
}

/// Why the views of a camera file may show none of the splats, and what to do.
const ANOTHER_WORLD: &str = "Splats trained by gsplat (normalize_world_space, its default), by 3DGRUT with it, or by \
                             Nerfstudio lie in a normalised world of their own, not the camera file's: `splat info \
                             SCENE --camera CAMERAS` names the world a COLMAP model's splats lie in, and \
                             --gsplat-world or --dataparser-transforms moves the cameras there, as does \
                             --world-transform FILE with the run's own matrix (such as gsplat's parser.transform)";

/// `splat render --frames A..B`: one share of a run, written as an accumulation file.
fn run_share(mut args: RenderArgs) -> Result<()> {
    if splat_io::extension(&args.output).as_deref() != Some("acc") {
        bail!(
            "--frames writes the share's accumulation (mean, variance, alpha, frame range): give -o PART.acc, \
             and merge the shares into images with `splat merge`"
        );
    }
    if args.alpha.is_some() || args.depth.is_some() || args.normal.is_some() || args.variance.is_some() {
        bail!(
            "--frames writes one accumulation file: drop --alpha, --depth, --normal and --variance (`splat merge` writes them)"
        );
    }
    crate::args::check_outputs(&[("-o", &args.output)], &args.scene.inputs())?;
    let staged = args.scene.load_world(640, 480)?;
    args.options.apply_capture(&staged.world.scene);
    let args = args;
    crate::args::check_memory(&staged.camera)?;
    let bar = progress_bar(u64::from(staged.camera.width) * u64::from(staged.camera.height));
    let start = Instant::now();
    let share = render_share(&args, &staged, &|n| bar.inc(n))?;
    bar.finish_and_clear();
    splat_io::accumulation::write(&args.output, &share)?;
    let a = &share.accumulation;
    eprintln!(
        "rendered frames {}..{} of seed {} ({}) in {:.2} s → {}",
        a.first,
        u64::from(a.first) + u64::from(a.count),
        args.seed,
        describe(&args),
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    Ok(())
}

/// The share of the run that `args` (with `--frames`) render: its accumulation and the
/// description that shares of one run have in common.
pub fn render_share(args: &RenderArgs, staged: &Staged, progress: Progress) -> Result<splat_io::accumulation::Share> {
    let frames = args.frames();
    let (out, count, method) = if args.pipeline == Some(PipelineArg::Path) {
        (render_path(args, staged, progress)?.0, frames.count, path_description(args)?)
    } else {
        let Rendered { out, algorithm, count, .. } =
            render_frames(args, staged, splat_gpu::Extras::default(), progress)?;
        (out, count, format!("{algorithm:?}"))
    };
    let render = run_description(args, staged, &staged.camera, &method);
    Ok(splat_io::accumulation::Share {
        accumulation: splat_core::frame::Accumulation::of(&out, &frames, count),
        render,
    })
}

/// The path tracer's part of a [`run_description`].
pub fn path_description(args: &RenderArgs) -> Result<String> {
    let gaussians = gaussian_estimator(args.method.unwrap_or(MethodId::Stochastic), &args.options)?;
    Ok(format!("path tracer {:?}, Gaussians {gaussians:?}", args.path))
}

/// Everything that decides the frames of a run besides their range, for `method` (the
/// algorithm, or the path tracer's [`path_description`]): equal for shares of one run
/// ([`crate::merge`]), through `camera` (the staged one, or one of [`render_views`]' views).
pub fn run_description(args: &RenderArgs, staged: &Staged, camera: &Camera, method: &str) -> String {
    let frames = args.frames();
    format!(
        "{method}; settings {:?}; camera {:?}; {} splats, {} triangles; seed {}, {:?}, {:?}",
        staged.settings,
        camera,
        staged.world.scene.particles.len(),
        staged.world.meshes.triangles().len(),
        frames.seed,
        frames.rng,
        frames.accumulation
    )
}

impl RenderArgs {
    /// The frames to render: `--frames A..B`, else `--spp` from frame 0, of the run seeded by
    /// `--seed`.
    pub fn frames(&self) -> Frames {
        let (first, count) = self.frames.map_or((0, self.spp), |(a, b)| (a, b - a));
        Frames { first, ..self.options.frames(count, self.seed) }
    }
}

/// A range of frames "A..B" with A < B.
fn parse_frame_range(s: &str) -> Result<(u32, u32), String> {
    let parse = |v: &str| v.trim().parse::<u32>().ok();
    match s.split_once("..").map(|(a, b)| (parse(a), parse(b))) {
        Some((Some(a), Some(b))) if a < b => Ok((a, b)),
        _ => Err(format!("'{s}' is not a range of frames: give A..B with whole numbers A < B (A included, B not)")),
    }
}

/// A share "I/N" of a set: 0 ≤ I < N.
fn parse_shard(s: &str) -> Result<(usize, usize), String> {
    let parse = |v: &str| v.trim().parse::<usize>().ok();
    match s.split_once('/').map(|(i, n)| (parse(i), parse(n))) {
        Some((Some(i), Some(n))) if i < n => Ok((i, n)),
        _ => Err(format!("'{s}' is not a share: give I/N with whole numbers 0 ≤ I < N (task I of N)")),
    }
}

/// What [`render_frames`] made, and how.
pub struct Rendered {
    /// The images.
    pub out: RenderOutput,
    /// The algorithm that made them (the GPU's variant where it ran there).
    pub algorithm: Algorithm,
    /// Frames averaged: the frames asked for, or one where every frame is the same (a
    /// deterministic method through a still camera).
    pub count: u32,
    /// The GPU adapter it ran on, described; `None` for the CPU.
    pub gpu: Option<String>,
}

/// Render `staged` as `args` say, on the backend they choose, with `extras` where that is the
/// GPU (the CPU always makes every image), calling `progress` with pixels done on the CPU: one
/// view, [`render_views`] of the staged camera. `args.options` must have had the capture's
/// implications applied ([`MethodOptions::apply_capture`]); the path tracer goes through
/// [`render_path`].
pub fn render_frames(
    args: &RenderArgs,
    staged: &Staged,
    extras: splat_gpu::Extras,
    progress: Progress,
) -> Result<Rendered> {
    let mut one = None;
    render_views(args, staged, [staged.camera], extras, progress, |_, rendered| {
        one = Some(rendered);
        Ok(())
    })?;
    one.context("a view was rendered")
}

/// Render `staged`'s world through each of `cameras` as `args` say, on the backend they choose:
/// the world is prepared once (the BVH; on the GPU also its device arrays and pipelines,
/// `splat_gpu::render_views`) and `each(i, rendered)` receives view i's images in order, as
/// soon as it is rendered (so `cameras` may be a channel that a caller feeds view by view).
/// `progress` counts a CPU render's pixels over all the views.
pub fn render_views(
    args: &RenderArgs,
    staged: &Staged,
    cameras: impl IntoIterator<Item = Camera, IntoIter: Send>,
    extras: splat_gpu::Extras,
    progress: Progress,
    mut each: impl FnMut(usize, Rendered) -> Result<()> + Send,
) -> Result<()> {
    let cpu_algorithm = algorithm(args)?;
    warn_unused(args, &cpu_algorithm, staged);
    let frames = args.frames();
    let gpu_algorithm = args.options.on_gpu(cpu_algorithm);
    let gpu = choose_gpu(args, &gpu_algorithm, &staged.world.meshes, extras)?;
    let algorithm = if gpu.is_some() { gpu_algorithm } else { cpu_algorithm };
    let World { lighting, meshes, .. } = &staged.world;
    let random = algorithm.is_random(lighting, !meshes.is_empty(), &staged.settings.sampling);
    let count = if random { frames.count } else { 1 };
    let adapter = gpu.as_ref().map(GpuContext::describe);
    let mut cameras = cameras.into_iter();
    let mut views = |render: &dyn Fn(&Camera) -> Result<RenderOutput>| -> Result<()> {
        for (i, camera) in cameras.by_ref().enumerate() {
            let out = render(&camera)?;
            each(i, Rendered { out, algorithm, count, gpu: adapter.clone() })?;
        }
        Ok(())
    };
    match &gpu {
        Some(ctx) => {
            eprintln!("rendering on {}", ctx.describe());
            splat_gpu::render_views(ctx, &algorithm, &staged.shot(), extras, |render| {
                views(&|camera| Ok(render(camera, &frames)?))
            })?
        }
        None => args.scene.pool()?.install(|| {
            algorithm.render_views(&staged.shot(), |render| views(&|camera| Ok(render(camera, &frames, progress)?)))
        })?,
    }
}

/// The images `splat render` writes, with their flags: colour first.
fn outputs(args: &RenderArgs) -> Vec<(&'static str, &Path)> {
    let extra = [("--alpha", &args.alpha), ("--depth", &args.depth), ("--normal", &args.normal)];
    let extra = extra.into_iter().chain([("--variance", &args.variance)]);
    let extra = extra.filter_map(|(flag, p)| p.as_deref().map(|p| (flag, p)));
    std::iter::once(("-o", args.output.as_path())).chain(extra).collect()
}

/// The files written, for the summary line.
fn written(args: &RenderArgs) -> String {
    outputs(args).iter().map(|(_, p)| p.display().to_string()).collect::<Vec<_>>().join(", ")
}

/// How many frames a render of `spp` averaged: one for a deterministic render, whatever
/// `--spp` asked.
fn frames_done(spp: u32, random: bool) -> String {
    match (random, spp) {
        (true, _) => format!("{spp} spp"),
        (false, 1) => "1 frame (deterministic)".into(),
        (false, _) => format!("1 frame (deterministic: --spp {spp} adds nothing)"),
    }
}

/// Say which options given on the command line the chosen method does not read, one warning
/// line each, so that nothing is ignored silently.
fn warn_unused(args: &RenderArgs, algorithm: &Algorithm, staged: &Staged) {
    for flag in args.options.unused(algorithm) {
        eprintln!("warning: {flag} does not apply to {}: ignored", describe(args));
    }
    if args.pipeline != Some(PipelineArg::Hybrid) && args.secondary != MethodId::Exact {
        eprintln!("warning: --secondary applies to --pipeline hybrid: ignored");
    }
    let splats = matches!(algorithm, Algorithm::Raster(..) | Algorithm::Hybrid(..));
    let splatting_only = [
        ("--near-plane", args.scene.near_plane.is_some()),
        ("--raster-iso-threshold", args.scene.raster_iso_threshold.is_some()),
    ];
    for (flag, _) in splatting_only.into_iter().filter(|&(_, given)| given && !splats) {
        eprintln!("warning: {flag} applies to the splatting methods, not to {}: ignored", describe(args));
    }
    let projected = args.options.raster_settings().response == Response::Projected;
    if splats && projected && staged.world.scene.is_surfels() {
        eprintln!(
            "note: the capture holds 2D Gaussians (2DGS), which {} projects as flat ellipses (EWA's affine \
             approximation) with --response projected; along-ray evaluates them at their ray–splat intersection",
            describe(args)
        );
    }
    let ray_evaluated = [Preset::ThreeDgrt, Preset::ThreeDgut, Preset::TwoDgs];
    let preset = args.scene.read.preset.or(staged.world.scene.trained.map(|t| t.preset));
    if let Some(preset) = preset.filter(|p| splats && ray_evaluated.contains(p)) {
        if projected {
            eprintln!(
                "note: {} evaluates its particles along each ray, which --response along-ray and the ray-tracing \
                 methods do; {} with --response projected approximates them by projected ellipses",
                preset.name(),
                describe(args)
            );
        } else if preset == Preset::ThreeDgrt {
            eprintln!(
                "note: 3DGRT composites each ray's hits in their own order, as the ray-tracing methods do; {} \
                 composites them in the global depth order of their centres (3DGUT's)",
                describe(args)
            );
        }
    }
    let filter = staged.world.scene.screen_filter;
    if filter != ScreenFilter::Dilation && !splats {
        eprintln!(
            "note: the capture was trained with {}, a screen-space filter that the splatting methods apply; \
             {} traces the particles themselves, without it",
            filter.describe(),
            describe(args)
        );
    }
    if staged.environment.is_some() {
        eprintln!(
            "warning: the world sets up the path tracer ([environment]): rendering with {}; \
             --pipeline path renders it path traced",
            describe(args)
        );
    }
}

/// `splat render --all-cameras`: every view of --camera into the folder -o, one progress bar
/// over the views, the GPU context (if any) made once.
fn run_all_cameras(mut args: RenderArgs) -> Result<()> {
    if args.alpha.is_some() || args.depth.is_some() || args.normal.is_some() || args.variance.is_some() {
        bail!("--all-cameras writes colour images only: drop --alpha, --depth, --normal and --variance");
    }
    let camera_file = args.scene.camera.clone().context("--all-cameras needs --camera")?;
    let mut staged = args.scene.load_world(640, 480)?;
    let cameras = std::mem::take(&mut staged.views);
    let extension = match args.view_format {
        ViewFormat::Png => "png",
        ViewFormat::Exr => "exr",
        ViewFormat::Npy => "npy",
    };
    let file = |i: usize, name: &str| args.output.join(format!("{}.{extension}", view_stem(name, i)));
    if let Some(photos) = crate::undistort::default_images(&camera_file)
        && let Some((i, name)) = cameras
            .iter()
            .map(|(n, _)| n)
            .enumerate()
            .find(|&(i, name)| crate::same_path(&file(i, name), &crate::undistort::photo_path(&photos, name)))
    {
        bail!(
            "view {i} ({name}) would be written over its photograph {}: give -o another folder",
            file(i, name).display()
        );
    }
    let sized = cameras.iter().map(|(_, camera)| args.scene.view(*camera)).collect::<Result<Vec<Camera>>>()?;
    args.options.apply_capture(&staged.world.scene);
    let args = &args;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let (share, of) = args.shard.unwrap_or((0, 1));
    let mine: Vec<(usize, &String)> =
        cameras.iter().enumerate().filter(|(i, _)| i % of == share).map(|(i, (name, _))| (i, name)).collect();
    let views: Vec<Camera> = mine.iter().map(|&(i, _)| sized[i]).collect();
    let bar = indicatif::ProgressBar::new(mine.len() as u64).with_style(
        indicatif::ProgressStyle::with_template("{spinner} views [{bar:40}] {pos}/{len} {elapsed} (eta {eta}) {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let start = Instant::now();
    let empty = std::sync::atomic::AtomicUsize::new(0);
    let write = |k: usize, out: &RenderOutput| -> Result<()> {
        let (i, name) = mine[k];
        write_image(&file(i, name), &out.mean)?;
        if shows_nothing(out) {
            empty.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        bar.set_message(name.clone());
        bar.inc(1);
        Ok(())
    };
    let random = if args.pipeline == Some(PipelineArg::Path) {
        render_path_views(args, &staged, views.iter().copied(), &|_| {}, |k, out, _| write(k, &out))?;
        true
    } else {
        let mut algorithm = None;
        render_views(args, &staged, views.iter().copied(), extras(args), &|_| {}, |k, rendered| {
            algorithm = Some(rendered.algorithm);
            write(k, &rendered.out)
        })?;
        let World { lighting, meshes, .. } = &staged.world;
        algorithm.is_some_and(|a| a.is_random(lighting, !meshes.is_empty(), &staged.settings.sampling))
    };
    bar.finish_and_clear();
    eprintln!(
        "rendered {}, {}, {} in {:.2} s → {}",
        crate::counted(mine.len(), "view"),
        describe(args),
        frames_done(args.spp, random),
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    if !mine.is_empty() && empty.into_inner() == mine.len() {
        eprintln!(
            "note: none of the views shows any of the splats (coverage under 1 % at every pixel). {ANOTHER_WORLD}"
        );
    }
    Ok(())
}

/// File stem of view `index` named `name`: the image name without its extension and folders,
/// or `view_0007` when the camera file names none.
pub(crate) fn view_stem(name: &str, index: usize) -> String {
    let stem = Path::new(name).file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let clean: String = stem.chars().map(|c| if c.is_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
    if clean.is_empty() { format!("view_{index:04}") } else { clean }
}

/// A rendering pipeline (vk_gaussian_splatting Lighting §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PipelineArg {
    /// Ray tracing: every method of the ray-tracing family.
    Rt,
    /// Rasterization: every splatting method, meshes composited in three passes.
    Raster,
    /// Rasterized first hit, ray-traced shadows and bounces.
    Hybrid,
    /// Monte Carlo path tracing: Gaussians by --method stochastic (default), stochastic-n,
    /// exact or depth-sampling-k (CPU only) at every segment, meshes by their BSDFs.
    Path,
}

/// The Gaussian estimator of the path tracer that `--method` names.
pub fn gaussian_estimator(method: MethodId, options: &MethodOptions) -> Result<GaussianEstimator> {
    GaussianEstimator::of(method, &options.parameters()).with_context(|| {
        let names: Vec<&str> = GaussianEstimator::methods().map(MethodId::name).collect();
        format!("--method {} is not a Gaussian estimator of the path tracer: use {}", method.name(), names.join(", "))
    })
}

/// The path tracer's settings from its options and the world, with `gaussians`.
pub fn path_options_settings(o: &PathOptions, staged: &Staged, gaussians: GaussianEstimator) -> Result<PathSettings> {
    let settings = PathSettings {
        max_depth: o.max_depth,
        roulette_depth: o.roulette_depth,
        gaussians,
        sampler: match o.sampler {
            SamplerArg::Sobol => SamplerKind::Sobol,
            SamplerArg::Hash => SamplerKind::Hash,
        },
        environment: staged.environment.unwrap_or(Environment::Constant(staged.settings.background)),
    };
    settings.validate()?;
    Ok(settings)
}

/// `splat render --pipeline path`: the Monte Carlo path tracer, on the CPU or the GPU.
fn run_path(args: &RenderArgs, staged: &Staged) -> Result<()> {
    if args.depth.is_some() || args.normal.is_some() || args.alpha.is_some() {
        bail!("the path tracer writes colour and --variance only (no --depth, --normal or --alpha)");
    }
    let Staged { world: World { scene, meshes, .. }, camera, .. } = staged;
    let bar = progress_bar(u64::from(camera.width) * u64::from(camera.height));
    let start = Instant::now();
    let (out, _) = render_path(args, staged, &|n| bar.inc(n))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    write_outputs(args, &out)?;
    eprintln!(
        "path traced {} particles and {} triangles at {}×{}, {} Gaussians, {} spp in {seconds:.2} s → {}",
        scene.particles.len(),
        meshes.triangles().len(),
        camera.width,
        camera.height,
        args.method.unwrap_or(MethodId::Stochastic).name(),
        args.spp,
        args.output.display()
    );
    Ok(())
}

/// The Monte Carlo path tracer's render of `staged` as `args` say (`--pipeline path`), on the
/// CPU (calling `progress` with pixels done) or the GPU: colour and variance, and the GPU
/// adapter it ran on, described (`None` for the CPU). One view, [`render_path_views`] of the
/// staged camera.
pub fn render_path(args: &RenderArgs, staged: &Staged, progress: Progress) -> Result<(RenderOutput, Option<String>)> {
    let mut one = None;
    render_path_views(args, staged, [staged.camera], progress, |_, out, gpu| {
        one = Some((out, gpu.clone()));
        Ok(())
    })?;
    one.context("a view was rendered")
}

/// The path tracer's renders of `staged`'s world through each of `cameras`, as [`render_views`]
/// renders the splat methods': the world prepared once (the BVH and the emitters; on the GPU
/// the device arrays and the kernel), `each(i, out, gpu)` given view i's colour and variance
/// as soon as it is rendered, and the GPU adapter it ran on, described (`None` for the CPU);
/// `progress` counts a CPU render's pixels over all the views.
pub fn render_path_views(
    args: &RenderArgs,
    staged: &Staged,
    cameras: impl IntoIterator<Item = Camera>,
    progress: Progress,
    mut each: impl FnMut(usize, RenderOutput, &Option<String>) -> Result<()>,
) -> Result<()> {
    let gaussians = gaussian_estimator(args.method.unwrap_or(MethodId::Stochastic), &args.options)?;
    let settings = path_options_settings(&args.path, staged, gaussians)?;
    let Staged { world: World { scene, lighting, meshes }, settings: render_settings, .. } = staged;
    let frames = Frames { rng: splat_core::rng::RngScheme::Hash, ..args.frames() };
    let gpu = match args.scene.backend {
        BackendArg::Gpu => crate::args::gpu_context(BackendArg::Gpu)?,
        BackendArg::Auto if !matches!(gaussians, GaussianEstimator::DepthSampling { .. }) => {
            crate::args::gpu_context(BackendArg::Auto)?
        }
        _ => None,
    };
    if let Some(ctx) = &gpu {
        // A scene the GPU cannot bind is refused before its BVH is built.
        splat_gpu::TraceSplit::at_least(ctx, scene, render_settings)?;
    }
    let trace = TraceScene::new(scene, *render_settings)?.with_lighting(lighting)?.with_meshes(meshes);
    let views = cameras.into_iter().enumerate();
    let adapter = gpu.as_ref().map(GpuContext::describe);
    match &gpu {
        Some(ctx) => {
            eprintln!("rendering on {}", ctx.describe());
            let pipeline = splat_gpu::TracePipeline::new(ctx)?;
            let tracer = GpuTracer::new(ctx, &pipeline, &trace)?;
            for (i, camera) in views {
                each(i, tracer.render_path(&camera, &settings, &frames)?.0, &adapter)?;
            }
        }
        None => {
            let tracer = PathTracer::new(&trace, settings)?;
            let pool = args.scene.pool()?;
            for (i, camera) in views {
                each(i, pool.install(|| tracer.render(&camera, &frames, progress))?, &adapter)?;
            }
        }
    }
    Ok(())
}

/// The method the options name, with the pipeline's default.
fn method_arg(args: &RenderArgs) -> MethodId {
    args.method.unwrap_or(match args.pipeline {
        Some(PipelineArg::Raster | PipelineArg::Hybrid) => MethodId::RasterSorted,
        _ => MethodId::Exact,
    })
}

/// The algorithm of `--pipeline`, `--method` and `--secondary`, refusing a method of the other
/// family.
fn algorithm(args: &RenderArgs) -> Result<Algorithm> {
    let m = method_arg(args);
    let algorithm = args.options.resolve(m);
    let family = |want: &str| anyhow::anyhow!("--method {} is not a {want} method", m.name());
    match (args.pipeline, algorithm) {
        (None, a) => Ok(a),
        (Some(PipelineArg::Rt), a @ (Algorithm::Trace(_) | Algorithm::Oracle)) => Ok(a),
        (Some(PipelineArg::Rt), _) => Err(family("ray-tracing")),
        (Some(PipelineArg::Raster), a @ Algorithm::Raster(..)) => Ok(a),
        (Some(PipelineArg::Raster), _) => Err(family("raster")),
        (Some(PipelineArg::Hybrid), Algorithm::Raster(method, raster)) => {
            let secondary = args.options.method(args.secondary).context("--secondary")?;
            Ok(Algorithm::Hybrid(method, raster, secondary))
        }
        (Some(PipelineArg::Hybrid), _) => Err(family("raster (the hybrid pipeline's first hit)")),
        (Some(PipelineArg::Path), _) => bail!("the path tracer is not an algorithm of the frame loop"),
    }
}

/// The method (and pipeline) for the summary line.
fn describe(args: &RenderArgs) -> String {
    match args.pipeline {
        Some(PipelineArg::Hybrid) => format!("hybrid {} + {}", method_arg(args).name(), args.secondary.name()),
        Some(PipelineArg::Path) => {
            format!("path tracer, {} Gaussians", args.method.unwrap_or(MethodId::Stochastic).name())
        }
        _ => method_arg(args).name().to_string(),
    }
}

/// The images besides colour that `args` asks for.
fn extras(args: &RenderArgs) -> splat_gpu::Extras {
    splat_gpu::Extras { depth: args.depth.is_some(), normal: args.normal.is_some() }
}

/// The GPU context to render on, or `None` for the CPU: `--backend gpu` insists (and fails
/// with the reason when the GPU cannot render this algorithm among these meshes), `auto` takes
/// a hardware GPU when one is found and it renders this, `cpu` never.
fn choose_gpu(
    args: &RenderArgs,
    algorithm: &Algorithm,
    meshes: &Meshes,
    extras: splat_gpu::Extras,
) -> Result<Option<GpuContext>> {
    let supported = || -> Result<(), splat_gpu::GpuError> {
        splat_gpu::supports(algorithm, extras)?;
        splat_gpu::supports_meshes(algorithm, meshes)
    };
    match args.scene.backend {
        BackendArg::Gpu => {
            supported()?;
            crate::args::gpu_context(BackendArg::Gpu)
        }
        BackendArg::Auto if supported().is_ok() => crate::args::gpu_context(BackendArg::Auto),
        BackendArg::Auto | BackendArg::Cpu => Ok(None),
    }
}

fn write_outputs(args: &RenderArgs, out: &RenderOutput) -> Result<()> {
    write_image(&args.output, &out.mean)?;
    if let Some(path) = &args.variance {
        write_image(path, &out.variance)?;
    }
    if let Some(path) = &args.alpha {
        write_image_as(path, &out.alpha, Single::Alpha)?;
    }
    if let Some(path) = &args.depth {
        write_image_as(path, &display_if_png(path, &out.depth, depth_for_display), Single::Depth)?;
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
