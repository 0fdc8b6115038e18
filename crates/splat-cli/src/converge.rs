//! `splat converge`: RMSE of each method at spp 1, 2, 4, … against its oracle — ray-traced
//! `exact` for the ray-tracing methods, `raster-sorted` (same samples) for the raster methods —
//! as CSV, a PNG plot and a Markdown table.

use crate::args::{BackendArg, MethodOptions, SceneArgs, method_parser, progress_bar};
use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::raster::{Blend, RasterMethod, Rasterizer, render_raster};
use splat_core::stats::{log_log_fit, rmse};
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Algorithm, Frames, MethodId};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `splat converge`.
#[derive(Args)]
pub struct ConvergeArgs {
    /// The scene, camera and shading.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Methods to measure, comma separated (default: stochastic, stochastic-n, stochastic-pass
    /// and depth-sampling-k; with --pipeline path: stochastic, stochastic-n and exact).
    #[arg(help_heading = "Measurement", long, value_parser = method_parser(), value_delimiter = ',')]
    pub methods: Option<Vec<MethodId>>,
    /// Largest spp (a power of two).
    #[arg(help_heading = "Measurement", long, default_value_t = 1024)]
    pub max_spp: u32,
    /// Output prefix: writes PREFIX.csv and PREFIX.png.
    #[arg(help_heading = "Measurement", short, long, default_value = "converge")]
    pub output: PathBuf,
    /// The method's parameters.
    #[command(flatten)]
    pub options: MethodOptions,
    /// `path`: converge the path tracer's Gaussian estimators (stochastic, stochastic-n, exact)
    /// on a world file against a long exact-compositing path-traced reference.
    #[arg(help_heading = "Measurement", long, value_enum)]
    pub pipeline: Option<crate::render::PipelineArg>,
    /// Path tracer: samples per pixel of the exact-compositing reference (hash sampler).
    #[arg(help_heading = "Measurement", long, default_value_t = 2048)]
    pub reference_spp: u32,
    /// Path tracer: the RMSE whose time to reach each method's table reports.
    #[arg(help_heading = "Measurement", long, default_value_t = 0.01)]
    pub target_rmse: f64,
    /// The path tracer's options.
    #[command(flatten)]
    pub path: crate::render::PathOptions,
}

/// One measurement.
struct Row {
    method: &'static str,
    spp: u32,
    rmse: f64,
    seconds: f64,
}

/// Run `splat converge`.
pub fn run(mut args: ConvergeArgs) -> Result<()> {
    if args.scene.backend == BackendArg::Gpu {
        bail!("splat converge runs on the CPU tracer; the GPU kernels are compared with it by the test suite");
    }
    crate::args::check_output(&args.output.with_extension("csv"), "-o")?;
    if !args.max_spp.is_power_of_two() {
        bail!("--max-spp must be a power of two, not {}", args.max_spp);
    }
    match args.pipeline {
        Some(crate::render::PipelineArg::Path) => return run_path(&args),
        Some(other) => {
            bail!("converge measures the ray-tracing and raster families, or --pipeline path (not {other:?})")
        }
        None => {}
    }
    let methods = args.methods.clone().unwrap_or_else(|| {
        vec![MethodId::Stochastic, MethodId::StochasticN, MethodId::StochasticPass, MethodId::DepthSampling]
    });
    let (scene, camera, settings) = args.scene.load(160, 120)?;
    args.options.apply_capture(&scene);
    let trace = TraceScene::new(&scene, settings)?;
    let exact = render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {})?;
    // The raster oracle, projected and rendered only when a raster method is measured.
    let any_raster = methods.iter().any(|&m| matches!(args.options.resolve(m), Algorithm::Raster(..)));
    let raster = if any_raster {
        let raster = Rasterizer::new(&scene, &camera, settings, args.options.raster_settings())?;
        let under = RasterMethod::Sorted { blend: Blend::Under };
        let sorted = render_raster(&raster, &under, &Frames::default(), &|_| {})?;
        eprintln!(
            "raster-sorted against ray-traced exact: RMSE {:.5} (the EWA projection and {} against ray-traced Eq. 3)",
            rmse(sorted.mean.data(), exact.mean.data()),
            args.options.raster_settings().extent.describe()
        );
        Some((raster, sorted))
    } else {
        None
    };
    let levels: Vec<u32> = (0..).map(|i| 1u32 << i).take_while(|&s| s <= args.max_spp).collect();
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let total: u64 = levels.iter().map(|&s| u64::from(s)).sum::<u64>() * methods.len() as u64;
    let bar = progress_bar(pixels * total);
    let mut rows = Vec::new();
    for &m in &methods {
        let method = args.options.resolve(m);
        for &spp in &levels {
            let frames = args.options.frames(spp, spp);
            let progress = |n| bar.inc(n * u64::from(spp));
            let start = Instant::now();
            let (out, reference) = match method {
                Algorithm::Oracle => bail!("the oracle is the reference, not a method to converge"),
                Algorithm::Hybrid(..) => bail!("converge runs the ray-tracing or the raster family, not hybrid"),
                Algorithm::Trace(t) => (render_frames(&trace, &camera, &t, &frames, &progress)?, &exact),
                Algorithm::Raster(r, _) => {
                    let (raster, sorted) = raster.as_ref().context("raster reference")?;
                    (render_raster(raster, &r, &frames, &progress)?, sorted)
                }
            };
            let seconds = start.elapsed().as_secs_f64();
            rows.push(Row { method: m.name(), spp, rmse: rmse(out.mean.data(), reference.mean.data()), seconds });
        }
    }
    bar.finish_and_clear();
    report(&args, &rows, &methods, "RMSE against the oracle (exact, or raster-sorted)", "")
}

