//! `splat bench`: rays per second of every ray-tracing method through the same BVH, measured
//! in one run, as ratios against the `opaque` closest-hit baseline; with `raster-sorted` or
//! `stochastic-splat` among the methods, the splatting path instead (on the GPU stage by
//! stage: projection, sort, sorted draw, StochasticSplats draw).

use crate::args::{MethodOptions, SceneArgs, method_parser};
use anyhow::Result;
use clap::Args;
use splat_core::bvh::work;
use splat_core::catalogue::Family;
use splat_core::trace::{TraceScene, render_frames};
use splat_core::{Frames, MethodId};
use std::time::Instant;

/// Arguments of `splat bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// The scene, camera and shading.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Methods to time, comma separated; `opaque` is always measured first as the baseline.
    /// Naming raster-sorted or stochastic-splat benchmarks the splatting path instead: stage
    /// times, the sort's share and keys/s, and the stochastic/sorted frame ratio.
    #[arg(
        help_heading = "Measurement",
        long,
        value_parser = method_parser(),
        value_delimiter = ',',
        default_value = "stochastic,stochastic-n,stochastic-pass,kbuffer,exact"
    )]
    pub methods: Vec<MethodId>,
    /// Frames per method (each frame is one sample per pixel).
    #[arg(help_heading = "Measurement", long, default_value_t = 1)]
    pub spp: u32,
    /// Timed repetitions per method; the fastest is reported.
    #[arg(help_heading = "Measurement", long, default_value_t = 3)]
    pub repeat: u32,
    /// Instead of the methods, the rows of Sun et al. 2025 Tables 4–5: one frame of
    /// `stochastic-n` with m traversals × n samples each, m × n = 1024 (1024 × 1 to 4 × 256; the
    /// GPU kernel runs n > 64 as traversals of 64), time as a speed-up over 1024 × 1 and RMSE
    /// against `exact`, on the backend chosen (1024 samples a pixel: choose --width/--height
    /// to suit).
    #[arg(help_heading = "Measurement", long, value_enum)]
    pub sweep: Option<Sweep>,
    /// With a lit world file: the frame time of each method unlit, lit without shadows and lit
    /// with each shadow kind (sorted, stochastic, exact transmittance), as ratios against the
    /// unlit frame measured in the same run (CPU).
    #[arg(help_heading = "Measurement", long)]
    pub lighting: bool,
    /// With a world file with meshes: the frame of each pipeline (raster three-pass, hybrid,
    /// ray tracing) with a deterministic and a stochastic method each, as ratios against
    /// raster-sorted measured in the same run (CPU; --raster-samples applies).
    #[arg(help_heading = "Measurement", long)]
    pub pipelines: bool,
    /// The method's parameters.
    #[command(flatten)]
    pub options: MethodOptions,
}

/// What `--sweep` varies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Sweep {
    /// Traversals × samples per traversal of `stochastic-n` (Sun et al. §3.5, Tables 4–5).
    Mn,
}

/// The (m, n) rows of Sun et al. 2025 Tables 4–5: 1024 samples a pixel in every row.
pub const MN_ROWS: [(u32, u32); 8] = [(1024, 1), (512, 2), (256, 4), (128, 8), (64, 16), (32, 32), (16, 64), (4, 256)];

