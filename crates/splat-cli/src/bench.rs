//! `splat bench`: rays per second of every ray-tracing method through the same BVH, measured
//! in one run, as ratios against the `opaque` closest-hit baseline.

use crate::render::{MethodArg, MethodOptions, SceneArgs};
use anyhow::{Context, Result};
use clap::Args;
use splat_core::trace::{Frames, TraceScene, render_frames};
use std::time::Instant;

/// Arguments of `splat bench`.
#[derive(Args)]
pub struct BenchArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Methods to time, comma separated; `opaque` is always measured first as the baseline.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "stochastic,stochastic-n,stochastic-pass,kbuffer,exact"
    )]
    pub methods: Vec<MethodArg>,
    /// Frames per method (each frame is one sample per pixel).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Timed repetitions per method; the fastest is reported.
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    #[command(flatten)]
    pub options: MethodOptions,
}

/// Run `splat bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    if let Some(ctx) = crate::render::gpu_context(args.scene.backend)? {
        return run_gpu(&args, &ctx);
    }
    let (scene, camera) = args.scene.load(1200, 800)?;
    let pool = args.scene.pool()?;
    let threads = pool.current_num_threads();
    let build = Instant::now();
    let trace = TraceScene::new(&scene, args.scene.settings())?;
    let build_s = build.elapsed().as_secs_f64();
    let rays = f64::from(camera.width) * f64::from(camera.height) * f64::from(args.spp);
    println!(
        "{} particles, BVH built in {build_s:.2} s ({} nodes), {}×{} at {} spp, {threads} threads\n",
        scene.particles.len(),
        trace.bvh().nodes.len(),
        camera.width,
        camera.height,
        args.spp
    );
    println!("| method | frame (ms) | Mrays/s | Mrays/s per core | cost vs opaque |");
    println!("|---|---:|---:|---:|---:|");
    let mut methods = vec![MethodArg::Opaque];
    methods.extend(args.methods.iter().copied().filter(|&m| m != MethodArg::Opaque));
    let mut baseline = None;
    for m in methods {
        let method = args.options.method(m).context("the brute-force oracle is not benchmarked (it has no BVH)")?;
        let frames = Frames { count: args.spp, seed: 1, rng: args.options.rng() };
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat.max(1) {
            let start = Instant::now();
            pool.install(|| render_frames(&trace, &camera, &method, &frames, &|_| {}))?;
            best = best.min(start.elapsed().as_secs_f64());
        }
        let base = *baseline.get_or_insert(best);
        let name = m.name();
        let mrays = rays / best / 1e6;
        println!(
            "| {name} | {:.1} | {mrays:.3} | {:.3} | {:.2}× |",
            1e3 * best / f64::from(args.spp),
            mrays / threads as f64,
            best / base
        );
    }
    Ok(())
}

/// Frame times of every method on the GPU, as ratios against `stochastic` measured in the same
/// run (wall time around submit and poll; the opaque baseline exists on the CPU only).
fn run_gpu(args: &BenchArgs, ctx: &splat_gpu::GpuContext) -> Result<()> {
    let (scene, camera) = args.scene.load(1200, 800)?;
    let trace = TraceScene::new(&scene, args.scene.settings())?;
    let gpu_scene = splat_gpu::GpuScene::new(ctx, &trace)?;
    println!(
        "{} particles on {}, {}×{} at {} spp, {}\n",
        scene.particles.len(),
        ctx.describe(),
        camera.width,
        camera.height,
        args.spp,
        if ctx.timestamps { "timestamp queries" } else { "wall time around submit + poll" }
    );
    println!("| method | frame (ms) | Mrays/s | cost vs stochastic |");
    println!("|---|---:|---:|---:|");
    let mut methods = vec![MethodArg::Stochastic];
    methods.extend(args.methods.iter().copied().filter(|&m| m != MethodArg::Stochastic && m != MethodArg::Opaque));
    let rays = f64::from(camera.width) * f64::from(camera.height) * f64::from(args.spp);
    let mut baseline = None;
    for m in methods {
        let method = args.options.method(m).context("the brute-force oracle is not benchmarked (it has no BVH)")?;
        let frames = Frames { count: args.spp, seed: 1, rng: args.options.rng() };
        let name = m.name();
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat.max(1) {
            match splat_gpu::render(ctx, &gpu_scene, &trace, &camera, &method, &frames) {
                Ok(out) => best = best.min(out.gpu_time.as_secs_f64()),
                Err(e) => {
                    println!("| {name} | refused: {e} | | |");
                    break;
                }
            }
        }
        if best.is_finite() {
            let base = *baseline.get_or_insert(best);
            println!(
                "| {name} | {:.1} | {:.3} | {:.2}× |",
                1e3 * best / f64::from(args.spp),
                rays / best / 1e6,
                best / base
            );
        }
    }
    Ok(())
}
