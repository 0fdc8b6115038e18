//! Statistics that prove estimators right: Welford accumulators, the per-pixel z-test of
//! docs/architecture.md ("How correctness is proven"), RMSE and log–log slopes.

/// Running mean and variance (Welford 1962), in f64.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Welford {
    /// Samples seen.
    pub n: u64,
    /// Running mean.
    pub mean: f64,
    /// Sum of squared deviations from the mean.
    pub m2: f64,
}

impl Welford {
    /// Add one sample.
    #[inline]
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        let delta = x - self.mean;
        self.mean += delta / self.n as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// Unbiased sample variance (0 with fewer than two samples).
    pub fn variance(&self) -> f64 {
        if self.n < 2 { 0.0 } else { self.m2 / (self.n - 1) as f64 }
    }

    /// The statistics of `n` samples of mean `mean` and unbiased variance `variance`.
    pub fn of(n: u64, mean: f64, variance: f64) -> Self {
        Self { n, mean, m2: variance * n.saturating_sub(1) as f64 }
    }

    /// The statistics of both sets of samples (Chan, Golub & LeVeque 1979): with δ = mean_b −
    /// mean_a and n = n_a + n_b, mean = mean_a + δ n_b / n and M2 = M2_a + M2_b + δ² n_a n_b / n.
    pub fn merge(self, other: Welford) -> Welford {
        let n = self.n + other.n;
        if n == 0 {
            return self;
        }
        let (na, nb) = (self.n as f64, other.n as f64);
        let delta = other.mean - self.mean;
        let mean = self.mean + delta * nb / n as f64;
        let m2 = self.m2 + other.m2 + delta * delta * na * nb / n as f64;
        Welford { n, mean, m2 }
    }
}

/// Outcome of the per-pixel z-test of a mean image against the exact one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZTest {
    /// |Σ(mean − exact)| / √(Σ se²) (a consistent bias), the largest over channels.
    pub global: f64,
    /// (Σ z² − n) / √(2n) (a bias whose sign changes from pixel to pixel), the largest over
    /// channels.
    pub spread: f64,
    /// Fraction of two-sided p-values below 0.01, over all pixel-channels.
    pub outliers: f64,
    /// The variance check: (Σ z² − n) / √(2n) over the pixel-channels where the independent
    /// run varied, the smallest over channels. Far below zero when the variance image is too
    /// large (every se too wide, so that a bias could hide in it); 0 when no channel varied.
    pub variance: f64,
    /// Fraction of pixel-channels whose se is the 1/F floor (the independent run never
    /// varied there).
    pub floored: f64,
    /// Pixel-channels tested.
    pub n: usize,
}

/// The expected global or spread statistic (noise-free: the z-test of an estimator's exact
/// expectation) from which a bias is visible at a budget (docs/power.md): a bias whose
/// expected statistics stay below it changes the image by less than the noise of the budget's
/// frames can show, and no test of that budget can be required to see it.
pub const VISIBLE: f64 = 6.0;

/// The spread statistic an estimator has in expectation, from the `spread` of the z-test of
/// its exact expectation over `n` pixel-channels of `channels` channels: the noise-free
/// Σ (d / se)² over the √(2n) of a channel's pixel-channels (the z-test's own spread subtracts
/// the n that noise adds).
pub fn expected_spread(spread: f64, n: usize, channels: usize) -> f64 {
    spread + (n as f64 / channels as f64 / 2.0).sqrt()
}

/// Thresholds of the z-test (docs/architecture.md).
pub const GLOBAL_MAX: f64 = 4.0;
/// Largest accepted spread statistic.
pub const SPREAD_MAX: f64 = 4.0;
/// Largest accepted fraction of pixels with p < 0.01.
pub const OUTLIERS_MAX: f64 = 0.03;
/// Smallest accepted variance statistic ([`ZTest::variance`]).
pub const VARIANCE_MIN: f64 = -4.0;
/// Fewest pixel-channels a z-test must see to pass: a test of nothing proves nothing.
pub const MIN_TESTED: usize = 96;
/// Smallest standard error where the independent run varied: the f32 resolution of a mean
/// of values of order 1 (GPU accumulators are f32).
pub const SE_MIN: f64 = 1e-6;

/// The standard error of a mean of `frames` frames from the per-frame variance `var` of an
/// independent run: √(var / F); where that run never varied (var = 0), 1/F, since an event
/// too rare for the runs to have drawn could still be in the mean, and one such event moves
/// it by up to 1/F.
pub fn standard_error(var: f32, frames: u32) -> f64 {
    let f = f64::from(frames);
    if var > 0.0 { (f64::from(var) / f).sqrt().max(SE_MIN) } else { 1.0 / f }
}
/// |z| above which the two-sided p-value is below 0.01.
pub const Z_P01: f64 = 2.575_829_303_549;