/// Run `splat bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    if args.sweep == Some(Sweep::Mn) {
        return run_mn_sweep(&args);
    }
    if args.lighting {
        return run_lighting(&args);
    }
    if args.pipelines {
        return run_pipelines(&args);
    }
    let raster = args.methods.iter().any(|m| m.entry().family == Family::Raster);
    let ctx = crate::args::gpu_context(args.scene.backend)?;
    if raster {
        return match &ctx {
            Some(ctx) => run_raster_gpu(&args, ctx),
            None => run_raster_cpu(&args),
        };
    }
    if let Some(ctx) = ctx {
        return run_gpu(&args, &ctx);
    }
    let load = Instant::now();
    let (scene, camera, settings) = args.scene.load(1200, 800)?;
    let load_s = load.elapsed().as_secs_f64();
    let pool = args.scene.pool()?;
    let threads = pool.current_num_threads();
    let build = Instant::now();
    let trace = pool.install(|| TraceScene::new(&scene, settings))?;
    let build_s = build.elapsed().as_secs_f64();
    let pixels = f64::from(camera.width) * f64::from(camera.height);
    println!(
        "{} particles loaded in {load_s:.2} s, BVH built in {build_s:.2} s ({} 4-wide nodes), {}×{} at {} spp, {threads} threads\n",
        scene.particles.len(),
        trace.bvh().len(),
        camera.width,
        camera.height,
        args.spp
    );
    println!(
        "| method | frame (ms) | Mrays/s | Mrays/s per core | cost vs opaque | traversals/ray | nodes/ray | leaves/ray | tests/ray | bytes/ray |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    // Work counters of every thread of the pool (splat_core::bvh::work), summed.
    let work = || pool.broadcast(|_| work::take()).into_iter().fold(work::Work::default(), work::Work::plus);
    let mut methods = vec![MethodId::Opaque];
    methods.extend(args.methods.iter().copied().filter(|&m| m != MethodId::Opaque));
    let mut baseline = None;
    for m in methods {
        let method = args.options.method(m)?;
        let frames = Frames { count: args.spp, seed: 1, rng: args.options.rng(), ..Frames::default() };
        let rendered = rendered_frames(&splat_core::Algorithm::Trace(method), &trace.shot(&camera), &frames);
        let mut best = f64::INFINITY;
        let _ = work();
        for _ in 0..args.repeat.max(1) {
            let start = Instant::now();
            pool.install(|| render_frames(&trace, &camera, &method, &frames, &|_| {}))?;
            best = best.min(start.elapsed().as_secs_f64() / rendered);
        }
        let counts = work();
        let rays = pixels * rendered * f64::from(args.repeat.max(1));
        let per_ray = |n: u64| n as f64 / rays;
        let bytes = counts.bytes(std::mem::size_of::<splat_core::hit::PreparedParticle>());
        let base = *baseline.get_or_insert(best);
        let name = m.name();
        let mrays = pixels / best / 1e6;
        println!(
            "| {name} | {:.1} | {mrays:.3} | {:.3} | {:.2}× | {:.2} | {:.1} | {:.1} | {:.1} | {:.0} |",
            1e3 * best,
            mrays / threads as f64,
            best / base,
            per_ray(counts.traversals),
            per_ray(counts.nodes),
            per_ray(counts.leaves),
            per_ray(counts.tests),
            per_ray(bytes)
        );
    }
    if let Some(peak) = splat_io::memory::peak_resident() {
        let per_splat = peak as f64 / scene.particles.len().max(1) as f64;
        println!(
            "\npeak memory {:.2} GB ({per_splat:.0} bytes a splat: the scene, its BVH and the frames)",
            peak as f64 / 1e9
        );
    }
    Ok(())
}

/// The frames a render of `frames` of `algorithm` in `shot` draws: all of them where frames
/// differ ([`splat_core::Algorithm::is_random`]), one otherwise; frame times and ray rates
/// divide by it.
fn rendered_frames(algorithm: &splat_core::Algorithm, shot: &splat_core::Shot, frames: &Frames) -> f64 {
    let random = algorithm.is_random(shot.lighting, !shot.meshes.is_empty(), &shot.settings.sampling);
    if random { f64::from(frames.count) } else { 1.0 }
}