/// Write PREFIX.csv and PREFIX.png and print the table of `rows`, then `extra`.
fn report(args: &ConvergeArgs, rows: &[Row], methods: &[MethodId], caption: &str, extra: &str) -> Result<()> {
    let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
    let csv = args.output.with_extension("csv");
    std::fs::write(&csv, to_csv(rows)).with_context(|| format!("writing {}", csv.display()))?;
    let png = args.output.with_extension("png");
    plot(&png, rows, &names, caption)?;
    print!("{}{extra}", to_markdown(rows, &names));
    eprintln!("wrote {} and {}", csv.display(), png.display());
    Ok(())
}

/// `splat converge --pipeline path`: RMSE and time of each Gaussian estimator inside the path
/// tracer at spp 1, 2, 4, … against an exact-compositing reference of `--reference-spp` samples
/// (hash sampler, its own seed), and the time each needs to reach `--target-rmse` (RMSE ∝
/// spp^−½ fitted at the largest spp, times the measured time per sample).
fn run_path(args: &ConvergeArgs) -> Result<()> {
    use splat_core::path::sampler::SamplerKind;
    use splat_core::path::{GaussianEstimator, PathSettings, PathTracer};
    let methods =
        args.methods.clone().unwrap_or_else(|| vec![MethodId::Stochastic, MethodId::StochasticN, MethodId::Exact]);
    let estimators: Vec<GaussianEstimator> =
        methods.iter().map(|&m| crate::render::gaussian_estimator(m, &args.options)).collect::<Result<_>>()?;
    let staged = args.scene.load_world(160, 120)?;
    let trace = TraceScene::new(&staged.world.scene, staged.settings)?
        .with_lighting(&staged.world.lighting)?
        .with_meshes(&staged.world.meshes);
    let camera = &staged.camera;
    let base = crate::render::path_options_settings(&args.path, &staged, GaussianEstimator::Exact)?;
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let levels: Vec<u32> = (0..).map(|i| 1u32 << i).take_while(|&s| s <= args.max_spp).collect();
    let total =
        u64::from(args.reference_spp) + levels.iter().map(|&s| u64::from(s)).sum::<u64>() * methods.len() as u64;
    let bar = progress_bar(pixels * total);
    let reference_settings = PathSettings { sampler: SamplerKind::Hash, ..base };
    let frames = Frames { count: args.reference_spp, seed: u32::MAX, ..Frames::default() };
    let progress = |n| bar.inc(n * u64::from(args.reference_spp));
    let reference = args
        .scene
        .pool()?
        .install(|| PathTracer::new(&trace, reference_settings)?.render(camera, &frames, &progress))?;
    let mut rows = Vec::new();
    for (&m, &gaussians) in methods.iter().zip(&estimators) {
        let tracer = PathTracer::new(&trace, PathSettings { gaussians, ..base })?;
        for &spp in &levels {
            let frames = Frames { count: spp, seed: spp, accumulation: args.options.accumulation, ..Frames::default() };
            let progress = |n| bar.inc(n * u64::from(spp));
            let start = Instant::now();
            let out = args.scene.pool()?.install(|| tracer.render(camera, &frames, &progress))?;
            let seconds = start.elapsed().as_secs_f64();
            rows.push(Row { method: m.name(), spp, rmse: rmse(out.mean.data(), reference.mean.data()), seconds });
        }
    }
    bar.finish_and_clear();
    let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
    let times = time_to_rmse(&rows, &names, args.target_rmse);
    report(args, &rows, &methods, "RMSE against the exact-compositing path tracer", &times)
}

/// Each method's time to reach `target`: RMSE = c / √spp fitted at its largest spp, times its
/// time per sample over all levels; as ratios against the first method.
fn time_to_rmse(rows: &[Row], methods: &[&str], target: f64) -> String {
    let mut s = format!(
        "\n| method | ms/spp | RMSE·√spp | time to RMSE {target} (s) | vs {} |\n|---|---:|---:|---:|---:|\n",
        methods[0]
    );
    let mut first = None;
    for m in methods {
        let of: Vec<&Row> = rows.iter().filter(|r| r.method == *m).collect();
        let Some(last) = of.iter().max_by_key(|r| r.spp) else { continue };
        let per_spp = of.iter().map(|r| r.seconds).sum::<f64>() / of.iter().map(|r| f64::from(r.spp)).sum::<f64>();
        let c = last.rmse * f64::from(last.spp).sqrt();
        let time = per_spp * (c / target).powi(2);
        let base = *first.get_or_insert(time);
        let _ = writeln!(s, "| {m} | {:.2} | {c:.4} | {time:.2} | {:.2}× |", 1e3 * per_spp, time / base);
    }
    s
}

