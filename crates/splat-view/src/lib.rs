//! `splat view`: an interactive window on transparent 3D Gaussian scenes, to fly through a
//! capture, switch between the estimators of Sun et al. 2025 and the splatting methods, and
//! watch them converge to the exact image (Eq. 3).
//!
//! The window (winit, wgpu and egui through eframe) posts jobs to a render thread
//! ([`worker`]), which traces on the GPU with [`splat_gpu::ProgressiveTrace`] — the
//! accumulation kept on the device and drawn straight into the window's texture — or renders
//! on the CPU with the `splat-core` renderers where there is no hardware GPU.
//!
//! ```text
//! splat view scene.ply --camera cameras.json
//! ```

pub mod accumulate;
pub mod app;
pub mod camera;
pub mod load;
pub mod navigate;
pub mod serve;
pub mod settings;
pub mod worker;

pub use app::{BackendChoice, KEY_BINDINGS, Options, Viewer};

use anyhow::{Context, Result};
use eframe::egui_wgpu;
use splat_core::ScreenFilter;
use splat_core::glam::Vec3;
use splat_core::sh::ShStorage;
use splat_core::trainer::Preset;
use splat_core::undistort::Undistortion;
use splat_gpu::GpuContext;
use splat_io::cameras::{Split, ViewOptions};
use splat_io::similarity::Similarity;
use std::path::PathBuf;
use std::sync::Arc;

/// What `splat view` and `splat serve` open and how they render it.
#[derive(clap::Args, Clone, Debug)]
pub struct SceneArgs {
    /// Scene file (.ply, compressed .ply, .splat, .spz) or world file (.toml); the built-in
    /// demo scene when omitted.
    pub scene: Option<PathBuf>,
    /// Views to step through (N / P): a cameras.json, a COLMAP model (sparse/0, or its
    /// cameras and images files) or a transforms.json (NeRF-synthetic, Nerfstudio); the first
    /// view opens.
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// The view of --camera to open with.
    #[arg(long, default_value_t = 0, requires = "camera")]
    pub camera_index: usize,
    /// A Nerfstudio training run's dataparser_transforms.json: moves the cameras of a
    /// transforms.json (--camera) into the run's normalised world, where splatfacto's exported
    /// splats (ns-export gaussian-splat) live.
    #[arg(long, requires = "camera")]
    pub dataparser_transforms: Option<PathBuf>,
    /// The splats are gsplat simple_trainer's, in the normalised world it trains in by default
    /// (normalize_world_space): moves the cameras of a COLMAP model (--camera, with its
    /// points3D) into that world.
    #[arg(long, requires = "camera", conflicts_with = "dataparser_transforms")]
    pub gsplat_world: bool,
    /// A 4 × 4 (or 3 × 4) matrix [s R | t] from the world of --camera to the splats' world
    /// (a .npy, or its numbers as text), such as gsplat's parser.transform: moves every camera
    /// by it.
    #[arg(
        long,
        value_name = "FILE",
        requires = "camera",
        conflicts_with_all = ["dataparser_transforms", "gsplat_world"],
        value_parser = world_transform_parser
    )]
    pub world_transform: Option<Similarity>,
    /// Show each camera of --camera as the pinhole this trainer undistorts its photos to
    /// (their training and evaluation images are of it): OpenCV's choice, as the trainer
    /// calls it; gsplat's fisheye, the ideal fisheye its own map resamples to.
    #[arg(long, requires = "camera", value_parser = undistort_parser())]
    pub undistort: Option<Undistortion>,
    /// Keep only a trainer's split of the views of --camera (its held-out views), in its order.
    #[arg(long, requires = "camera", value_parser = split_parser())]
    pub split: Option<Split>,
    /// The trainer read images downscaled by F (images_F/, gsplat's --data_factor, Nerfstudio's
    /// downscale factor): each camera of --camera takes K / F and its sides floored before it
    /// is undistorted, as they do.
    #[arg(long, requires = "camera", value_parser = clap::value_parser!(u32).range(1..))]
    pub data_factor: Option<u32>,
    /// Where frames render: auto takes a hardware GPU and the CPU renderers on a CPU adapter
    /// such as lavapipe.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendChoice,
    /// World up "x,y,z" for framing a scene without cameras (COLMAP captures: 0,-1,0).
    #[arg(long, value_parser = splat_io::text::parse_direction, default_value = "0,1,0")]
    pub up: Vec3,
    /// Frames after which the accumulation stops.
    #[arg(long, default_value_t = 1024)]
    pub max_frames: u32,
    /// The screen-space filter the capture was trained with, which the splatting methods apply
    /// (default: the --preset's, else the one its file names; else 3dgs).
    #[arg(long, value_parser = screen_filter_parser())]
    pub screen_filter: Option<ScreenFilter>,
    /// The trainer of the capture: the renderer the window starts with (its screen filter, splat
    /// extent and response, near plane, kernel degree and cutoff), which the panel can change
    /// [default: the one the capture's file names: a trainer's checkpoint; else 3dgs].
    #[arg(long, value_parser = preset_parser())]
    pub preset: Option<Preset>,
    /// How the SH coefficients are stored (vk_gaussian_splatting's SH formats): f16 halves the
    /// GPU's largest scene array, u8 quarters it, each rounding the colours; the CPU reads the
    /// same stored values [default: the world's, else f32].
    #[arg(long, value_parser = sh_storage_parser())]
    pub sh_storage: Option<ShStorage>,
}