/// The cost of lighting: each method's frame unlit, lit without shadows and lit with each
/// shadow kind, through the same BVH, as ratios against the unlit frame of the same run.
fn run_lighting(args: &BenchArgs) -> Result<()> {
    use splat_core::lighting::{Lighting, Shadows};
    let staged = args.scene.load_world(1200, 800)?;
    if !staged.world.lighting.is_on() {
        anyhow::bail!("--lighting needs a lit world: a .toml whose splat sets have a non-emissive material");
    }
    let (scene, camera) = (&staged.world.scene, &staged.camera);
    let pool = args.scene.pool()?;
    println!(
        "{} particles, {} lights, {}×{} at {} spp, {} threads; frame time in ms (× the unlit frame)\n",
        scene.particles.len(),
        staged.world.lighting.lights.len(),
        camera.width,
        camera.height,
        args.spp,
        pool.current_num_threads()
    );
    let variants = [
        ("unlit", Lighting::default()),
        ("lit, no shadows", Lighting { shadows: Shadows::None, ..staged.world.lighting.clone() }),
        ("sorted shadows", Lighting { shadows: Shadows::SORTED, ..staged.world.lighting.clone() }),
        ("stochastic shadows", Lighting { shadows: Shadows::Stochastic, ..staged.world.lighting.clone() }),
        ("exact transmittance", Lighting { shadows: Shadows::Exact, ..staged.world.lighting.clone() }),
    ];
    let names: Vec<&str> = variants.iter().map(|v| v.0).collect();
    println!("| method | {} |", names.join(" | "));
    println!("|---|{}", "---:|".repeat(names.len()));
    let traces = variants
        .iter()
        .map(|(_, l)| Ok(TraceScene::new(scene, staged.settings)?.with_lighting(l)?))
        .collect::<Result<Vec<_>>>()?;
    for &m in &args.methods {
        let method = args.options.method(m)?;
        let frames = Frames { count: args.spp, seed: 1, rng: args.options.rng(), ..Frames::default() };
        let mut cells = Vec::new();
        let mut unlit = None;
        for trace in &traces {
            let rendered = rendered_frames(&splat_core::Algorithm::Trace(method), &trace.shot(camera), &frames);
            let mut best = f64::INFINITY;
            for _ in 0..args.repeat.max(1) {
                let start = Instant::now();
                pool.install(|| render_frames(trace, camera, &method, &frames, &|_| {}))?;
                best = best.min(start.elapsed().as_secs_f64() / rendered);
            }
            let base = *unlit.get_or_insert(best);
            cells.push(format!("{:.1} ({:.2}×)", 1e3 * best, best / base));
        }
        println!("| {} | {} |", m.name(), cells.join(" | "));
    }
    Ok(())
}

/// The cost of each pipeline on a world with meshes, as ratios against `raster-sorted`
/// measured in the same run.
fn run_pipelines(args: &BenchArgs) -> Result<()> {
    use splat_core::Algorithm;
    use splat_core::raster::{Blend, RasterMethod};
    use splat_core::trace::Method;
    let staged = args.scene.load_world(640, 480)?;
    if staged.world.meshes.is_empty() {
        anyhow::bail!("--pipelines needs a world file with [[meshes]]");
    }
    let (scene, camera) = (&staged.world.scene, &staged.camera);
    let mut options = args.options.clone();
    options.apply_capture(scene);
    let pool = args.scene.pool()?;
    let raster = options.raster_settings();
    let sorted = RasterMethod::Sorted { blend: Blend::Under };
    let rows = [
        ("raster", "raster-sorted", Algorithm::Raster(sorted, raster)),
        ("raster", "stochastic-splat", Algorithm::Raster(RasterMethod::StochasticSplat, raster)),
        ("hybrid", "raster-sorted + exact", Algorithm::Hybrid(sorted, raster, Method::Exact)),
        ("hybrid", "raster-sorted + stochastic", Algorithm::Hybrid(sorted, raster, Method::Stochastic)),
        ("rt", "exact", Algorithm::Trace(Method::Exact)),
        ("rt", "stochastic", Algorithm::Trace(Method::Stochastic)),
    ];
    println!(
        "{} particles, {} meshes' triangles, {}×{}, {} raster samples, {} spp, {} threads\n",
        scene.particles.len(),
        staged.world.meshes.triangles().len(),
        camera.width,
        camera.height,
        raster.samples,
        args.spp,
        pool.current_num_threads()
    );
    println!("| pipeline | method | frame (ms) | cost vs raster-sorted |");
    println!("|---|---|---:|---:|");
    let frames = Frames { count: args.spp, seed: 1, ..Frames::default() };
    let mut baseline = None;
    for (pipeline, name, algorithm) in rows {
        let rendered = rendered_frames(&algorithm, &staged.shot(), &frames);
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat.max(1) {
            let start = Instant::now();
            pool.install(|| algorithm.render_world(&staged.shot(), &frames, &|_| {}))?;
            best = best.min(start.elapsed().as_secs_f64() / rendered);
        }
        let base = *baseline.get_or_insert(best);
        println!("| {pipeline} | {name} | {:.1} | {:.2}× |", 1e3 * best, best / base);
    }
    Ok(())
}

