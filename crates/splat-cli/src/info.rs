//! `splat info`: what is in a scene file.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `splat info`.
#[derive(Args)]
pub struct InfoArgs {
    /// Scene file: INRIA 3DGS `.ply` or antimatter15 `.splat`.
    pub scene: PathBuf,
    /// Skip unknown `.ply` vertex properties instead of refusing the file.
    #[arg(long)]
    pub allow_unknown_properties: bool,
}

/// Run `splat info`.
pub fn run(args: InfoArgs) -> Result<()> {
    let scene = crate::args::load_scene(&args.scene, args.allow_unknown_properties)?;
    let n = scene.particles.len();
    println!("file       {}", args.scene.display());
    println!("particles  {n}");
    println!("SH degree  {}", scene.sh_degree);
    if n == 0 {
        return Ok(());
    }
    let b = scene.mean_bounds();
    let r = scene.robust_bounds(0.01);
    println!("bounds     min {:.3} max {:.3}", b.min, b.max);
    println!("1–99 %     min {:.3} max {:.3}", r.min, r.max);
    let (lo, hi) = scene
        .particles
        .iter()
        .fold((f32::INFINITY, 0.0f32), |(lo, hi), p| (lo.min(p.scale.min_element()), hi.max(p.scale.max_element())));
    println!("scale      {lo:.2e} … {hi:.2e}");
    println!("opacity histogram:");
    let mut bins = [0usize; 10];
    for p in &scene.particles {
        bins[((p.opacity * 10.0) as usize).min(9)] += 1;
    }
    let max = *bins.iter().max().unwrap_or(&1);
    for (i, &count) in bins.iter().enumerate() {
        let bar = "#".repeat((40 * count).div_ceil(max.max(1)));
        println!(
            "  [{:.1}, {:.1}{} {count:>9}  {bar}",
            i as f32 / 10.0,
            (i + 1) as f32 / 10.0,
            if i == 9 { "]" } else { ")" }
        );
    }
    Ok(())
}
