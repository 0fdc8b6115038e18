//! `splat compare`: how far apart two images are, by RMSE, PSNR, SSIM and ꟻLIP, with error maps.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Image;
use std::path::{Path, PathBuf};

/// ꟻLIP's default observer: 0.7 m from a 0.7 m wide 4K monitor.
pub use nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// Arguments of `splat compare`.
#[derive(Args)]
pub struct CompareArgs {
    /// The reference image (.png, .exr or .npy).
    pub reference: PathBuf,
    /// The test image, same size.
    pub test: PathBuf,
    /// Write the error maps PREFIX-abs.png (largest |A − B| over the channels, magma, 0 to the
    /// image's largest), PREFIX-ssim.png (SSIM per pixel) and PREFIX-flip.png (ꟻLIP, magma).
    #[arg(long)]
    pub maps: Option<PathBuf>,
    /// Observer's pixels per degree of visual angle for ꟻLIP (its default: 0.7 m from a 0.7 m
    /// wide 4K monitor).
    #[arg(long, default_value_t = nv_flip::DEFAULT_PIXELS_PER_DEGREE)]
    pub pixels_per_degree: f32,
}

/// The RGB values of an image (a grey one repeated), as f32.
fn rgb(image: &Image) -> Vec<f32> {
    let c = image.channels() as usize;
    image.data().chunks_exact(c).flat_map(|p| if c >= 3 { [p[0], p[1], p[2]] } else { [p[0]; 3] }).collect()
}

/// 8-bit display values, as PNG would store them.
fn rgb8(values: &[f32]) -> Vec<u8> {
    values.iter().map(|&v| splat_io::image::to_u8(v)).collect()
}

/// RMSE, PSNR, SSIM and ꟻLIP of two images.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    /// Root mean square difference of the RGB values.
    pub rmse: f64,
    /// −20 log₁₀ RMSE (peak 1); infinite for equal images.
    pub psnr: f64,
    /// SSIM of the 8-bit images, the lowest of the three channels.
    pub ssim: f64,
    /// Mean LDR ꟻLIP of the 8-bit images.
    pub flip: f64,
}

/// The metrics of `test` against `reference`, and the per-pixel SSIM and ꟻLIP images behind
/// them (for the error maps).
struct Measured {
    metrics: Metrics,
    rgb: (Vec<f32>, Vec<f32>),
    ssim: image_compare::Similarity,
    flip: nv_flip::FlipImageFloat,
}

/// RMSE and PSNR on the RGB values (a grey image's value repeated), SSIM and ꟻLIP (LDR, at
/// `pixels_per_degree`) on their 8-bit display values: the images must be equally sized and
/// finite.
pub fn metrics(reference: &Image, test: &Image, pixels_per_degree: f32) -> Result<Metrics> {
    Ok(measure(reference, test, pixels_per_degree)?.metrics)
}

fn measure(a: &Image, b: &Image, pixels_per_degree: f32) -> Result<Measured> {
    let (w, h) = (a.width(), a.height());
    if (b.width(), b.height()) != (w, h) {
        bail!("the images differ in size: {w}×{h} and {}×{}", b.width(), b.height());
    }
    let (fa, fb) = (rgb(a), rgb(b));
    if let Some(v) = fa.iter().chain(&fb).find(|v| !v.is_finite()) {
        bail!("an image holds {v}: every value must be finite");
    }
    let rmse = splat_core::stats::rmse(&fa, &fb);
    let psnr = if rmse > 0.0 { -20.0 * rmse.log10() } else { f64::INFINITY };
    let (a8, b8) = (rgb8(&fa), rgb8(&fb));
    let image_a = image::RgbImage::from_raw(w, h, a8.clone()).expect("3 bytes a pixel");
    let image_b = image::RgbImage::from_raw(w, h, b8.clone()).expect("3 bytes a pixel");
    let ssim = image_compare::rgb_similarity_structure(&image_compare::Algorithm::MSSIMSimple, &image_a, &image_b)
        .map_err(|e| anyhow::anyhow!("SSIM: {e}"))?;
    let flip = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &a8),
        nv_flip::FlipImageRgb8::with_data(w, h, &b8),
        pixels_per_degree,
    );
    let flip_mean = f64::from(nv_flip::FlipPool::from_image(&flip).mean());
    let metrics = Metrics { rmse, psnr, ssim: ssim.score, flip: flip_mean };
    Ok(Measured { metrics, rgb: (fa, fb), ssim, flip })
}

