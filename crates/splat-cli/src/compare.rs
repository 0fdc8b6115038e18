//! `splat compare`: how far apart two images are, by RMSE, PSNR, SSIM and ꟻLIP, with error maps.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Image;
use splat_core::glam::Vec3;
use std::path::{Path, PathBuf};

/// ꟻLIP's default observer: 0.7 m from a 0.7 m wide 4K monitor.
pub use nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// Arguments of `splat compare`.
#[derive(Args)]
pub struct CompareArgs {
    /// The reference image (.png, .jpg, .exr or .npy), or a folder of them (ground truth).
    pub reference: PathBuf,
    /// The test image, same size; or a folder: each of its images against the reference's of
    /// the same name (extension aside), and the mean over them, as 3DGS's metrics.py reports.
    pub test: PathBuf,
    /// Write the error maps PREFIX-abs.png (largest |A − B| over the channels, magma, 0 to the
    /// image's largest), PREFIX-ssim.png (SSIM per pixel) and PREFIX-flip.png (ꟻLIP, magma).
    #[arg(long)]
    pub maps: Option<PathBuf>,
    /// Observer's pixels per degree of visual angle for ꟻLIP (its default: 0.7 m from a 0.7 m
    /// wide 4K monitor).
    #[arg(long, default_value_t = nv_flip::DEFAULT_PIXELS_PER_DEGREE)]
    pub pixels_per_degree: f32,
    /// Composite 8-bit images with alpha over this colour "r,g,b" (each 0 to 1) before comparing,
    /// as 3DGS loads a NeRF-synthetic photograph (1,1,1 with its --white_background, else
    /// 0,0,0); without it such an image is compared on its colour as stored.
    #[arg(long, value_parser = parse_background)]
    pub background: Option<Vec3>,
    /// Masks of the pixels that count (white) as `splat undistort --masks` writes them: a mask
    /// image, or a folder of them by the images' names (an image without one counts whole). The
    /// test image is blacked where its mask is dark, as gsplat's evaluation blacks the pixels
    /// its fisheye mask leaves out before it scores.
    #[arg(long, value_name = "MASKS")]
    pub masks: Option<PathBuf>,
}

/// A background colour "r,g,b", each in [0, 1].
fn parse_background(s: &str) -> Result<Vec3, String> {
    let c = splat_io::text::parse_vec3(s)?;
    if c.to_array().iter().all(|v| (0.0..=1.0).contains(v)) {
        Ok(c)
    } else {
        Err(format!("{s}: each of r, g, b must be in 0..=1"))
    }
}

/// An image as it is compared, and whether alpha was left aside: with `background`, an 8-bit
/// image with alpha composited over it as 3DGS's `readCamerasFromTransforms` does (c α + b (1 −
/// α) in f64 from the 8-bit values, then × 255 truncated to 8 bits by its `np.byte` cast);
/// otherwise as stored.
fn read_compared(path: &Path, background: Option<Vec3>) -> Result<(Image, bool)> {
    let image = splat_io::image::read_image(path).with_context(|| format!("reading {}", path.display()))?;
    let has_alpha = image.channels() == 4;
    match background {
        Some(background) if has_alpha && splat_io::image::is_eight_bit(path) => Ok((over(&image, background), false)),
        _ => Ok((image, has_alpha)),
    }
}

/// `image` black where the mask at `path` (of its size; a pixel counts where the mask's first
/// channel is above one half) is dark.
fn masked(image: Image, path: &Path) -> Result<Image> {
    let mask = splat_io::image::read_image(path).with_context(|| format!("reading the mask {}", path.display()))?;
    let (w, h) = (image.width(), image.height());
    if (mask.width(), mask.height()) != (w, h) {
        bail!("the mask {} is {}×{} and its image {w}×{h}", path.display(), mask.width(), mask.height());
    }
    let (c, m) = (image.channels() as usize, mask.channels() as usize);
    let counts = mask.data().chunks_exact(m).map(|p| p[0] > 0.5);
    let data = image
        .data()
        .chunks_exact(c)
        .zip(counts)
        .flat_map(|(p, counts)| p.iter().map(move |&v| if counts { v } else { 0.0 }));
    Ok(Image::from_data(w, h, image.channels(), data.collect()).expect("the image's own size"))
}

/// 8-bit RGBA `image` over `background`, as [`read_compared`] describes.
fn over(image: &Image, background: Vec3) -> Image {
    let b = background.to_array().map(f64::from);
    let level = |v: f32| f64::from((v * 255.0).round());
    let data = image
        .data()
        .chunks_exact(4)
        .flat_map(|p| {
            let alpha = level(p[3]) / 255.0;
            std::array::from_fn::<f32, 3, _>(|c| {
                let v = level(p[c]) / 255.0 * alpha + b[c] * (1.0 - alpha);
                ((v * 255.0).trunc() / 255.0) as f32
            })
        })
        .collect();
    Image::from_data(image.width(), image.height(), 3, data).expect("3 values a pixel")
}

