//! `splat ztest`: the project's per-pixel z-test (docs/architecture.md, "How correctness is
//! proven") on images a user rendered, with a verdict scripts can use.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::Image;
use splat_core::stats::{GLOBAL_MAX, MIN_TESTED, OUTLIERS_MAX, SPREAD_MAX, VARIANCE_MIN, ZTest, standard_error};
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// Arguments of `splat ztest`.
#[derive(Args)]
pub struct ZtestArgs {
    /// Mean image of the estimator under test over --frames frames (.exr or .npy), e.g.
    /// `splat render --method stochastic --spp 256 --seed 1 -o mean.exr`.
    pub mean: PathBuf,
    /// Per-frame variance of an independent run of the same estimator (.exr or .npy), e.g.
    /// `splat render --method stochastic --spp 1024 --seed 2 --variance var.exr -o run2.exr`.
    pub variance: PathBuf,
    /// The reference (expected) image, e.g. `splat render --method exact -o ref.exr`.
    pub reference: PathBuf,
    /// Frames averaged in MEAN (its --spp).
    #[arg(long)]
    pub frames: u32,
    /// The per-frame variance of the MEAN run itself (`--variance` of the same render), pooled
    /// with VARIANCE by degrees of freedom, as the project's suites do: a heavy-tailed
    /// estimator's rare event that moves the mean then also widens its standard error, while a
    /// bias, which moves the mean without widening the variance, is still seen. Needs
    /// --variance-frames.
    #[arg(long, requires = "variance_frames")]
    pub mean_variance: Option<PathBuf>,
    /// Frames of the independent run behind VARIANCE (for --mean-variance).
    #[arg(long)]
    pub variance_frames: Option<u32>,
    /// Write the z-map (PNG): per pixel the z of its most extreme colour channel, blue below
    /// zero, red above, white at zero, full colour at |z| ≥ 4; black where nothing was tested.
    #[arg(long)]
    pub zmap: Option<PathBuf>,
}

/// The verdict: `Ok(true)` passes, `Ok(false)` rejects, `Err` is bad input.
pub fn run(args: &ZtestArgs) -> Result<bool> {
    let read = |p: &Path| splat_io::image::read_image(p).with_context(|| format!("reading {}", p.display()));
    let (mean, variance, reference) = (read(&args.mean)?, read(&args.variance)?, read(&args.reference)?);
    let mean_variance = args.mean_variance.as_deref().map(read).transpose()?;
    let pooling = mean_variance.as_ref().zip(args.variance_frames);
    let variance = tested_variance(&mean, &variance, &reference, args.frames, pooling)?;
    let verdict = statistics(&mean, &variance, &reference, args.frames)?;
    println!("z-test of {} ({} frames) against {}", args.mean.display(), args.frames, args.reference.display());
    println!(
        "tested     {} pixel-channels ({} constant and equal to the reference left out)",
        verdict.tested, verdict.left_out
    );
    println!("global     {:>7.2}   (≤ {GLOBAL_MAX}: a consistent bias)", verdict.global);
    println!("spread     {:>7.2}   (≤ {SPREAD_MAX}: a bias whose sign varies)", verdict.spread);
    println!("outliers   {:>7.2} % (≤ {} %: p < 0.01)", 100.0 * verdict.outliers, 100.0 * OUTLIERS_MAX);
    println!("variance   {:>7.2}   (≥ {VARIANCE_MIN}: the variance image is not too wide)", verdict.variance);
    println!("floored    {:>7.2} % (se set to 1/F where the variance run never varied)", 100.0 * verdict.floored);
    if verdict.passes() {
        println!("verdict    PASS");
    } else {
        println!("verdict    REJECT ({})", verdict.failures.join("; "));
    }
    if let Some(path) = &args.zmap {
        write_zmap(path, &mean, &variance, &reference, args.frames)?;
        eprintln!("z-map → {}", path.display());
    }
    Ok(verdict.passes())
}