/// Run `splat compare`.
pub fn run(args: CompareArgs) -> Result<()> {
    let read = |p: &Path| splat_io::image::read_image(p).with_context(|| format!("reading {}", p.display()));
    let (a, b) = (read(&args.reference)?, read(&args.test)?);
    let measured = measure(&a, &b, args.pixels_per_degree)?;
    let Metrics { rmse, psnr, ssim, flip } = measured.metrics;
    println!("reference  {}", args.reference.display());
    println!("test       {}", args.test.display());
    println!("RMSE       {rmse:.6e}   (RGB values: {})", value_scale(&args.reference, &args.test));
    println!("PSNR       {psnr:.2} dB (peak 1)");
    println!("SSIM       {ssim:.6}   (8-bit, the lowest of the three channels)");
    println!("FLIP       {flip:.6}   (LDR ꟻLIP mean, {} pixels per degree)", args.pixels_per_degree);
    if let Some(prefix) = &args.maps {
        let (fa, fb) = &measured.rgb;
        write_maps(prefix, (a.width(), a.height()), fa, fb, &measured.ssim, &measured.flip)?;
    }
    Ok(())
}

/// How the inputs' values were read, for the RMSE line: 8-bit PNG values scaled to [0, 1],
/// float files as they are stored.
fn value_scale(a: &Path, b: &Path) -> &'static str {
    let png = |p: &Path| matches!(splat_io::image::ImageFormat::from_path(p), Ok(splat_io::image::ImageFormat::Png));
    match (png(a), png(b)) {
        (true, true) => "8-bit PNG values / 255",
        (false, false) => "float values as stored",
        _ => "PNG values / 255, float values as stored",
    }
}

fn write_maps(
    prefix: &Path,
    (w, h): (u32, u32),
    a: &[f32],
    b: &[f32],
    ssim: &image_compare::Similarity,
    flip: &nv_flip::FlipImageFloat,
) -> Result<()> {
    let name = |suffix: &str| {
        let mut p = prefix.as_os_str().to_owned();
        p.push(format!("-{suffix}.png"));
        PathBuf::from(p)
    };
    let abs: Vec<f32> = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f32::max))
        .collect();
    let largest = abs.iter().copied().fold(0.0f32, f32::max);
    let scaled: Vec<f32> = abs.iter().map(|&v| if largest > 0.0 { v / largest } else { 0.0 }).collect();
    let abs_map = nv_flip::FlipImageFloat::with_data(w, h, &scaled).apply_color_lut(&nv_flip::magma_lut());
    let flip_map = flip.apply_color_lut(&nv_flip::magma_lut());
    let save = |path: PathBuf, bytes: Vec<u8>| -> Result<()> {
        image::RgbImage::from_raw(w, h, bytes)
            .expect("3 bytes a pixel")
            .save(&path)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
        Ok(())
    };
    save(name("abs"), abs_map.to_vec())?;
    let ssim_path = name("ssim");
    ssim.image.to_color_map().save(&ssim_path).with_context(|| format!("writing {}", ssim_path.display()))?;
    eprintln!("wrote {}", ssim_path.display());
    save(name("flip"), flip_map.to_vec())?;
    eprintln!("abs map: black 0, yellow {largest:.3e}");
    eprintln!("ssim map: each channel's SSIM as its colour channel, black 0 (or less) to full 1 (identical)");
    Ok(())
}
