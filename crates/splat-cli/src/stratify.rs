//! `splat stratify`: the stratification gain of Laine & Karras (their Table 1) — RMSE of one
//! frame of `stratified` divided by that of `enderton`, at S = 4 … 64 samples per pixel, on the
//! two layered fixtures drawn in random order, with a side-by-side image.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Frames;
use splat_core::RenderSettings;
use splat_core::raster::{Blend, RasterMethod, RasterSettings, Rasterizer, render_raster};
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
}

/// Samples per pixel of Table 1.
const SAMPLES: [u32; 5] = [4, 8, 16, 32, 64];
/// Rows of the side-by-side image.
const IMAGE_SAMPLES: [u32; 3] = [4, 16, 64];

/// RMSE in 8-bit units of single frames of `method` against sorted splatting, root mean square
/// over `frames` frames; also frame 0's image.
fn frame_rmse(r: &Rasterizer, method: &RasterMethod, reference: &Image, frames: u32) -> Result<(f64, Image)> {
    let mut sum = 0.0;
    let mut first = None;
    for seed in 0..frames {
        let out = render_raster(r, method, &Frames { count: 1, seed, ..Frames::default() }, &|_| {})?;
        sum += rmse(out.mean.data(), reference.data()).powi(2);
        first.get_or_insert(out.mean);
    }
    Ok((255.0 * (sum / f64::from(frames)).sqrt(), first.context("at least one frame")?))
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
    let mut table =
        String::from("| scene | S | stratified RMSE | enderton RMSE | ratio |\n|---|---:|---:|---:|---:|\n");
    let mut tiles: Vec<Vec<Image>> = Vec::new();
    for name in &args.scenes {
        let (scene, camera) = scenes::by_name(name)
            .with_context(|| format!("unknown scene '{name}' (built-in: {})", scenes::NAMES.join(", ")))?;
        for samples in SAMPLES {
            let raster = RasterSettings { samples, ..RasterSettings::default() };
            let r = Rasterizer::new(&scene, &camera, settings, raster)?;
            let sorted = RasterMethod::Sorted { blend: Blend::Under };
            let reference = render_raster(&r, &sorted, &Frames::default(), &|_| {})?.mean;
            let (ours, ours_image) =
                frame_rmse(&r, &RasterMethod::Stratified { scramble: true }, &reference, args.frames)?;
            let (theirs, theirs_image) = frame_rmse(&r, &RasterMethod::Enderton, &reference, args.frames)?;
            let _ = writeln!(table, "| {name} | {samples} | {ours:.2} | {theirs:.2} | {:.2} |", ours / theirs);
            if IMAGE_SAMPLES.contains(&samples) {
                tiles.push(vec![theirs_image, ours_image, reference]);
            }
        }
    }
    print!("{table}");
    let png = args.output.with_extension("png");
    splat_io::image::write_image(&png, &mosaic(&tiles))?;
    eprintln!("wrote {} (columns: enderton, stratified, sorted; rows: S = 4, 16, 64 per scene)", png.display());
    Ok(())
}

/// Images laid out in a grid (rows × columns) with a 4-pixel grey gutter.
fn mosaic(rows: &[Vec<Image>]) -> Image {
    let gap = 4;
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