/// The z-test's statistics on a user's images and the criteria they fail.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// Pixel-channels tested.
    pub tested: usize,
    /// Pixel-channels left out: constant in the variance run and equal to the reference.
    pub left_out: usize,
    /// |Σ(mean − reference)| / √(Σ se²), the largest over the colour channels.
    pub global: f64,
    /// (Σ z² − n) / √(2n), the largest over the colour channels.
    pub spread: f64,
    /// Share of pixel-channels with p < 0.01.
    pub outliers: f64,
    /// The variance check, the smallest over the colour channels.
    pub variance: f64,
    /// Share of pixel-channels whose se is the 1/F floor.
    pub floored: f64,
    /// The criteria failed, each with its value and bound; empty when the test passes.
    pub failures: Vec<String>,
}

impl Verdict {
    /// Whether every criterion holds.
    pub fn passes(&self) -> bool {
        self.failures.is_empty()
    }
}

/// The z-test (docs/architecture.md, "How correctness is proven") of `mean` over `frames`
/// frames against `reference`, with the per-frame `variance` of an independent run; where
/// `pooling` gives the mean run's own per-frame variance and the independent run's frame
/// count, the two variances are pooled by degrees of freedom. Each colour channel
/// is tested on its own (channels of a pixel share decisions) and the worst reported. Bad
/// input (sizes that differ, values that are not finite, too few informative pixel-channels)
/// is an error naming it.
pub fn verdict(
    mean: &Image,
    variance: &Image,
    reference: &Image,
    frames: u32,
    pooling: Option<(&Image, u32)>,
) -> Result<Verdict> {
    let variance = tested_variance(mean, variance, reference, frames, pooling)?;
    statistics(mean, &variance, reference, frames)
}

/// The variance [`verdict`] tests with, its inputs checked: `variance`, or pooled with the mean
/// run's own where `pooling` gives it.
fn tested_variance<'a>(
    mean: &Image,
    variance: &'a Image,
    reference: &Image,
    frames: u32,
    pooling: Option<(&Image, u32)>,
) -> Result<Cow<'a, Image>> {
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    for (name, image) in
        [("variance", variance), ("reference", reference)].into_iter().chain(pooling.map(|(m, _)| ("mean-variance", m)))
    {
        if (image.width(), image.height()) != (mean.width(), mean.height()) {
            bail!(
                "the {name} image is {}×{}, the mean {}×{}",
                image.width(),
                image.height(),
                mean.width(),
                mean.height()
            );
        }
    }
    if let Some(bad) = mean.data().iter().find(|v| !v.is_finite()) {
        bail!("the mean image holds {bad}: expected finite values");
    }
    if let Some(bad) = reference.data().iter().find(|v| !v.is_finite()) {
        bail!("the reference image holds {bad}: expected finite values");
    }
    if let Some(bad) = variance.data().iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        bail!("the variance image holds {bad}: expected finite values ≥ 0");
    }
    Ok(match pooling {
        Some((own, variance_frames)) => Cow::Owned(pooled(own, frames, variance, variance_frames)?),
        None => Cow::Borrowed(variance),
    })
}

