//! `splat`: render transparent 3D Gaussian scenes and inspect them.

use clap::{CommandFactory, Parser, Subcommand};
use splat_cli::{
    bench, compare, converge, convert, hint, hits, info, merge, render, reproduce, stratify, undistort, ztest,
};
use std::process::ExitCode;

/// Render 3D Gaussian splat scenes with exact and stochastic transparency, measure convergence
/// and speed, and inspect scenes.
///
/// Examples:
///   splat render -o demo.png                          # the built-in demo scene
///   splat render scene.ply --camera cameras.json -o view.png --depth depth.npy
///   splat render scene.splat --method stochastic --spp 64 --seed 1 -o noisy.exr
///   splat render scene.ply --method stratified --raster-samples 16 -o strat.png
///   splat render scene.splat --backend gpu --method stochastic-splat --spp 64 -o ss.png
///   splat converge scene.splat --max-spp 256 -o converge   # converge.csv, converge.png
///   splat bench scene.splat                                 # rays/s per method
///   splat bench scene.splat --backend gpu --methods raster-sorted,stochastic-splat
///   splat stratify -o strat                                 # Laine–Karras Table 1 analogue
///   splat render scene.ply --camera sparse/0 --all-cameras -o views/   # every COLMAP view
///   splat convert point_cloud.ply scene.spz                 # .ply, .splat, .spz
///   splat ztest mean.exr var.exr ref.exr --frames 256 --zmap z.png   # exit 0 pass, 1 reject
///   splat compare ref.exr test.png --maps err        # RMSE, PSNR, SSIM, FLIP; err-*.png
///   splat render scene.ply --method stochastic --seed 1 --frames 0..64 -o part0.acc   # a job's share
///   splat merge part*.acc -o mean.exr --variance var.exr   # the shares' run
///   splat render scene.ply --camera sparse/0 --all-cameras --shard 3/8 -o views/   # task 3 of 8
///   splat undistort --camera sparse/0 --undistort gsplat --split 3dgs-test -o gt/   # the trainer's test photos
///   splat info point_cloud.ply
///   splat view scene.ply --camera cameras.json            # interactive window
#[derive(Parser)]
#[command(name = "splat", version, about, long_about, verbatim_doc_comment)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (or the built-in demo scene) to an image.
    Render(Box<render::RenderArgs>),
    /// Convert a scene between .ply, .splat, .spz, glTF, PlayCanvas SOG, OpenUSD .usda, and the
    /// read-only compressed .ply, .ksplat and trainers' checkpoints (3DGS's .pth, gsplat's and
    /// 3DGRUT's .pt, Nerfstudio's .ckpt).
    Convert(convert::ConvertArgs),
    /// Print a scene's particle count, SH degree, bounds and opacity histogram.
    Info(info::InfoArgs),
    /// RMSE against the oracle (exact; raster-sorted for raster methods) at spp 1, 2, 4, …:
    /// CSV, log–log plot PNG, Markdown table.
    Converge(Box<converge::ConvergeArgs>),
    /// Rays per second of each ray-tracing method against an opaque closest-hit baseline, or the
    /// stages of the splatting path (--methods raster-sorted,stochastic-splat).
    Bench(Box<bench::BenchArgs>),
    /// Open a window on a scene: fly through it, switch methods, watch them converge (the
    /// built-in demo scene without a file).
    View(Box<splat_view::ViewArgs>),
    /// Serve a scene to a browser: a page on localhost shows the render converging and steers
    /// it with the window's controls (for GPU machines without a display).
    Serve(Box<splat_view::serve::ServeArgs>),
    /// RMSE, PSNR, SSIM and ꟻLIP between two images (.png, .exr, .npy), with error maps.
    Compare(compare::CompareArgs),
    /// A capture's photographs as a trainer undistorts them (OpenCV's resampling, as splatfacto
    /// or gsplat calls it): the ground truth that renders through `--undistort` compare against.
    Undistort(undistort::UndistortArgs),
    /// Merge the shares of a run (`splat render --frames A..B -o PART.acc`, one per task of a
    /// job array) into its mean, variance and alpha images.
    Merge(merge::MergeArgs),
    /// Print a shell completion script: `splat completions bash > ~/.local/share/bash-completion/completions/splat`
    /// (zsh: a `_splat` file on $fpath; fish: ~/.config/fish/completions/splat.fish).
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Per-pixel z-test of a mean image against a reference, with the variance of an
    /// independent run: prints the statistics and PASS or REJECT; exit status 0 pass, 1 reject,
    /// 2 bad input.
    Ztest(ztest::ZtestArgs),
    /// Laine–Karras stratification gain: RMSE of stratified / Enderton at 4…64 samples per
    /// pixel on the layered fixtures, as a table and a side-by-side PNG.
    Stratify(stratify::StratifyArgs),
    /// The surface each hit distance convention picks (vk_gaussian_splatting Lighting §1.4.3):
    /// icosahedron, maximum density, centre and the rasterizer's billboard, side by side.
    HitDistance(Box<hits::HitDistanceArgs>),
    /// The sources' tables and figures by name (`--list`), each regenerated through these
    /// commands and written beside the published numbers (`--quick`: the demo scene, seconds).
    Reproduce(reproduce::ReproduceArgs),
}

fn main() -> ExitCode {
    // SAFETY: the first statement of main, before any thread starts.
    #[allow(unsafe_code)]
    unsafe {
        splat_gpu::quiet_device_select()
    };
    let cli = Cli::parse();
    if let Command::Ztest(args) = &cli.command {
        return match ztest::run(args) {
            Ok(true) => ExitCode::SUCCESS,
            Ok(false) => ExitCode::from(1),
            Err(e) => {
                eprintln!("error: {e:#}{}", hint::flags(&e));
                ExitCode::from(2)
            }
        };
    }
    let result = match cli.command {
        Command::Render(mut args) => {
            args.options.apply_preset(args.scene.read.preset);
            render::run(*args)
        }
        Command::Info(args) => info::run(args),
        Command::Convert(args) => convert::run(args),
        Command::Converge(mut args) => {
            args.options.apply_preset(args.scene.read.preset);
            converge::run(*args)
        }
        Command::Bench(mut args) => {
            args.options.apply_preset(args.scene.read.preset);
            bench::run(*args)
        }
        Command::Stratify(args) => stratify::run(args),
        Command::HitDistance(args) => hits::run(*args),
        Command::Reproduce(args) => reproduce::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Merge(args) => merge::run(args),
        Command::Undistort(args) => undistort::run(args),
        Command::View(args) => splat_view::run(&args),
        Command::Serve(args) => splat_view::serve::run(&args),
        Command::Completions { shell } => {
            clap_complete::generate(shell, &mut Cli::command(), "splat", &mut std::io::stdout());
            Ok(())
        }
        Command::Ztest(_) => unreachable!("handled above"),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}{}", hint::flags(&e));
            ExitCode::FAILURE
        }
    }
}