impl SceneArgs {
    /// Read the scene and its views, checking `--camera-index` against them.
    pub fn load(&self) -> Result<load::Loaded> {
        let screen_filter = self.screen_filter.or(self.preset.and_then(Preset::screen_filter));
        let read = splat_io::ReadOptions { screen_filter, ..Default::default() };
        let views = ViewOptions {
            dataparser: self.dataparser_transforms.as_deref(),
            world_transform: self.world_transform,
            undistort: self.undistort,
            split: self.split,
            factor: self.data_factor,
            ..Default::default()
        };
        let cameras = self.camera.as_deref().map(|path| (path, self.gsplat_world));
        let mut loaded = load::load(self.scene.as_deref(), cameras, views, read, self.preset)?;
        if let Some(storage) = self.sh_storage {
            loaded.info.render.sh_storage = storage;
        }
        if let Some(camera) = &self.camera
            && self.camera_index >= loaded.info.views.len()
        {
            anyhow::bail!(
                "--camera-index {} but {} has {} views",
                self.camera_index,
                camera.display(),
                loaded.info.views.len()
            );
        }
        Ok(loaded)
    }

    /// The options the window (or the server) needs; `quit_after` frames close the window.
    pub fn options(&self, quit_after: Option<u32>) -> Options {
        Options {
            backend: self.backend,
            camera_index: self.camera_index,
            up: self.up.normalize(),
            quit_after,
            max_frames: quit_after.unwrap_or(u32::MAX).min(self.max_frames).max(1),
        }
    }
}

/// The command line of `splat view`.
#[derive(clap::Args, Clone, Debug)]
pub struct ViewArgs {
    /// The scene and how it renders.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Window width in points.
    #[arg(long, default_value_t = 1280.0)]
    pub width: f32,
    /// Window height in points.
    #[arg(long, default_value_t = 800.0)]
    pub height: f32,
    /// Render N frames of the first view, print a summary and close the window (smoke tests).
    #[arg(long, value_name = "N")]
    pub quit_after: Option<u32>,
}

/// The values of `--sh-storage` (here and in the `splat` commands): every [`ShStorage`] by its
/// name, described.
pub fn sh_storage_parser() -> impl clap::builder::TypedValueParser<Value = ShStorage> {
    choice_parser(&ShStorage::ALL, ShStorage::name, ShStorage::describe)
}

