//! `splat`: render transparent 3D Gaussian scenes and inspect them.

mod info;
mod render;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Render 3D Gaussian splat scenes with exact (sorted, Eq. 3) transparency and inspect them.
///
/// Examples:
///   splat render -o demo.png                          # the built-in demo scene
///   splat render scene.ply --camera cameras.json -o view.png --depth depth.npy
///   splat info point_cloud.ply
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
    /// Print a scene's particle count, SH degree, bounds and opacity histogram.
    Info(info::InfoArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render::run(*args),
        Command::Info(args) => info::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
