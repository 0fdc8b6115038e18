//! `splat stratify`: the stratification gain of Laine & Karras (their Table 1) — RMSE of one
//! frame of `stratified` divided by that of `enderton`, at S = 4 … 64 samples per pixel, on the
//! paper's scenes rebuilt from transparent triangles ([`splat_core::lk_scenes`]: the motor, the
//! cloth, Figures 1, 3b and 8) or on the splat fixtures, with a side-by-side image. `--variants`
//! adds the paper's controls (no sample sorting, Morton pixel order, the Sobol sequence) as more
//! stratified columns. With `--backend gpu` the GPU's rows (S = 4, 8, 16 at the standard sample
//! pattern) stand beside the CPU's.

use crate::args::SamplePatternArg;
use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Frames;
use splat_core::RenderSettings;
use splat_core::raster::{Blend, LkVariant, RasterMethod, RasterSettings, Rasterizer, SamplePattern, render_raster};
use splat_core::stats::rmse;
use splat_core::{Image, KernelParams, lk_scenes, scenes};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `splat stratify`.
#[derive(Args)]
pub struct StratifyArgs {
    /// Scenes to measure, comma separated: transparent-triangle scenes (motor, cloth, figure-1,
    /// stack, smoke) or built-in splat scenes (plates, splat-cloth, …).
    #[arg(long, value_delimiter = ',', default_value = "motor,cloth")]
    pub scenes: Vec<String>,
    /// Samples per pixel of the rows, comma separated.
    #[arg(long, value_delimiter = ',', default_value = "4,8,16,32,64")]
    pub samples: Vec<u32>,
    /// Stratified variants measured, comma separated: paper, unsorted (Figure 6a), morton (§3.1's
    /// pixel order), sobol (Figure 3b).
    #[arg(long, value_delimiter = ',', default_value = "paper")]
    pub variants: Vec<String>,
    /// Measure the error of B × B pixel blocks' means (Figure 1's "clumpy" noise: what the eye
    /// sees from a distance, where a stratified dither cancels between neighbours); 1: pixels.
    #[arg(long, default_value_t = 1)]
    pub block: u32,
    /// Subdivision of the motor and the cloth (triangles of about a sixth of a pixel at the default).
    #[arg(long, default_value_t = lk_scenes::DETAIL)]
    pub detail: u32,
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

/// Rows of the side-by-side image.
const IMAGE_SAMPLES: [u32; 3] = [4, 16, 64];

/// The RMSE of single frames in 8-bit units and its standard error over the frames.
#[derive(Clone, Copy)]
struct FrameRmse {
    rmse: f64,
    se: f64,
}

impl FrameRmse {
    /// `self` ÷ `other` with its standard error (first order, the two independent).
    fn ratio(&self, other: &FrameRmse) -> (f64, f64) {
        let r = self.rmse / other.rmse;
        (r, r * ((self.se / self.rmse).powi(2) + (other.se / other.rmse).powi(2)).sqrt())
    }
}

/// RMSE in 8-bit units of single frames of a method (`frame(seed)`) against sorted splatting,
/// root mean square over `frames` frames, with its standard error (the spread of the frames'
/// mean square errors, through d√x = dx / 2√x); also frame 0's image.
fn frame_rmse(
    frame: impl Fn(u32) -> Result<Image>,
    reference: &Image,
    frames: u32,
    block: u32,
) -> Result<(FrameRmse, Image)> {
    let mut mse = Vec::with_capacity(frames as usize);
    let mut first = None;
    let reference_blocks = block_means(reference, block);
    for seed in 0..frames {
        let image = frame(seed)?;
        mse.push((255.0 * rmse(block_means(&image, block).data(), reference_blocks.data())).powi(2));
        first.get_or_insert(image);
    }
    let n = mse.len() as f64;
    let mean = mse.iter().sum::<f64>() / n;
    let var = if mse.len() > 1 { mse.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    let rmse = mean.sqrt();
    let se = if rmse > 0.0 { (var / n).sqrt() / (2.0 * rmse) } else { 0.0 };
    Ok((FrameRmse { rmse, se }, first.context("at least one frame")?))
}

/// The means of `image`'s `block` × `block` pixel blocks (whole blocks only; the image itself at 1).
fn block_means(image: &Image, block: u32) -> Image {
    if block <= 1 {
        return image.clone();
    }
    let (w, h) = (image.width() / block, image.height() / block);
    let mut out = Image::filled(w.max(1), h.max(1), image.channels(), 0.0);
    for y in 0..h * block {
        for x in 0..w * block {
            let sum = out.pixel_mut(x / block, y / block);
            for (s, v) in sum.iter_mut().zip(image.pixel(x, y)) {
                *s += v / (block * block) as f32;
            }
        }
    }
    out
}

/// A scene to measure: splats or transparent triangles, with its meshes and lighting.
struct Measured {
    scene: splat_core::Scene,
    camera: splat_core::Camera,
    meshes: splat_core::mesh::Meshes,
    lighting: splat_core::lighting::Lighting,
}

fn measured(name: &str, detail: u32) -> Result<Measured> {
    if let Some(m) = lk_scenes::by_name_at(name, detail) {
        return Ok(Measured { scene: m.scene, camera: m.camera, meshes: m.meshes, lighting: m.lighting });
    }
    let splats = if name == "splat-cloth" { "cloth" } else { name };
    let (scene, camera) = scenes::by_name(splats).with_context(|| {
        format!(
            "unknown scene '{name}' (transparent triangles: {}; splats: {})",
            lk_scenes::NAMES.join(", "),
            scenes::NAMES.map(|n| if n == "cloth" { "splat-cloth" } else { n }).join(", ")
        )
    })?;
    Ok(Measured { scene, camera, meshes: Default::default(), lighting: Default::default() })
}

fn variant(name: &str) -> Result<LkVariant> {
    LkVariant::ALL.into_iter().find(|v| v.name() == name).with_context(|| {
        format!("unknown variant '{name}' (one of {})", LkVariant::ALL.map(LkVariant::name).join(", "))
    })
}

/// The frame of seed `seed` of `method` on the CPU.
fn cpu_frame<'a>(r: &'a Rasterizer, method: RasterMethod) -> impl Fn(u32) -> Result<Image> + 'a {
    move |seed| Ok(render_raster(r, &method, &one(seed), &|_| {})?.mean)
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
    if args.block == 0 {
        bail!("--block must be at least 1");
    }
    if !(1..=32).contains(&args.detail) {
        bail!("--detail {} must lie in 1..=32", args.detail);
    }
    if let Some(&s) = args.samples.iter().find(|&&s| !splat_core::raster::SAMPLE_COUNTS.contains(&s)) {
        bail!("--samples {s} is not one of {:?}", splat_core::raster::SAMPLE_COUNTS);
    }
    let variants = args.variants.iter().map(|v| variant(v)).collect::<Result<Vec<_>>>()?;
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
        "| scene | S | backend | pattern | variant | stratified RMSE | enderton RMSE | ratio |\n|---|---:|---|---|---|---:|---:|---:|\n",
    );
    let mut row =
        |name: &str, samples, backend, pattern: SamplePattern, variant: LkVariant, ours: FrameRmse, theirs| {
            let (ratio, se) = ours.ratio(&theirs);
            let _ = writeln!(
                table,
                "| {name} | {samples} | {backend} | {} | {} | {:.3} ± {:.3} | {:.3} ± {:.3} | {ratio:.3} ± {se:.3} |",
                pattern.name(),
                variant.name(),
                ours.rmse,
                ours.se,
                theirs.rmse,
                theirs.se,
            );
        };
    let stratified = RasterMethod::Stratified { scramble: true };
    let mut tiles: Vec<Vec<Image>> = Vec::new();
    let (mut labels, mut rmses) = (Vec::new(), Vec::new());
    for name in &args.scenes {
        let m = measured(name, args.detail)?;
        for &samples in &args.samples {
            let pattern = cpu_pattern(&args, samples);
            let raster = |lk_variant| {
                let raster =
                    RasterSettings { samples, sample_pattern: pattern, lk_variant, ..RasterSettings::default() };
                Ok::<_, anyhow::Error>(
                    Rasterizer::new(&m.scene, &m.camera, settings, raster)?
                        .with_meshes(&m.meshes)
                        .with_lighting(&m.lighting)?,
                )
            };
            let r = raster(LkVariant::Paper)?;
            let sorted = RasterMethod::Sorted { blend: Blend::Under };
            let reference = render_raster(&r, &sorted, &Frames::default(), &|_| {})?.mean;
            let (theirs, theirs_image) =
                frame_rmse(cpu_frame(&r, RasterMethod::Enderton), &reference, args.frames, args.block)?;
            let mut images = vec![theirs_image];
            let mut errors = vec![theirs.rmse];
            for &v in &variants {
                let r = raster(v)?;
                let (ours, ours_image) = frame_rmse(cpu_frame(&r, stratified), &reference, args.frames, args.block)?;
                row(name, samples, "cpu", pattern, v, ours, theirs);
                images.push(ours_image);
                errors.push(ours.rmse);
            }
            if IMAGE_SAMPLES.contains(&samples) || args.samples.len() == 1 {
                images.push(reference);
                tiles.push(images);
                labels.push(format!("{name}, S = {samples}"));
                rmses.push(errors);
            }
            if let (Some(ctx), Some(pipes)) = (&ctx, &pipes)
                && SamplePattern::Standard.has(samples)
            {
                let (ours, theirs) = gpu_rmse(ctx, pipes, &m, settings, samples, args.frames)?;
                row(name, samples, "gpu", SamplePattern::Standard, LkVariant::Paper, ours, theirs);
            }
        }
    }
    if args.block > 1 {
        println!("RMSE of the means of {0} × {0} pixel blocks, in 8-bit levels\n", args.block);
    }
    print!("{table}");
    let png = args.output.with_extension("png");
    let mut columns = vec!["Enderton".to_string()];
    columns.extend(variants.iter().map(|v| match v {
        LkVariant::Paper => "stratified".to_string(),
        v => format!("stratified, {}", v.name()),
    }));
    columns.push("sorted (reference)".into());
    let what = match args.block {
        1 => "RMSE of one frame against sorted splatting, in 8-bit levels (0-255), over the frames".to_string(),
        b => format!(
            "RMSE of {b} x {b} block means of one frame against sorted splatting, in 8-bit levels, over the frames"
        ),
    };
    write_labelled(&png, &tiles, &columns, &labels, &rmses, &what)?;
    eprintln!("wrote {} (columns: {}; rows: scene and S)", png.display(), columns.join(", "));
    Ok(())
}

