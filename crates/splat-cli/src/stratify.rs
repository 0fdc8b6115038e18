//! `splat stratify`: the stratification gain of Laine & Karras (their Table 1) — RMSE of one
//! frame of `stratified` divided by that of `enderton`, at S = 4 … 64 samples per pixel, on the
//! two layered fixtures drawn in random order, with a side-by-side image. With `--backend gpu`
//! the GPU's rows (S = 4, 8, 16 at the standard sample pattern) stand beside the CPU's.

use crate::args::SamplePatternArg;
use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Frames;
use splat_core::RenderSettings;
use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, SamplePattern, render_raster};
use splat_core::stats::rmse;
use splat_core::{Image, KernelParams, scenes};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `splat stratify`.
#[derive(Args)]
pub struct StratifyArgs {
    /// Built-in layered scenes to measure, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "plates,cloth")]
    pub scenes: Vec<String>,
    /// Frames (independent draws, each in its own random order) the RMSE is averaged over.
    #[arg(long, default_value_t = 16)]
    pub frames: u32,
    /// Kernel degree (8: flat plates of near-constant alpha, like the paper's polygons).
    #[arg(long, default_value_t = scenes::PLATE_KERNEL_DEGREE)]
    pub kernel_degree: u32,
    /// Output prefix: writes PREFIX.png (Enderton | stratified | sorted, rows S = 4, 16, 64).
    #[arg(short, long, default_value = "stratification")]
    pub output: PathBuf,
    /// Sample positions of the CPU rows (the GPU's rows are at the standard pattern, the
    /// hardware's; the standard pattern has no 32 or 64, whose rows stay Hammersley).
    #[arg(long, value_enum, default_value = "hammersley")]
    pub sample_pattern: SamplePatternArg,
    /// cpu: the CPU reference only; gpu: also the GPU's rows at S = 4, 8 and 16.
    #[arg(long, value_enum, default_value = "cpu")]
    pub backend: StratifyBackend,
}

/// Where `splat stratify` renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StratifyBackend {
    /// The CPU reference.
    Cpu,
    /// The CPU reference and the GPU beside it.
    Gpu,
}

/// Samples per pixel of Table 1.
const SAMPLES: [u32; 5] = [4, 8, 16, 32, 64];
/// Rows of the side-by-side image.
const IMAGE_SAMPLES: [u32; 3] = [4, 16, 64];

/// RMSE in 8-bit units of single frames of a method (`frame(seed)`) against sorted splatting,
/// root mean square over `frames` frames; also frame 0's image.
fn frame_rmse(frame: impl Fn(u32) -> Result<Image>, reference: &Image, frames: u32) -> Result<(f64, Image)> {
    let mut sum = 0.0;
    let mut first = None;
    for seed in 0..frames {
        let image = frame(seed)?;
        sum += rmse(image.data(), reference.data()).powi(2);
        first.get_or_insert(image);
    }
    Ok((255.0 * (sum / f64::from(frames)).sqrt(), first.context("at least one frame")?))
}

/// One frame of seed `seed`.
fn one(seed: u32) -> Frames {
    Frames { count: 1, seed, ..Frames::default() }
}

/// The pattern of the CPU rows at `samples`: the one asked for where it has that count.
fn cpu_pattern(args: &StratifyArgs, samples: u32) -> SamplePattern {
    match args.sample_pattern {
        SamplePatternArg::Standard if SamplePattern::Standard.has(samples) => SamplePattern::Standard,
        _ => SamplePattern::Hammersley,
    }
}

/// Run `splat stratify`.
pub fn run(args: StratifyArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let settings = RenderSettings {
        kernel: KernelParams { degree: args.kernel_degree, ..KernelParams::default() },
        ..Default::default()
    };
    let ctx = match args.backend {
        StratifyBackend::Gpu => Some(splat_gpu::GpuContext::new()?),
        StratifyBackend::Cpu => None,
    };
    let pipes = ctx.as_ref().map(splat_gpu::RasterPipelines::new).transpose()?;
    let mut table = String::from(
        "| scene | S | backend | pattern | stratified RMSE | enderton RMSE | ratio |\n|---|---:|---|---|---:|---:|---:|\n",
    );
    let mut row = |name: &str, samples, backend, pattern: SamplePattern, ours: f64, theirs: f64| {
        let _ = writeln!(
            table,
            "| {name} | {samples} | {backend} | {} | {ours:.3} | {theirs:.3} | {:.2} |",
            pattern.name(),
            ours / theirs
        );
    };
    let stratified = RasterMethod::Stratified { scramble: true };
    let mut tiles: Vec<Vec<Image>> = Vec::new();
    let (mut labels, mut rmses) = (Vec::new(), Vec::new());
    for name in &args.scenes {
        let (scene, camera) = scenes::by_name(name)
            .with_context(|| format!("unknown scene '{name}' (built-in: {})", scenes::NAMES.join(", ")))?;
        for samples in SAMPLES {
            let pattern = cpu_pattern(&args, samples);
            let raster = RasterSettings { samples, sample_pattern: pattern, ..RasterSettings::default() };
            let r = Rasterizer::new(&scene, &camera, settings, raster)?;
            let sorted = RasterMethod::Sorted { blend: Blend::Under };
            let reference = render_raster(&r, &sorted, &Frames::default(), &|_| {})?.mean;
            let r = &r;
            let cpu_frame = |method| move |seed| Ok(render_raster(r, &method, &one(seed), &|_| {})?.mean);
            let (ours, ours_image) = frame_rmse(cpu_frame(stratified), &reference, args.frames)?;
            let (theirs, theirs_image) = frame_rmse(cpu_frame(RasterMethod::Enderton), &reference, args.frames)?;
            row(name, samples, "cpu", pattern, ours, theirs);
            if IMAGE_SAMPLES.contains(&samples) {
                tiles.push(vec![theirs_image, ours_image, reference]);
                labels.push(format!("{name}, S = {samples}"));
                rmses.push([theirs, ours]);
            }
            if let (Some(ctx), Some(pipes)) = (&ctx, &pipes)
                && SamplePattern::Standard.has(samples)
            {
                let (ours, theirs) = gpu_rmse(ctx, pipes, &scene, &camera, settings, samples, args.frames)?;
                row(name, samples, "gpu", SamplePattern::Standard, ours, theirs);
            }
        }
    }
    print!("{table}");
    let png = args.output.with_extension("png");
    write_labelled(&png, &tiles, &labels, &rmses)?;
    eprintln!("wrote {} (columns: enderton, stratified, sorted; rows: S = 4, 16, 64 per scene)", png.display());
    Ok(())
}