/// The values of `--undistort` (here and in the `splat` commands): every [`Undistortion`] by
/// its name, described.
pub fn undistort_parser() -> impl clap::builder::TypedValueParser<Value = Undistortion> {
    choice_parser(&Undistortion::ALL, Undistortion::name, Undistortion::describe)
}

/// `--world-transform FILE` (here and in the `splat` commands): the similarity the file holds,
/// read as the arguments are parsed, so that a bad file is named before the scene is read.
pub fn world_transform_parser(path: &str) -> Result<Similarity, String> {
    splat_io::similarity::read(std::path::Path::new(path)).map_err(|e| e.to_string())
}

/// The values of `--split` (here and in the `splat` commands): every [`Split`] by its name,
/// described.
pub fn split_parser() -> impl clap::builder::TypedValueParser<Value = Split> {
    choice_parser(&Split::ALL, Split::name, Split::describe)
}

/// The values of `--preset` (here and in the `splat` commands): every [`Preset`] by its name,
/// described.
pub fn preset_parser() -> impl clap::builder::TypedValueParser<Value = Preset> {
    choice_parser(&Preset::ALL, Preset::name, Preset::describe)
}

/// The values of `--screen-filter` (here and in the `splat` commands): every [`ScreenFilter`]
/// by its name, described.
pub fn screen_filter_parser() -> impl clap::builder::TypedValueParser<Value = ScreenFilter> {
    choice_parser(&ScreenFilter::ALL, ScreenFilter::name, ScreenFilter::describe)
}

/// A parser of one of the values `all`, each given by its `name` and listed in `--help` with
/// its `help`: the options whose values the libraries declare (`--screen-filter`, and the
/// `splat` commands' `--preset` and `--method`).
pub fn choice_parser<T: Copy + Send + Sync + 'static>(
    all: &'static [T],
    name: fn(T) -> &'static str,
    help: fn(T) -> &'static str,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let values = all.iter().map(|&v| PossibleValue::new(name(v)).help(help(v)));
    PossibleValuesParser::new(values).map(move |n| *all.iter().find(|&&v| name(v) == n).expect("one of the values"))
}

impl ViewArgs {
    /// The options the window needs.
    pub fn options(&self) -> Options {
        self.scene.options(self.quit_after)
    }
}

/// The wgpu setup of the window: the device asks for what the ray-tracing kernel needs
/// ([`GpuContext::device_descriptor`]), so that the kernel runs on the window's device and
/// draws into its textures.
pub fn wgpu_configuration() -> egui_wgpu::WgpuConfiguration {
    let mut setup = egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.device_descriptor = Arc::new(GpuContext::device_descriptor);
    egui_wgpu::WgpuConfiguration { wgpu_setup: egui_wgpu::WgpuSetup::CreateNew(setup), ..Default::default() }
}

/// Open the window on `args`' scene and run until it closes.
pub fn run(args: &ViewArgs) -> Result<()> {
    if args.width < 64.0 || args.height < 64.0 || !args.width.is_finite() || !args.height.is_finite() {
        anyhow::bail!("--width and --height must be at least 64 points");
    }
    let loaded = args.scene.load()?;
    let title = format!("splat view — {}", loaded.info.name);
    let options = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title(&title)
            .with_inner_size([args.width, args.height]),
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: wgpu_configuration(),
        ..Default::default()
    };
    let view_options = args.options();
    eframe::run_native(
        "splat view",
        options,
        Box::new(move |cc| {
            let render_state = cc.wgpu_render_state.clone().ok_or("eframe started without a wgpu renderer")?;
            Ok(Box::new(Viewer::new(loaded, &view_options, render_state, cc.egui_ctx.clone())))
        }),
    )
    .map_err(|e| anyhow::anyhow!("{e}"))
    .context("could not open the window (splat view needs a desktop: X11 or Wayland; on a headless machine, xvfb-run)")
}