/// Per-channel sums of the z-test.
#[derive(Clone, Copy, Default)]
struct Sums {
    d: f64,
    se2: f64,
    z2: f64,
    n: usize,
    /// Σ z² and count over the unfloored pixel-channels.
    z2_free: f64,
    n_free: usize,
}

/// (Σ z² − n) / √(2n): a χ²_n statistic in standard units.
fn chi2_units(z2: f64, n: usize) -> f64 {
    (z2 - n as f64) / (2.0 * n as f64).sqrt()
}

impl ZTest {
    /// Compare `mean` (over `frames` frames) with `exact`, using the per-frame `variance` of an
    /// independent run: se = [`standard_error`] per pixel-channel. Values are interleaved with
    /// `channels` channels per pixel.
    ///
    /// The global and spread statistics sum over pixels, which are independent, but the
    /// channels of one pixel come from the same random decisions and are correlated (fully,
    /// for a stochastic pick): summed across channels they would be over-dispersed by up to
    /// √channels. So both are computed per channel and the largest is reported.
    pub fn new(mean: &[f32], exact: &[f32], variance: &[f32], frames: u32, channels: usize) -> Self {
        assert!(mean.len() == exact.len() && mean.len() == variance.len(), "image sizes differ");
        assert!(channels > 0 && mean.len().is_multiple_of(channels), "length is not a multiple of the channels");
        let mut sums = vec![Sums::default(); channels];
        let (mut outliers, mut floored) = (0usize, 0usize);
        for (i, ((&m, &e), &v)) in mean.iter().zip(exact).zip(variance).enumerate() {
            let se = standard_error(v, frames);
            let d = f64::from(m) - f64::from(e);
            let z = d / se;
            let s = &mut sums[i % channels];
            s.d += d;
            s.se2 += se * se;
            s.z2 += z * z;
            s.n += 1;
            if v > 0.0 {
                s.z2_free += z * z;
                s.n_free += 1;
            } else {
                floored += 1;
            }
            outliers += usize::from(z.is_nan() || z.abs() > Z_P01);
        }
        let tested = sums.iter().filter(|s| s.n > 0);
        let global = tested.clone().map(|s| s.d.abs() / s.se2.sqrt()).fold(0.0, f64::max);
        let spread = tested.map(|s| chi2_units(s.z2, s.n)).fold(f64::NEG_INFINITY, f64::max);
        let variance =
            sums.iter().filter(|s| s.n_free > 0).map(|s| chi2_units(s.z2_free, s.n_free)).fold(0.0, f64::min);
        let n = mean.len();
        let share = |k: usize| k as f64 / n.max(1) as f64;
        Self { global, spread, outliers: share(outliers), variance, floored: share(floored), n }
    }

    /// Whether all four criteria hold on at least [`MIN_TESTED`] pixel-channels.
    pub fn passes(&self) -> bool {
        self.n >= MIN_TESTED
            && self.global <= GLOBAL_MAX
            && self.spread <= SPREAD_MAX
            && self.outliers <= OUTLIERS_MAX
            && self.variance >= VARIANCE_MIN
    }
}

/// Root mean square difference of two equally sized images.
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "image sizes differ");
    let sum: f64 = a.iter().zip(b).map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2)).sum();
    (sum / a.len().max(1) as f64).sqrt()
}

/// Least-squares slope of log(y) against log(x).
pub fn log_log_slope(x: &[f64], y: &[f64]) -> f64 {
    log_log_fit(x, y).0
}