fn to_csv(rows: &[Row]) -> String {
    let mut s = String::from("method,spp,rmse,seconds,seconds_per_spp\n");
    for r in rows {
        let _ =
            writeln!(s, "{},{},{:.6e},{:.4},{:.6}", r.method, r.spp, r.rmse, r.seconds, r.seconds / f64::from(r.spp));
    }
    s
}

/// A table: one row per spp, RMSE and time per spp for each method, and the log–log slopes
/// with the standard error of the fit.
fn to_markdown(rows: &[Row], methods: &[&str]) -> String {
    let mut s = String::from("| spp |");
    for m in methods {
        let _ = write!(s, " {m} RMSE | {m} ms/spp |");
    }
    s += "\n|---:|";
    s += &"---:|---:|".repeat(methods.len());
    s += "\n";
    let mut spps: Vec<u32> = rows.iter().map(|r| r.spp).collect();
    spps.sort_unstable();
    spps.dedup();
    for spp in spps {
        let _ = write!(s, "| {spp} |");
        for m in methods {
            if let Some(r) = rows.iter().find(|r| r.method == *m && r.spp == spp) {
                let _ = write!(s, " {:.5} | {:.1} |", r.rmse, 1e3 * r.seconds / f64::from(spp));
            }
        }
        s += "\n";
    }
    s += "| slope |";
    for m in methods {
        let (x, y): (Vec<f64>, Vec<f64>) =
            rows.iter().filter(|r| r.method == *m).map(|r| (f64::from(r.spp), r.rmse.max(1e-12))).unzip();
        let (slope, stderr) = log_log_fit(&x, &y);
        let _ = write!(s, " {slope:.3} ± {stderr:.3} | |");
    }
    s + "\n"
}

/// Log–log plot of RMSE against spp, one line per method, with the 1/√spp reference.
fn plot(path: &std::path::Path, rows: &[Row], methods: &[&str], caption: &str) -> Result<()> {
    use plotters::prelude::*;
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let max_spp = rows.iter().map(|r| r.spp).max().unwrap_or(1).max(2);
    let lo = rows.iter().map(|r| r.rmse).filter(|&v| v > 0.0).fold(f64::INFINITY, f64::min).min(1.0);
    let hi = rows.iter().map(|r| r.rmse).fold(0.0f64, f64::max).max(lo * 10.0);
    // Drawn into a buffer and encoded with `image` (plotters' own encoder would pull in a second
    // `image` and `png`).
    let (width, height) = (900u32, 620u32);
    let mut pixels = vec![0u8; 3 * (width * height) as usize];
    draw_plot(&mut pixels, (width, height), rows, methods, caption, lo, hi, max_spp)
        .map_err(|e| anyhow::anyhow!("plotting {}: {e}", path.display()))?;
    let png = image::RgbImage::from_raw(width, height, pixels).expect("3 bytes a pixel");
    png.save(path).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
}

/// Draw the plot of [`plot`] into an RGB8 buffer of `size`.
#[allow(clippy::too_many_arguments)]
fn draw_plot(
    pixels: &mut [u8],
    size: (u32, u32),
    rows: &[Row],
    methods: &[&str],
    caption: &str,
    lo: f64,
    hi: f64,
    max_spp: u32,
) -> Result<(), String> {
    use plotters::prelude::*;
    let root = BitMapBackend::with_buffer(pixels, size).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| e.to_string();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d((1f64..f64::from(max_spp)).log_scale(), (lo * 0.5..hi * 2.0).log_scale())
        .map_err(|e| err(&e))?;
    // One x label per power of two (at most 11), integers; y labels in scientific notation
    // (plotters' default prints small values as long digit strings).
    let x_labels = (max_spp.ilog2() as usize + 1).min(11);
    chart
        .configure_mesh()
        .x_desc("samples per pixel")
        .y_desc("RMSE")
        .x_labels(x_labels)
        .x_label_formatter(&|x| format!("{}", x.round() as u64))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, m) in methods.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let points: Vec<(f64, f64)> =
            rows.iter().filter(|r| r.method == *m && r.rmse > 0.0).map(|r| (f64::from(r.spp), r.rmse)).collect();
        chart
            .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(*m)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(|e| err(&e))?;
    }
    if let Some(first) = rows.iter().find(|r| r.spp == 1 && r.rmse > 0.0) {
        let reference: Vec<(f64, f64)> =
            (0..=max_spp.ilog2()).map(|i| (f64::from(1u32 << i), first.rmse / f64::from(1u32 << i).sqrt())).collect();
        chart
            .draw_series(LineSeries::new(reference, BLACK.mix(0.4).stroke_width(1)))
            .map_err(|e| err(&e))?
            .label("1/√spp")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.4)));
    }
    // RMSE falls from the upper left: the lower left corner is empty.
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
