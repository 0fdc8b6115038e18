//! `splat-view`: the viewer on its own (the same as `splat view`).

use clap::Parser;
use std::process::ExitCode;

/// An interactive window on transparent 3D Gaussian scenes.
#[derive(Parser)]
#[command(name = "splat-view", version, about)]
struct Cli {
    #[command(flatten)]
    args: splat_view::ViewArgs,
}

fn main() -> ExitCode {
    // SAFETY: the first statement of main, before any thread starts.
    #[allow(unsafe_code)]
    unsafe {
        splat_gpu::quiet_device_select()
    };
    match splat_view::run(&Cli::parse().args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