/// The note for images compared on their colour with their alpha left aside.
fn alpha_note(count: usize) {
    if count > 0 {
        eprintln!(
            "note: {count} image(s) have alpha, compared on their colour as stored: --background composites them \
             over a colour first (as 3DGS composites NeRF-synthetic photographs)"
        );
    }
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
    /// SSIM of the RGB values as 3DGS reports it: the mean over every pixel
    /// ([`splat_core::ssim`]).
    pub ssim: f64,
    /// SSIM as torchmetrics (Nerfstudio, gsplat) reports it: the mean over the pixels whose
    /// window lies inside the image; `None` for an image smaller than the window.
    pub ssim_inside: Option<f64>,
    /// Mean LDR ꟻLIP of the 8-bit images.
    pub flip: f64,
}

/// The metrics of `test` against `reference`, and the per-pixel SSIM and ꟻLIP images behind
/// them (for the error maps).
struct Measured {
    metrics: Metrics,
    rgb: (Vec<f32>, Vec<f32>),
    ssim: Vec<f64>,
    flip: nv_flip::FlipImageFloat,
}

/// RMSE, PSNR and SSIM on the RGB values (a grey image's value repeated), ꟻLIP (LDR, at
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
    let ssim = splat_core::ssim::ssim(&fa, &fb, w, h, 3);
    let (a8, b8) = (rgb8(&fa), rgb8(&fb));
    let flip = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &a8),
        nv_flip::FlipImageRgb8::with_data(w, h, &b8),
        pixels_per_degree,
    );
    let flip_mean = f64::from(nv_flip::FlipPool::from_image(&flip).mean());
    let metrics = Metrics { rmse, psnr, ssim: ssim.mean, ssim_inside: ssim.mean_inside, flip: flip_mean };
    Ok(Measured { metrics, rgb: (fa, fb), ssim: ssim.map, flip })
}

/// Run `splat compare`.
pub fn run(args: CompareArgs) -> Result<()> {
    if args.reference.is_dir() || args.test.is_dir() {
        return run_folders(&args);
    }
    if let Some(folder) = args.masks.as_ref().filter(|m| m.is_dir()) {
        bail!("--masks {} is a folder: give the mask of the one test image", folder.display());
    }
    let ((a, alpha_a), (b, alpha_b)) =
        (read_compared(&args.reference, args.background)?, read_compared(&args.test, args.background)?);
    alpha_note(usize::from(alpha_a) + usize::from(alpha_b));
    let b = match &args.masks {
        Some(mask) => masked(b, mask)?,
        None => b,
    };
    let measured = measure(&a, &b, args.pixels_per_degree)?;
    let Metrics { rmse, psnr, ssim, ssim_inside, flip } = measured.metrics;
    println!("reference  {}", args.reference.display());
    println!("test       {}", args.test.display());
    println!("RMSE       {rmse:.6e}   (RGB values: {})", value_scale(&args.reference, &args.test));
    println!("PSNR       {psnr:.2} dB (peak 1)");
    println!("SSIM       {ssim:.6}   (3DGS's: 11 × 11 Gaussian window, σ 1.5, every pixel)");
    if let Some(inside) = ssim_inside {
        println!(
            "SSIM       {inside:.6}   (torchmetrics', as Nerfstudio and gsplat report it: windows inside the image)"
        );
    }
    println!("FLIP       {flip:.6}   (LDR ꟻLIP mean, {} pixels per degree)", args.pixels_per_degree);
    if let Some(prefix) = &args.maps {
        let (fa, fb) = &measured.rgb;
        write_maps(prefix, (a.width(), a.height()), fa, fb, &measured.ssim, &measured.flip)?;
    }
    Ok(())
}

/// The images of a folder that `splat compare` reads, by name without extension.
fn images_in(folder: &Path) -> Result<std::collections::BTreeMap<String, PathBuf>> {
    let entries = std::fs::read_dir(folder).with_context(|| format!("reading the folder {}", folder.display()))?;
    let mut images = std::collections::BTreeMap::new();
    for entry in entries {
        let path = entry.with_context(|| format!("reading the folder {}", folder.display()))?.path();
        let readable = splat_io::image::is_jpeg(&path) || splat_io::image::ImageFormat::from_path(&path).is_ok();
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else { continue };
        if !readable || !path.is_file() {
            continue;
        }
        if let Some(other) = images.insert(stem.to_string(), path.clone()) {
            bail!("{} and {} share a name: which one is the image is unclear", other.display(), path.display());
        }
    }
    Ok(images)
}

