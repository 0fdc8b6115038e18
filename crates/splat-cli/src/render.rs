//! `splat render`: one exact image of a scene.

use crate::info::load_scene;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use splat_core::normal::NormalMode;
use splat_core::render::{RenderOutput, RenderSettings, render_exact};
use splat_core::{Camera, HitDistance, KernelParams, Scene, scenes};
use splat_io::image::{ImageFormat, depth_for_display, normal_for_display, write_image};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Rendering method.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Method {
    /// Every hit along each ray, sorted front to back, composited by Eq. 3 (the oracle).
    Exact,
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

/// Arguments of `splat render`.
#[derive(Args)]
pub struct RenderArgs {
    /// Scene file (.ply or .splat). Without one, the built-in demo scene is rendered.
    pub scene: Option<PathBuf>,
    /// Output image; the format follows the extension: .png (8-bit), .exr or .npy (f32).
    #[arg(short, long, default_value = "render.png")]
    pub output: PathBuf,
    /// Rendering method.
    #[arg(long, value_enum, default_value = "exact")]
    pub method: Method,
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
    /// World up for --eye/--target "x,y,z".
    #[arg(long, value_parser = parse_vec3, default_value = "0,1,0")]
    pub up: Vec3,
    /// Vertical field of view in degrees for --eye/--target.
    #[arg(long, default_value_t = 50.0)]
    pub fov: f32,
    /// Background colour "r,g,b" behind the particles.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0")]
    pub background: Vec3,
    /// Also write the overall opacity 1 − T (.png, .exr or .npy).
    #[arg(long)]
    pub alpha: Option<PathBuf>,
    /// Also write the iso-opacity depth (NaN where none; PNG is normalised near = bright).
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Also write the integrated unit normal (PNG maps n to n/2 + 1/2).
    #[arg(long)]
    pub normal: Option<PathBuf>,
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
    /// Skip unknown `.ply` vertex properties instead of refusing the file.
    #[arg(long)]
    pub allow_unknown_properties: bool,
}

fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| c.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("'{s}': {e}"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("'{s}' is not three finite numbers x,y,z")),
    }
}

/// Run `splat render`.
pub fn run(args: RenderArgs) -> Result<()> {
    for path in std::iter::once(&args.output)
        .chain(&args.alpha)
        .chain(&args.depth)
        .chain(&args.normal)
    {
        ImageFormat::from_path(path)?;
    }
    let (scene, default_camera) = match &args.scene {
        Some(path) => (load_scene(path, args.allow_unknown_properties)?, None),
        None => {
            let (scene, camera) = scenes::demo();
            (scene, Some(camera))
        }
    };
    let camera = choose_camera(&args, &scene, default_camera)?;
    let settings = RenderSettings {
        kernel: KernelParams {
            degree: args.kernel_degree,
            cutoff: args.cutoff,
            ..KernelParams::default()
        },
        hit_distance: match args.hit_distance {
            HitArg::Mean => HitDistance::Mean,
            HitArg::Center => HitDistance::Center,
        },
        normal_mode: match args.normals {
            NormalArg::Plane => NormalMode::MaxDensityPlane,
            NormalArg::Ellipsoid => NormalMode::KernelEllipsoid,
        },
        background: args.background,
        iso_threshold: args.iso_threshold,
        ..RenderSettings::default()
    };
    let Method::Exact = args.method;
    let pool = rayon_pool(args.threads)?;
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let bar = ProgressBar::new(pixels).with_style(
        ProgressStyle::with_template(
            "{spinner} rendering [{bar:40}] {percent:>3}% {elapsed} (eta {eta})",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let start = Instant::now();
    let out = pool.install(|| render_exact(&scene, &camera, &settings, &|n| bar.inc(n)))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    write_outputs(&args, &out)?;
    eprintln!(
        "rendered {} particles at {}×{} in {seconds:.2} s → {}",
        scene.particles.len(),
        camera.width,
        camera.height,
        args.output.display()
    );
    Ok(())
}

fn choose_camera(
    args: &RenderArgs,
    scene: &Scene,
    default_camera: Option<Camera>,
) -> Result<Camera> {
    let camera = if let Some(path) = &args.camera {
        let cameras = splat_io::cameras::read_cameras(path)?;
        let n = cameras.len();
        *cameras.get(args.camera_index).with_context(|| {
            format!(
                "{}: --camera-index {} but the file has {n} cameras",
                path.display(),
                args.camera_index
            )
        })?
    } else if let (Some(eye), Some(target)) = (args.eye, args.target) {
        Camera::look_at(
            eye,
            target,
            args.up,
            args.fov,
            args.width.unwrap_or(640),
            args.height.unwrap_or(480),
        )?
    } else if let Some(camera) = default_camera {
        camera
    } else {
        Camera::framing(
            &scene.robust_bounds(0.02),
            args.width.unwrap_or(640),
            args.height.unwrap_or(480),
        )?
    };
    let (w, h) = (
        args.width.unwrap_or(camera.width),
        args.height.unwrap_or(camera.height),
    );
    if w == 0 || h == 0 {
        bail!("--width and --height must be positive");
    }
    Ok(camera.rescaled(w, h)?)
}

fn rayon_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        builder = builder.num_threads(n);
    }
    Ok(builder.build()?)
}

fn write_outputs(args: &RenderArgs, out: &RenderOutput) -> Result<()> {
    write_image(&args.output, &out.radiance)?;
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