/// What the adapter's storage bindings let the GPU paths hold: bindings a stage and their size,
/// and the most particles like the scene's (its SH degree and storage) the ray tracer and the
/// splatting kernels bind, the bound of issue 39 that device memory may undercut.
fn binding_budget(
    ctx: &splat_gpu::GpuContext,
    scene: &splat_core::Scene,
    settings: &splat_core::RenderSettings,
) -> String {
    let mib = |bytes: u64| bytes as f64 / f64::from(1 << 20);
    format!(
        "bindings: {} storage buffers a stage of at most {:.0} MiB each (binding arrays: {}); \
         they hold {} particles like these (SH degree {}, {:?}) in the ray tracer, {} in the splatting kernels; \
         device memory may bound them first",
        ctx.storage_buffers_per_stage(),
        mib(ctx.max_binding),
        match ctx.binding_array_elements_per_stage() {
            0 => "none, a split array's parts bind one each".to_string(),
            n => format!("{n} buffers a stage, a split array's parts bind as one"),
        },
        splat_gpu::TraceSplit::capacity(ctx, scene.sh_degree, settings.sh_storage),
        scene.sh_degree,
        settings.sh_storage,
        splat_gpu::RasterSplit::capacity(ctx),
    )
}

/// Frame times of every method on the GPU, as ratios against `stochastic` measured in the same
/// run (wall time around submit and poll; the opaque baseline exists on the CPU only).
fn run_gpu(args: &BenchArgs, ctx: &splat_gpu::GpuContext) -> Result<()> {
    let (scene, camera, settings) = args.scene.load(1200, 800)?;
    splat_gpu::TraceSplit::at_least(ctx, &scene, &settings)?;
    let trace = TraceScene::new(&scene, settings)?;
    let pipeline = splat_gpu::TracePipeline::new(ctx)?;
    let tracer = splat_gpu::GpuTracer::new(ctx, &pipeline, &trace)?;
    println!(
        "{} particles on {}, {}×{} at {} spp, {}; scene arrays {:.0} bytes a splat on the device\n",
        scene.particles.len(),
        ctx.describe(),
        camera.width,
        camera.height,
        args.spp,
        if ctx.timestamps { "timestamp queries" } else { "wall time around submit + poll" },
        tracer.scene_bytes() as f64 / scene.particles.len().max(1) as f64
    );
    println!("{}\n", binding_budget(ctx, &scene, &settings));
    println!(
        "| method | frame (ms) | Mrays/s | cost vs stochastic | dispatches a frame | host waits a frame | loop steps a pixel |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let mut methods = vec![MethodId::Stochastic];
    methods.extend(args.methods.iter().copied().filter(|&m| m != MethodId::Stochastic && m != MethodId::Opaque));
    let pixels = f64::from(camera.width) * f64::from(camera.height);
    let mut baseline = None;
    for m in methods {
        let method = args.options.method(m)?;
        let frames = Frames { count: args.spp, seed: 1, rng: args.options.rng(), ..Frames::default() };
        let rendered = rendered_frames(&splat_core::Algorithm::Trace(method), &tracer.trace().shot(&camera), &frames);
        let name = m.name();
        let mut best = f64::INFINITY;
        let mut work = splat_gpu::GpuCounters::default();
        let mut steps = 0.0;
        for _ in 0..args.repeat.max(1) {
            let before = ctx.counters();
            match tracer.render(&camera, &method, &frames) {
                Ok((_, stats)) => {
                    best = best.min(stats.gpu_time.as_secs_f64() / rendered);
                    work = ctx.counters() - before;
                    steps = stats.mean_loop_iterations;
                }
                Err(e) => {
                    println!("| {name} | refused: {e} | | | | | |");
                    break;
                }
            }
        }
        if best.is_finite() {
            let base = *baseline.get_or_insert(best);
            let (dispatches, waits) = (work.dispatches as f64 / rendered, work.waits as f64 / rendered);
            println!(
                "| {name} | {:.1} | {:.3} | {:.2}× | {dispatches:.2} | {waits:.2} | {steps:.1} |",
                1e3 * best,
                pixels / best / 1e6,
                best / base
            );
        }
    }
    Ok(())
}

/// The splatting path on the GPU: at one sample per pixel, stage by stage in one run
/// (projection, depth sort, sorted (over) draw, and a StochasticSplats draw at 1 spp; frames as
/// ratios to the sorted frame); then the frame of every raster method named, at
/// `--raster-samples`, against raster-sorted's in the same run ([`raster_methods_gpu`]).
fn run_raster_gpu(args: &BenchArgs, ctx: &splat_gpu::GpuContext) -> Result<()> {
    let (scene, camera, settings) = args.scene.load(1200, 800)?;
    let mut options = args.options.clone();
    options.apply_capture(&scene);
    let pipes = splat_gpu::RasterPipelines::new(ctx)?;
    let gpu_scene = splat_gpu::RasterScene::new(ctx, &scene, &settings)?;
    let budget = binding_budget(ctx, &scene, &settings);
    let settings = match options.on_gpu(options.resolve(MethodId::RasterSorted)) {
        splat_core::Algorithm::Raster(_, settings) => settings,
        _ => unreachable!("raster-sorted resolves to a raster algorithm"),
    };
    let raster = splat_gpu::GpuRasterizer::new(ctx, &pipes, &gpu_scene, &camera, &settings)?;
    if settings.samples > 1 || settings.fragment_depth != splat_core::raster::FragmentDepth::Center {
        println!("{} particles on {}, {}×{}\n", scene.particles.len(), ctx.describe(), camera.width, camera.height);
        return raster_methods_gpu(args, ctx, &raster, &settings);
    }
    let t = raster.profile(args.repeat)?;
    let visible = raster.order()?.len();
    let n = scene.particles.len();
    let bytes = (gpu_scene.scene_bytes() + raster.camera_bytes()) as f64 / n.max(1) as f64;
    println!(
        "{n} particles ({visible} visible) on {}, {}×{}, fastest of {} runs, {}; scene and camera arrays {bytes:.0} bytes a splat on the device\n",
        ctx.describe(),
        camera.width,
        camera.height,
        args.repeat.max(1),
        if t.timestamps { "timestamp queries" } else { "wall time around submit + poll" }
    );
    println!("{budget}\n");
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let sorted = ms(t.sorted_frame());
    println!("| stage | time (ms) | share of the sorted frame |");
    println!("|---|---:|---:|");
    println!("| projection | {:.2} | {:.0} % |", ms(t.project), 100.0 * ms(t.project) / sorted);
    println!(
        "| depth sort ({n} keys, {visible} visible past its first pass; {} passes of {} bits, {} dispatches; {:.1} Mkeys/s of the scene) | {:.2} | {:.0} % |",
        splat_gpu::sort::pass_count(u32::BITS),
        splat_gpu::sort::RADIX_BITS,
        t.sort_dispatches,
        n as f64 / t.sort.as_secs_f64() / 1e6,
        ms(t.sort),
        100.0 * ms(t.sort) / sorted
    );
    println!("| sorted draw (over) | {:.2} | {:.0} % |", ms(t.draw_sorted), 100.0 * ms(t.draw_sorted) / sorted);
    println!("| **sorted frame** | {sorted:.2} | 100 % |");
    println!("| stochastic-splat draw (1 spp) | {:.2} | |", ms(t.draw_stochastic));
    println!(
        "| **stochastic-splat frame** (projection + draw) | {:.2} | {:.2}× the sorted frame |",
        ms(t.stochastic_frame()),
        ms(t.stochastic_frame()) / sorted
    );
    println!();
    raster_methods_gpu(args, ctx, &raster, &settings)
}

/// The frame of each raster method of `args.methods` on the GPU at `settings` (raster-sorted
/// first, the baseline, and StochasticSplats at both fragment depths: the max-density plane
/// writes frag_depth per sample, which turns off early depth tests), fastest of `--repeat` runs
/// of `--spp` frames after one untimed run. A frame is its draw (or raster operations, with the
/// per-frame shuffle and binning of Enderton and stratified) and the fold; the projection and
/// depth sort run once per camera and are not in it.
fn raster_methods_gpu(
    args: &BenchArgs,
    ctx: &splat_gpu::GpuContext,
    raster: &splat_gpu::GpuRasterizer,
    settings: &splat_core::raster::RasterSettings,
) -> Result<()> {
    use splat_core::raster::{FragmentDepth, RasterSettings};
    let mut methods = vec![MethodId::RasterSorted];
    methods.extend(
        args.methods.iter().copied().filter(|&m| m.entry().family == Family::Raster && m != MethodId::RasterSorted),
    );
    println!(
        "{} samples per pixel ({} pattern), {} frames per run, fastest of {} runs\n",
        settings.samples,
        settings.sample_pattern.name(),
        args.spp,
        args.repeat.max(1)
    );
    println!(
        "| method | fragment depth | frame (ms) | cost vs raster-sorted | dispatches a frame | host waits a frame |"
    );
    println!("|---|---|---:|---:|---:|---:|");
    let mut baseline = None;
    for m in methods {
        let splat_core::Algorithm::Raster(method, _) = args.options.resolve(m) else { continue };
        let depths: &[FragmentDepth] = match m {
            MethodId::RasterSorted => &[FragmentDepth::Center],
            MethodId::StochasticSplat => &[FragmentDepth::Center, FragmentDepth::MaxDensityPlane],
            _ => &[settings.fragment_depth],
        };
        for &depth in depths {
            let at = RasterSettings { fragment_depth: depth, ..*settings };
            let gpu = raster.with_settings(&at)?;
            let frames = Frames { count: args.spp, seed: 1, ..Frames::default() };
            let label = if depth == FragmentDepth::Center { "centre" } else { "max-density plane" };
            let mut best = f64::INFINITY;
            let rendered = f64::from(if method.is_stochastic() { args.spp } else { 1 });
            let mut work = splat_gpu::GpuCounters::default();
            for run in 0..=args.repeat.max(1) {
                let before = ctx.counters();
                match gpu.render(&method, &frames) {
                    Ok((_, stats)) if run > 0 => {
                        best = best.min(stats.gpu_time.as_secs_f64() / rendered);
                        work = ctx.counters() - before;
                    }
                    Ok(_) => {}
                    Err(e) => {
                        println!("| {} | {label} | refused: {e} | | | |", m.name());
                        break;
                    }
                }
            }
            if best.is_finite() {
                let base = *baseline.get_or_insert(best);
                let (dispatches, waits) = (work.dispatches as f64 / rendered, work.waits as f64 / rendered);
                let (name, frame, cost) = (m.name(), 1e3 * best, best / base);
                println!("| {name} | {label} | {frame:.2} | {cost:.2}× | {dispatches:.2} | {waits:.2} |");
            }
        }
    }
    Ok(())
}

/// The splatting path on the CPU reference: one frame of each raster method of `args.methods`
/// (raster-sorted first, the baseline; projection, sort and binning included) at the raster
/// settings of the options, as ratios in one run.
fn run_raster_cpu(args: &BenchArgs) -> Result<()> {
    use splat_core::raster::{Rasterizer, render_raster};
    let (scene, camera, settings) = args.scene.load(1200, 800)?;
    let mut options = args.options.clone();
    options.apply_capture(&scene);
    let pool = args.scene.pool()?;
    let raster = options.raster_settings();
    println!(
        "{} particles, {}×{}, CPU reference, {} samples per pixel ({} pattern), {} threads, fastest of {} runs\n",
        scene.particles.len(),
        camera.width,
        camera.height,
        raster.samples,
        raster.sample_pattern.name(),
        pool.current_num_threads(),
        args.repeat.max(1)
    );
    println!("| method | frame (ms) | cost vs raster-sorted |");
    println!("|---|---:|---:|");
    let mut methods = vec![MethodId::RasterSorted];
    methods.extend(
        args.methods.iter().copied().filter(|&m| m.entry().family == Family::Raster && m != MethodId::RasterSorted),
    );
    let mut baseline = None;
    for m in methods {
        let splat_core::Algorithm::Raster(method, raster) = options.resolve(m) else { continue };
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat.max(1) {
            let start = Instant::now();
            pool.install(|| -> Result<()> {
                let r = Rasterizer::new(&scene, &camera, settings, raster)?;
                render_raster(&r, &method, &Frames::default(), &|_| {})?;
                Ok(())
            })?;
            best = best.min(start.elapsed().as_secs_f64());
        }
        let base = *baseline.get_or_insert(best);
        println!("| {} | {:.1} | {:.2}× |", m.name(), 1e3 * best, best / base);
    }
    Ok(())
}

/// `--sweep mn`: one frame of `stochastic-n` per (m, n) row, timed (fastest of `--repeat`) and
/// compared with `exact`, on the CPU or the GPU as `--backend` says.
fn run_mn_sweep(args: &BenchArgs) -> Result<()> {
    use splat_core::trace::Method;
    let (scene, camera, settings) = args.scene.load(1200, 800)?;
    let pool = args.scene.pool()?;
    let trace = TraceScene::new(&scene, settings)?;
    let ctx = crate::args::gpu_context(args.scene.backend)?;
    let gpu = match &ctx {
        Some(ctx) => Some((ctx, splat_gpu::TracePipeline::new(ctx)?)),
        None => None,
    };
    let tracer = match &gpu {
        Some((ctx, pipeline)) => Some(splat_gpu::GpuTracer::new(ctx, pipeline, &trace)?),
        None => None,
    };
    let exact = pool.install(|| render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {}))?;
    let device = match &gpu {
        Some((ctx, _)) => ctx.describe(),
        None => format!("CPU, {} threads", pool.current_num_threads()),
    };
    println!(
        "{} particles, {}×{}, {device}, one frame of 1024 samples a pixel per row, fastest of {} runs\n",
        scene.particles.len(),
        camera.width,
        camera.height,
        args.repeat.max(1)
    );
    println!("| m × n | frame (ms) | Msamples/s | speed-up vs 1024 × 1 | RMSE vs exact | max difference vs 1024 × 1 |");
    println!("|---|---:|---:|---:|---:|---:|");
    let samples = f64::from(camera.width) * f64::from(camera.height) * 1024.0;
    let mut baseline: Option<(f64, splat_core::frame::RenderOutput)> = None;
    for (m, n) in MN_ROWS {
        let method = Method::StochasticN { m, n };
        if let Err(e) = method.validate() {
            println!("| {m} × {n} | refused: {e} | | | | |");
            continue;
        }
        let frames = Frames { count: 1, seed: 1, rng: args.options.rng(), ..Frames::default() };
        let mut best = f64::INFINITY;
        let mut image = None;
        for _ in 0..args.repeat.max(1) {
            let start = Instant::now();
            let out = match &tracer {
                Some(tracer) => {
                    let (out, stats) = tracer.render(&camera, &method, &frames)?;
                    best = best.min(stats.gpu_time.as_secs_f64());
                    out
                }
                None => {
                    let out = pool.install(|| render_frames(&trace, &camera, &method, &frames, &|_| {}))?;
                    best = best.min(start.elapsed().as_secs_f64());
                    out
                }
            };
            image = Some(out);
        }
        let image = image.expect("at least one run");
        // The GPU kernel's traversal holds 64 samples: say how it grouped the row's slots.
        let grouped = match &tracer {
            Some(_) => {
                let kernel = splat_gpu::MethodParams::try_from(&method)?;
                if (kernel.m, kernel.n) != (m, n) {
                    format!(" (as {} × {})", kernel.m, kernel.n)
                } else {
                    String::new()
                }
            }
            None => String::new(),
        };
        let rmse = splat_core::stats::rmse(image.mean.data(), exact.mean.data());
        let (base_time, base_image) = baseline.get_or_insert((best, image.clone()));
        let diff =
            image.mean.data().iter().zip(base_image.mean.data()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        println!(
            "| {m} × {n}{grouped} | {:.1} | {:.2} | {:.2}× | {rmse:.5} | {diff:.1e} |",
            1e3 * best,
            samples / best / 1e6,
            *base_time / best
        );
    }
    println!(
        "\nEvery row draws the same 1024 decisions a pixel (a decision is keyed by its sample's index,\n\
         not by the traversal that draws it), so the images agree and the rows differ in time only."
    );
    if tracer.is_some() {
        println!(
            "A traversal of the GPU kernel holds {} samples; a row with more runs as traversals of a\n\
             divisor of n (\"as m × n\"): the same slots, the same image, another cost.",
            splat_core::trace::MAX_HITS
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::Algorithm;
    use splat_core::lighting::{Light, LightKind, Lighting, Material, Shadows, SplatSet};
    use splat_core::raster::{Blend, RasterMethod, RasterSettings};
    use splat_core::trace::Method;

    /// Frame times divide by the frames a render draws: one for a deterministic method (the
    /// opaque baseline, exact, sorted splatting), every frame for a stochastic one or where the
    /// lighting draws (stochastic shadows), so that an N-spp run compares frames with frames.
    #[test]
    fn frame_times_divide_by_the_frames_drawn() {
        let (scene, camera) = splat_core::scenes::layers();
        let settings = splat_core::RenderSettings::default();
        let frames = Frames { count: 8, ..Frames::default() };
        let trace = TraceScene::new(&scene, settings).unwrap();
        let sorted = Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Under }, RasterSettings::default());
        for (algorithm, expected) in [
            (Algorithm::Trace(Method::Opaque), 1.0),
            (Algorithm::Trace(Method::Exact), 1.0),
            (Algorithm::Trace(Method::Stochastic), 8.0),
            (sorted, 1.0),
        ] {
            assert_eq!(rendered_frames(&algorithm, &trace.shot(&camera), &frames), expected, "{algorithm:?}");
        }
        // Diffuse splats under a directional light, shadowed by stochastic shadow rays.
        let shadowed = Lighting {
            sets: vec![SplatSet { first: 0, material: Material::DIFFUSE }],
            lights: vec![Light {
                kind: LightKind::Directional { direction: glam::Vec3::new(0.0, -1.0, -1.0).normalize() },
                color: glam::Vec3::ONE,
                intensity: 1.0,
                radius: 0.0,
            }],
            shadows: Shadows::Stochastic,
            ..Lighting::default()
        };
        let lit = TraceScene::new(&scene, settings).unwrap().with_lighting(&shadowed).unwrap();
        assert_eq!(rendered_frames(&Algorithm::Trace(Method::Exact), &lit.shot(&camera), &frames), 8.0);
    }
}