/// `splat compare` of two folders: each test image against the reference of its name, then
/// the mean of each metric over the images (3DGS's metrics.py averages per image).
fn run_folders(args: &CompareArgs) -> Result<()> {
    let (reference, test) = (&args.reference, &args.test);
    if !(reference.is_dir() && test.is_dir()) {
        bail!("compare two images or two folders: {} and {}", reference.display(), test.display());
    }
    if args.maps.is_some() {
        bail!("--maps writes the maps of two images, not of two folders: compare one pair for its maps");
    }
    let (references, tests) = (images_in(reference)?, images_in(test)?);
    let masks = match &args.masks {
        Some(folder) if folder.is_dir() => images_in(folder)?,
        Some(file) => {
            bail!("--masks {} is not a folder: give the folder of the masks by the images' names", file.display())
        }
        None => Default::default(),
    };
    if tests.is_empty() {
        bail!("{} holds no image (.png, .jpg, .exr or .npy)", test.display());
    }
    let missing: Vec<&str> = tests.keys().filter(|name| !references.contains_key(*name)).map(String::as_str).collect();
    if let Some(first) = missing.first() {
        bail!(
            "{} of the {} images of {} have no image of that name in {} (the first: {first})",
            missing.len(),
            tests.len(),
            test.display(),
            reference.display()
        );
    }
    println!("reference  {}", reference.display());
    println!("test       {}", test.display());
    println!("{:<32} {:>9} {:>9} {:>9} {:>9}", "image", "PSNR dB", "SSIM", "SSIM tm", "FLIP");
    let mut rows = Vec::with_capacity(tests.len());
    let mut with_alpha = 0;
    for (name, path) in &tests {
        let (a, alpha_a) = read_compared(&references[name], args.background)?;
        let (b, alpha_b) = read_compared(path, args.background)?;
        let b = match masks.get(name) {
            Some(mask) => masked(b, mask)?,
            None => b,
        };
        with_alpha += usize::from(alpha_a) + usize::from(alpha_b);
        let m = metrics(&a, &b, args.pixels_per_degree).with_context(|| format!("comparing {name}"))?;
        println!("{name:<32} {:>9.3} {:>9.5} {:>9} {:>9.5}", m.psnr, m.ssim, inside(m.ssim_inside), m.flip);
        rows.push(m);
    }
    let n = rows.len() as f64;
    let mean = |f: fn(&Metrics) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let inside_mean = rows.iter().map(|m| m.ssim_inside).sum::<Option<f64>>().map(|s| s / n);
    let label = format!("mean of {}", rows.len());
    let (psnr, ssim, flip) = (mean(|m| m.psnr), mean(|m| m.ssim), mean(|m| m.flip));
    println!("{label:<32} {psnr:>9.3} {ssim:>9.5} {:>9} {flip:>9.5}", inside(inside_mean));
    println!("SSIM is 3DGS's (every pixel), SSIM tm torchmetrics' (windows inside the image); PSNR peak 1");
    alpha_note(with_alpha);
    if args.masks.is_some() {
        let used = tests.keys().filter(|name| masks.contains_key(*name)).count();
        eprintln!("note: {used} of the {} test images masked (blacked where their masks are dark)", tests.len());
    }
    let unmatched = references.len() - tests.len();
    if unmatched > 0 {
        let were = if unmatched == 1 { "was" } else { "were" };
        let images = crate::counted(unmatched, "image");
        eprintln!("note: {images} of {} without a test image {were} not compared", reference.display());
    }
    Ok(())
}

/// A torchmetrics SSIM for the table: "-" where the image is smaller than its window.
fn inside(ssim: Option<f64>) -> String {
    ssim.map_or_else(|| "-".into(), |v| format!("{v:.5}"))
}

/// How the inputs' values were read, for the RMSE line: 8-bit PNG and JPEG values scaled to
/// [0, 1], float files as they are stored.
fn value_scale(a: &Path, b: &Path) -> &'static str {
    use splat_io::image::is_eight_bit;
    match (is_eight_bit(a), is_eight_bit(b)) {
        (true, true) => "8-bit values / 255",
        (false, false) => "float values as stored",
        _ => "8-bit values / 255, float values as stored",
    }
}

fn write_maps(
    prefix: &Path,
    (w, h): (u32, u32),
    a: &[f32],
    b: &[f32],
    ssim: &[f64],
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
    save(name("ssim"), ssim.iter().map(|&v| splat_io::image::to_u8(v as f32)).collect())?;
    save(name("flip"), flip_map.to_vec())?;
    eprintln!("abs map: black 0, yellow {largest:.3e}");
    eprintln!("ssim map: each channel's SSIM as its colour channel, black 0 (or less) to full 1 (identical)");
    Ok(())
}