/// The GPU's stratified and Enderton frame RMSE at `samples` standard samples, against the CPU's
/// sorted splatting with the same samples.
fn gpu_rmse(
    ctx: &splat_gpu::GpuContext,
    pipes: &splat_gpu::RasterPipelines,
    scene: &splat_core::Scene,
    camera: &splat_core::Camera,
    settings: RenderSettings,
    samples: u32,
    frames: u32,
) -> Result<(f64, f64)> {
    let raster = RasterSettings { samples, sample_pattern: SamplePattern::Standard, ..RasterSettings::default() };
    let cpu = Rasterizer::new(scene, camera, settings, raster)?;
    let reference =
        render_raster(&cpu, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {})?.mean;
    let gpu_scene = splat_gpu::RasterScene::new(ctx, scene, &settings)?;
    let gpu = splat_gpu::GpuRasterizer::new(ctx, pipes, &gpu_scene, camera, &raster)?;
    let gpu = &gpu;
    let gpu_frame = |method| move |seed| Ok(gpu.render(&method, &one(seed))?.0.mean);
    let (ours, _) = frame_rmse(gpu_frame(RasterMethod::Stratified { scramble: true }), &reference, frames)?;
    let (theirs, _) = frame_rmse(gpu_frame(RasterMethod::Enderton), &reference, frames)?;
    Ok((ours, theirs))
}

/// The gutter between the mosaic's images, in pixels.
const GAP: u32 = 4;

/// The mosaic as a PNG with its legend: the columns' names above, each row's scene and S to
/// its left, and each method's frame RMSE against sorted splatting (in 8-bit levels, as the
/// table) under it, so that the picture reads without the table.
fn write_labelled(path: &std::path::Path, tiles: &[Vec<Image>], rows: &[String], rmses: &[[f64; 2]]) -> Result<()> {
    use plotters::prelude::*;
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let body = mosaic(tiles);
    let (tile_w, tile_h) = tiles.iter().flatten().fold((0, 0), |(w, h), i| (w.max(i.width()), h.max(i.height())));
    let (left, top, below) = (130u32, 24u32, 16u32);
    let (w, h) = (left + body.width(), top + body.height() + below);
    let mut rgb = vec![255u8; 3 * (w * h) as usize];
    for y in 0..body.height() {
        for x in 0..body.width() {
            let i = 3 * ((top + y) * w + left + x) as usize;
            for (c, v) in body.pixel(x, y).iter().enumerate() {
                rgb[i + c] = splat_core::image::to_u8(*v);
            }
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let coloured = |s: &str, (x, y): (u32, u32), size: u32, colour: &RGBColor| {
            root.draw_text(s, &("sans-serif", size).into_font().color(colour), (x as i32, y as i32))
        };
        let text = |s: &str, at, size| coloured(s, at, size, &BLACK);
        let column_x = |c: u32| left + GAP + c * (tile_w + GAP);
        let row_y = |r: u32| top + GAP + r * (tile_h + GAP);
        for (c, name) in ["Enderton", "stratified", "sorted (reference)"].iter().enumerate() {
            text(name, (column_x(c as u32), 4), 15).map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        for (r, (label, rmse)) in rows.iter().zip(rmses).enumerate() {
            let y = row_y(r as u32);
            text(label, (6, y + tile_h / 2 - 8), 14).map_err(|e| anyhow::anyhow!("{e}"))?;
            for (c, value) in rmse.iter().enumerate() {
                let at = (column_x(c as u32) + 2, y + tile_h.saturating_sub(14));
                coloured(&format!("RMSE {value:.2}"), at, 12, &WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
            }
        }
        text(
            "RMSE of one frame against sorted splatting, in 8-bit levels (0-255), over the frames",
            (6, h - below + 1),
            12,
        )
        .map_err(|e| anyhow::anyhow!("{e}"))?;
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let image = image::RgbImage::from_raw(w, h, rgb).expect("3 bytes a pixel");
    image.save(path).map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
}

/// Images laid out in a grid (rows × columns) with a [`GAP`]-pixel grey gutter.
fn mosaic(rows: &[Vec<Image>]) -> Image {
    let gap = GAP;
    let (w, h) = rows.iter().flatten().fold((0, 0), |(w, h), i| (w.max(i.width()), h.max(i.height())));
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let mut out = Image::filled(cols * (w + gap) + gap, rows.len() as u32 * (h + gap) + gap, 3, 0.5);
    for (r, row) in rows.iter().enumerate() {
        for (c, image) in row.iter().enumerate() {
            let (x0, y0) = (gap + c as u32 * (w + gap), gap + r as u32 * (h + gap));
            for y in 0..image.height() {
                for x in 0..image.width() {
                    out.pixel_mut(x0 + x, y0 + y).copy_from_slice(image.pixel(x, y));
                }
            }
        }
    }
    out
}