/// The GPU's stratified and Enderton frame RMSE at `samples` standard samples on scene `m`
/// (its transparent triangles drawn by the raster operations), against the CPU's sorted
/// splatting with the same samples.
fn gpu_rmse(
    ctx: &splat_gpu::GpuContext,
    pipes: &splat_gpu::RasterPipelines,
    m: &Measured,
    settings: RenderSettings,
    samples: u32,
    frames: u32,
) -> Result<(FrameRmse, FrameRmse)> {
    let raster = RasterSettings { samples, sample_pattern: SamplePattern::Standard, ..RasterSettings::default() };
    let cpu =
        Rasterizer::new(&m.scene, &m.camera, settings, raster)?.with_meshes(&m.meshes).with_lighting(&m.lighting)?;
    let reference =
        render_raster(&cpu, &RasterMethod::Sorted { blend: Blend::Under }, &Frames::default(), &|_| {})?.mean;
    let gpu_scene =
        splat_gpu::RasterScene::new_lit(ctx, &m.scene, &settings, &m.lighting)?.with_meshes(ctx, &m.meshes)?;
    let gpu = splat_gpu::GpuRasterizer::new(ctx, pipes, &gpu_scene, &m.camera, &raster)?;
    let gpu = &gpu;
    let gpu_frame = |method| move |seed| Ok(gpu.render(&method, &one(seed))?.0.mean);
    let (ours, _) = frame_rmse(gpu_frame(RasterMethod::Stratified { scramble: true }), &reference, frames, 1)?;
    let (theirs, _) = frame_rmse(gpu_frame(RasterMethod::Enderton), &reference, frames, 1)?;
    Ok((ours, theirs))
}

/// The gutter between the mosaic's images, in pixels.
const GAP: u32 = 4;

/// The mosaic as a PNG with its legend: the columns' names above, each row's scene and S to
/// its left, and each method's frame RMSE against sorted splatting (in 8-bit levels, as the
/// table) under it, so that the picture reads without the table.
fn write_labelled(
    path: &std::path::Path,
    tiles: &[Vec<Image>],
    columns: &[String],
    rows: &[String],
    rmses: &[Vec<f64>],
    caption: &str,
) -> Result<()> {
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
        for (c, name) in columns.iter().enumerate() {
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
        text(caption, (6, h - below + 1), 12).map_err(|e| anyhow::anyhow!("{e}"))?;
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