/// The z-test's statistics of checked images, and the criteria they fail.
fn statistics(mean: &Image, variance: &Image, reference: &Image, frames: u32) -> Result<Verdict> {
    let tested = Channels::new(mean, variance, reference);
    if tested.mean.len() < MIN_TESTED {
        bail!("only {} pixel-channels carry information (at least {MIN_TESTED} are needed)", tested.mean.len());
    }
    let z = ZTest::new(&tested.mean, &tested.reference, &tested.variance, frames, 1);
    // ZTest with one channel sums over all channels; test each colour channel on its own, as
    // the suites do (channels of a pixel share decisions), and report the worst.
    let per_channel: Vec<ZTest> = (0..tested.channels)
        .map(|c| {
            let pick = |v: &[f32]| v.iter().zip(&tested.channel).filter(|(_, k)| **k == c).map(|(v, _)| *v).collect();
            let (m, r, v): (Vec<f32>, Vec<f32>, Vec<f32>) =
                (pick(&tested.mean), pick(&tested.reference), pick(&tested.variance));
            ZTest::new(&m, &r, &v, frames, 1)
        })
        .filter(|t| t.n > 0)
        .collect();
    let worst = |f: fn(&ZTest) -> f64| per_channel.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    let global = worst(|t| t.global);
    let spread = worst(|t| t.spread);
    let variance_check = per_channel.iter().map(|t| t.variance).fold(0.0, f64::min);
    let failures: Vec<String> = [
        (global > GLOBAL_MAX).then(|| format!("global {global:.2} > {GLOBAL_MAX}")),
        (spread > SPREAD_MAX).then(|| format!("spread {spread:.2} > {SPREAD_MAX}")),
        (z.outliers > OUTLIERS_MAX)
            .then(|| format!("outliers {:.1} % > {} %", 100.0 * z.outliers, 100.0 * OUTLIERS_MAX)),
        (variance_check < VARIANCE_MIN).then(|| format!("variance check {variance_check:.2} < {VARIANCE_MIN}")),
    ]
    .into_iter()
    .flatten()
    .collect();
    Ok(Verdict {
        tested: tested.mean.len(),
        left_out: tested.left_out,
        global,
        spread,
        outliers: z.outliers,
        variance: variance_check,
        floored: z.floored,
        failures,
    })
}

/// Whether a bias is visible at a budget: the z-test of an estimator's exact expectation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Power {
    /// The expected global statistic, the largest over the colour channels.
    pub global: f64,
    /// The expected spread statistic ([`splat_core::stats::expected_spread`]), the largest
    /// over the colour channels.
    pub spread: f64,
    /// Whether either reaches [`splat_core::stats::VISIBLE`]: a test of this budget can be
    /// required to see the bias.
    pub visible: bool,
}

/// The power of the z-test against a bias (docs/power.md): `expectation`, the exact expected
/// image of a biased estimator (say the oracle of a scene with its opacities × 1.02), tested
/// against `reference` with the per-frame `variance` of the unbiased estimator at `frames`
/// frames, noise-free. Its statistics are those the estimator's z-test has on average.
pub fn power(expectation: &Image, variance: &Image, reference: &Image, frames: u32) -> Result<Power> {
    let v = verdict(expectation, variance, reference, frames, None)?;
    let channels = expectation.channels().min(3) as usize;
    let spread = splat_core::stats::expected_spread(v.spread, v.tested, channels);
    let visible = v.global.max(spread) >= splat_core::stats::VISIBLE;
    Ok(Power { global: v.global, spread, visible })
}

/// ((F₁ − 1) v₁ + (F₂ − 1) v₂) / (F₁ + F₂ − 2): the two runs' per-frame variances pooled.
fn pooled(own: &Image, own_frames: u32, other: &Image, other_frames: u32) -> Result<Image> {
    if own.channels() != other.channels() {
        bail!("the two variance images have {} and {} channels", own.channels(), other.channels());
    }
    if own_frames + other_frames < 3 {
        bail!("pooling needs at least three frames in all");
    }
    let (a, b) = (f64::from(own_frames - 1), f64::from(other_frames.max(1) - 1));
    let data = own
        .data()
        .iter()
        .zip(other.data())
        .map(|(&x, &y)| ((a * f64::from(x) + b * f64::from(y)) / (a + b)) as f32)
        .collect();
    Ok(Image::from_data(own.width(), own.height(), own.channels(), data).expect("same size"))
}

/// The colour channels (up to three) of every pixel that carry information: left out are
/// those where the variance run never varied and the mean equals the reference (background).
struct Channels {
    mean: Vec<f32>,
    reference: Vec<f32>,
    variance: Vec<f32>,
    /// Colour channel of each kept value.
    channel: Vec<usize>,
    channels: usize,
    left_out: usize,
}