/// Least-squares slope b of log(y) = a + b log(x) and its standard error
/// √(Σ rᵢ² / (n − 2) / Σ (log xᵢ − mean)²) from the residuals rᵢ (NaN with fewer than three
/// points): how well the points fit a line, not the sampling error of each point.
pub fn log_log_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let (lx, ly): (Vec<f64>, Vec<f64>) = x.iter().zip(y).map(|(a, b)| (a.ln(), b.ln())).unzip();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let cov: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let var: f64 = lx.iter().map(|a| (a - mx).powi(2)).sum();
    let slope = cov / var;
    let residuals: f64 = lx.iter().zip(&ly).map(|(a, b)| (b - my - slope * (a - mx)).powi(2)).sum();
    let stderr = if lx.len() > 2 { (residuals / (n - 2.0) / var).sqrt() } else { f64::NAN };
    (slope, stderr)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{SplitMix64, unit_f32};

    #[test]
    fn welford_matches_two_pass() {
        let xs = [1.0, 4.0, 2.5, -3.0, 8.0];
        let mut w = Welford::default();
        xs.iter().for_each(|&x| w.push(x));
        let mean = xs.iter().sum::<f64>() / 5.0;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 4.0;
        assert!((w.mean - mean).abs() < 1e-12 && (w.variance() - var).abs() < 1e-12);
    }

    #[test]
    fn slope_of_a_power_law() {
        let x = [1.0, 2.0, 4.0, 8.0];
        let y: Vec<f64> = x.iter().map(|v: &f64| 3.0 * v.powf(-0.5)).collect();
        assert!((log_log_slope(&x, &y) + 0.5).abs() < 1e-12);
        // Points off the line: the slope's standard error by hand (residuals ±0.1 in ln y).
        let x = [1.0f64, 2.0, 4.0, 8.0];
        let y: Vec<f64> =
            x.iter().zip([0.1, -0.1, -0.1, 0.1]).map(|(v, r)| (3.0 * v.powf(-0.5)).ln() + r).map(f64::exp).collect();
        let (slope, se) = log_log_fit(&x, &y);
        // ln x = 0, l, 2l, 3l (l = ln 2): Σ (ln x − 1.5 l)² = 5 l²; the fitted residuals are ±0.1
        // (the perturbation is orthogonal to a line), so se = √(0.04 / 2 / (5 l²)).
        let l = std::f64::consts::LN_2;
        assert!((slope + 0.5).abs() < 1e-12, "{slope}");
        assert!((se - (0.04f64 / 2.0 / (5.0 * l * l)).sqrt()).abs() < 1e-12, "{se}");
    }

    /// Simulated Bernoulli estimators on 40 × 30 pixels at F = 256 (docs/architecture.md): the
    /// unbiased one passes, a 1 % low bias and a ±5 % checkerboard bias are rejected, and so is
    /// the unbiased one judged with a variance image twice too large or half too small.
    #[test]
    fn z_test_accepts_unbiased_and_rejects_biased_bernoulli() {
        let (w, h, frames) = (40usize, 30usize, 256u32);
        let mut rng = SplitMix64::new(42);
        let p: Vec<f64> = (0..w * h).map(|_| 0.2 + 0.6 * f64::from(rng.next_f32())).collect();
        let run = |bias: &dyn Fn(usize) -> f64, frames: u32, rng: &mut SplitMix64| -> (Vec<f32>, Vec<f32>) {
            let mut acc = vec![Welford::default(); w * h];
            for (i, a) in acc.iter_mut().enumerate() {
                let q = (p[i] * bias(i)).clamp(0.0, 1.0);
                for _ in 0..frames {
                    a.push(if f64::from(unit_f32(rng.next_u64() as u32)) < q { 1.0 } else { 0.0 });
                }
            }
            (acc.iter().map(|a| a.mean as f32).collect(), acc.iter().map(|a| a.variance() as f32).collect())
        };
        let exact: Vec<f32> = p.iter().map(|&v| v as f32).collect();
        let test = |bias: &dyn Fn(usize) -> f64, rng: &mut SplitMix64| {
            let (mean, _) = run(bias, frames, rng);
            let (_, var) = run(bias, 4 * frames, rng);
            ZTest::new(&mean, &exact, &var, frames, 1)
        };
        let unbiased = test(&|_| 1.0, &mut rng);
        assert!(unbiased.passes() && unbiased.global < 3.0, "{unbiased:?}");
        let low = test(&|_| 0.99, &mut rng);
        assert!(!low.passes() && low.global > 4.0, "{low:?}");
        let checker = test(&|i| if (i % w + i / w) % 2 == 0 { 1.05 } else { 0.95 }, &mut rng);
        assert!(!checker.passes() && checker.spread > 4.0, "{checker:?}");
        let (mean, _) = run(&|_| 1.0, frames, &mut rng);
        let (_, var) = run(&|_| 1.0, 4 * frames, &mut rng);
        let scaled = |k: f32| var.iter().map(|v| v * k).collect::<Vec<f32>>();
        let wide = ZTest::new(&mean, &exact, &scaled(2.0), frames, 1);
        assert!(!wide.passes() && wide.variance < VARIANCE_MIN, "{wide:?}");
        let narrow = ZTest::new(&mean, &exact, &scaled(0.5), frames, 1);
        assert!(!narrow.passes() && narrow.spread > SPREAD_MAX, "{narrow:?}");
    }

    /// An empty mask, or a handful of pixels, is not a pass.
    #[test]
    fn a_z_test_of_too_few_pixels_fails() {
        let empty = ZTest::new(&[], &[], &[], 256, 3);
        assert!(!empty.passes() && empty.n == 0, "{empty:?}");
        let few = ZTest::new(&[0.5; 30], &[0.5; 30], &[0.25; 30], 256, 3);
        assert!(!few.passes(), "{few:?}");
    }

    /// A pixel where both runs have zero variance but the mean differs from the exact value
    /// is caught by the floor, not divided by zero.
    #[test]
    fn zero_variance_disagreements_are_outliers() {
        let mut mean = vec![0.5f32; 300];
        mean[7] = 0.6;
        let z = ZTest::new(&mean, &[0.5; 300], &[0.0; 300], 256, 3);
        assert!(!z.passes() && z.floored == 1.0, "{z:?}");
    }
}
