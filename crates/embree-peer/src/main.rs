//! `embree-peer`: splat-core's CPU tracer against the Embree peer, in one run, on one capture
//! and view: BVH build time, rays per second of `opaque`, `stochastic` (Algorithm 1) and
//! `exact`, the ratios, and how far the two images are apart (the same seed must give the same
//! image, or the peer is no baseline). `cargo xtask bench` runs it on the bonsai capture.

use anyhow::{Context, Result, bail};
use clap::Parser;
use embree_peer::{EmbreePeer, PeerBounds, PeerMethod, difference};
use glam::Vec3;
use splat_core::frame::Frames;
use splat_core::rng::frame_key;
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, RenderSettings};
use splat_io::text::parse_vec3;
use std::path::PathBuf;
use std::time::Instant;

/// splat-core's CPU ray tracer against an Embree 3 user-geometry peer, same view, same decisions.
#[derive(Parser)]
struct Args {
    /// Scene (.ply or .splat).
    scene: PathBuf,
    /// Camera position "x,y,z".
    #[arg(long, value_parser = parse_vec3, default_value = "0,-1.5,4")]
    eye: Vec3,
    /// Look-at target "x,y,z".
    #[arg(long, value_parser = parse_vec3, default_value = "0,0.5,0")]
    target: Vec3,
    /// World up "x,y,z".
    #[arg(long, value_parser = splat_io::text::parse_direction, default_value = "0,-1,0")]
    up: Vec3,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 50.0)]
    fov: f32,
    /// Image width.
    #[arg(long, default_value_t = 1200)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 800)]
    height: u32,
    /// Threads for both (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Timed repetitions of each measurement; the fastest is reported.
    #[arg(long, default_value_t = 3)]
    repeat: u32,
}

/// The fastest of `repeat` runs of `f`, in seconds, with the last result.
fn fastest<T>(repeat: u32, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        let out = f()?;
        best = best.min(start.elapsed().as_secs_f64());
        last = Some(out);
    }
    Ok((best, last.expect("at least one run")))
}

fn main() -> Result<()> {
    let args = Args::parse();
    if !embree_peer::available() {
        bail!("{}", embree_peer::NOT_BUILT);
    }
    let scene = splat_io::read_scene(&args.scene).with_context(|| format!("loading {}", args.scene.display()))?;
    let camera = Camera::look_at(args.eye, args.target, args.up, args.fov, args.width, args.height)?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let settings = RenderSettings::default();
    let n = scene.particles.len();

    let (splat_build, trace) = fastest(args.repeat, || Ok(pool.install(|| TraceScene::new(&scene, settings))?))?;
    let peer = |bounds| {
        fastest(args.repeat, || EmbreePeer::build(&scene, &settings, bounds, threads).map_err(anyhow::Error::msg))
    };
    let (cutoff_build, cutoff_peer) = peer(PeerBounds::Cutoff)?;
    let (same_build, same_peer) = peer(PeerBounds::Splat)?;
    let rays = f64::from(camera.width) * f64::from(camera.height);
    println!(
        "{n} particles, {}×{} at 1 spp, {threads} threads, fastest of {} runs. Embree A bounds each particle by its \
         cutoff box (as Sun et al.), Embree B by splat's boxes (visible extent); ratios are splat's throughput over \
         Embree's (> 1: splat is faster)\n",
        camera.width,
        camera.height,
        args.repeat.max(1)
    );
    println!("| | Embree A | Embree B | splat | splat ÷ A | splat ÷ B | images: max |Δ|, pixels apart (A, B) |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    println!(
        "| BVH build, {n} splats | {cutoff_build:.3} s | {same_build:.3} s | {splat_build:.3} s | {:.2}× | {:.2}× | |",
        cutoff_build / splat_build,
        same_build / splat_build
    );
    let frames = Frames { count: 1, seed: 1, ..Frames::default() };
    let key = frame_key(frames.seed, 0);
    let mut opaque_time = None;
    for (name, method, peer_method) in [
        ("opaque ray (closest ellipsoid)", Method::Opaque, PeerMethod::Opaque),
        ("stochastic (Algorithm 1)", Method::Stochastic, PeerMethod::Stochastic),
        ("exact (every hit, sorted)", Method::Exact, PeerMethod::Exact),
    ] {
        let (splat_s, out) =
            fastest(args.repeat, || Ok(pool.install(|| render_frames(&trace, &camera, &method, &frames, &|_| {}))?))?;
        let (a_s, a_image) = fastest(args.repeat, || Ok(cutoff_peer.render(&camera, peer_method, key, threads)))?;
        let (b_s, b_image) = fastest(args.repeat, || Ok(same_peer.render(&camera, peer_method, key, threads)))?;
        let (a_max, a_apart) = difference(out.mean.data(), &a_image);
        let (b_max, b_apart) = difference(out.mean.data(), &b_image);
        let mrays = |s: f64| rays / s / 1e6;
        println!(
            "| {name} (M rays/s) | {:.3} | {:.3} | {:.3} | {:.2}× | {:.2}× | {a_max:.1e}, {a_apart}; {b_max:.1e}, {b_apart} |",
            mrays(a_s),
            mrays(b_s),
            mrays(splat_s),
            a_s / splat_s,
            b_s / splat_s,
        );
        if method == Method::Opaque {
            opaque_time = Some((a_s, b_s, splat_s));
        } else if method == Method::Stochastic {
            let (oa, ob, os) = opaque_time.expect("opaque is measured first");
            println!(
                "| stochastic ÷ opaque (cost per ray, same BVH) | {:.2}× | {:.2}× | {:.2}× | | | |",
                a_s / oa,
                b_s / ob,
                splat_s / os
            );
        }
    }
    println!("\nsplat BVH: {:.1} bytes/splat (4-wide nodes)", trace.bvh().bytes() as f64 / n as f64);
    println!(
        "pixels apart: a channel differs by more than 1e-4 (a different decision, not float noise), of {}",
        rays as u64
    );
    Ok(())
}