impl Channels {
    fn new(mean: &Image, variance: &Image, reference: &Image) -> Self {
        let channels = mean.channels().min(variance.channels()).min(reference.channels()).min(3) as usize;
        let mut out = Self {
            mean: Vec::new(),
            reference: Vec::new(),
            variance: Vec::new(),
            channel: Vec::new(),
            channels,
            left_out: 0,
        };
        for y in 0..mean.height() {
            for x in 0..mean.width() {
                let (m, v, r) = (mean.pixel(x, y), variance.pixel(x, y), reference.pixel(x, y));
                for c in 0..channels {
                    if v[c] == 0.0 && m[c] == r[c] {
                        out.left_out += 1;
                        continue;
                    }
                    out.mean.push(m[c]);
                    out.variance.push(v[c]);
                    out.reference.push(r[c]);
                    out.channel.push(c);
                }
            }
        }
        out
    }
}

/// Diverging colour of z: white at 0, blue (negative) or red (positive) at |z| ≥ 4.
fn diverging(z: f64) -> [u8; 3] {
    let t = (z.abs() / 4.0).min(1.0);
    let fade = (255.0 * (1.0 - t)).round() as u8;
    if z >= 0.0 { [255, fade, fade] } else { [fade, fade, 255] }
}

/// Write the z-map, scaled up to at least 480 pixels wide, with a colour bar and its labels.
fn write_zmap(path: &Path, mean: &Image, variance: &Image, reference: &Image, frames: u32) -> Result<()> {
    let (w, h) = (mean.width(), mean.height());
    let k = 480u32.div_ceil(w).max(1);
    let (width, map_height, bar) = (w * k, h * k, 56u32);
    let channels = mean.channels().min(variance.channels()).min(reference.channels()).min(3) as usize;
    let mut pixels = vec![0u8; 3 * (width * (map_height + bar)) as usize];
    for y in 0..h {
        for x in 0..w {
            let (m, v, r) = (mean.pixel(x, y), variance.pixel(x, y), reference.pixel(x, y));
            let z = (0..channels)
                .filter(|&c| !(v[c] == 0.0 && m[c] == r[c]))
                .map(|c| (f64::from(m[c]) - f64::from(r[c])) / standard_error(v[c], frames))
                .max_by(|a, b| a.abs().total_cmp(&b.abs()));
            let colour = z.map_or([0, 0, 0], diverging);
            for (dy, dx) in (0..k).flat_map(|dy| (0..k).map(move |dx| (dy, dx))) {
                let at = 3 * ((y * k + dy) * width + x * k + dx) as usize;
                pixels[at..at + 3].copy_from_slice(&colour);
            }
        }
    }
    draw_legend(&mut pixels, (width, map_height + bar), map_height)
        .map_err(|e| anyhow::anyhow!("z-map legend: {e}"))?;
    let png = image::RgbImage::from_raw(width, map_height + bar, pixels).expect("3 bytes a pixel");
    png.save(path).with_context(|| format!("writing {}", path.display()))
}

/// The colour bar from z = −4 to 4 under the map, labelled.
fn draw_legend(pixels: &mut [u8], size: (u32, u32), top: u32) -> Result<(), String> {
    use plotters::prelude::*;
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let root = BitMapBackend::with_buffer(pixels, size).into_drawing_area();
    let (width, _) = size;
    let (x0, x1) = (40i32, width as i32 - 40);
    let e = |e: &dyn std::fmt::Display| e.to_string();
    root.draw(&Rectangle::new([(0, top as i32), (width as i32, size.1 as i32)], WHITE.filled())).map_err(|x| e(&x))?;
    for x in x0..x1 {
        let z = -4.0 + 8.0 * f64::from(x - x0) / f64::from(x1 - x0);
        let [r, g, b] = diverging(z);
        let column = [(x, top as i32 + 8), (x + 1, top as i32 + 24)];
        root.draw(&Rectangle::new(column, RGBColor(r, g, b).filled())).map_err(|x| e(&x))?;
    }
    let style = ("sans-serif", 14).into_font().color(&BLACK);
    for z in [-4, -2, 0, 2, 4] {
        let x = x0 + (x1 - x0) * (z + 4) / 8;
        let label = if z > 0 { format!("+{z}") } else { z.to_string() };
        root.draw(&Text::new(label, (x - 6, top as i32 + 28), style.clone())).map_err(|x| e(&x))?;
    }
    root.draw(&Text::new("z", (8, top as i32 + 10), style)).map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))
}
