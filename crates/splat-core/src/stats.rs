//! Statistics that prove estimators right: Welford accumulators, the per-pixel z-test of
//! docs/architecture.md ("How correctness is proven"), the Welch t-test, RMSE and log–log slopes.

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
    /// Pixel-channels tested.
    pub n: usize,
}

/// Thresholds of the z-test (docs/architecture.md).
pub const GLOBAL_MAX: f64 = 4.0;
/// Largest accepted spread statistic.
pub const SPREAD_MAX: f64 = 4.0;
/// Largest accepted fraction of pixels with p < 0.01.
pub const OUTLIERS_MAX: f64 = 0.03;
/// |z| above which the two-sided p-value is below 0.01.
pub const Z_P01: f64 = 2.575_829_303_549;

impl ZTest {
    /// Compare `mean` (over `frames` frames) with `exact`, using the per-frame `variance` of an
    /// independent run: se = max(√(var / F), 1 / F) per pixel-channel. Values are interleaved
    /// with `channels` channels per pixel.
    ///
    /// The global and spread statistics sum over pixels, which are independent, but the
    /// channels of one pixel come from the same random decisions and are correlated (fully,
    /// for a stochastic pick): summed across channels they would be over-dispersed by up to
    /// √channels. So both are computed per channel and the largest is reported.
    pub fn new(mean: &[f32], exact: &[f32], variance: &[f32], frames: u32, channels: usize) -> Self {
        assert!(mean.len() == exact.len() && mean.len() == variance.len(), "image sizes differ");
        assert!(channels > 0 && mean.len().is_multiple_of(channels), "length is not a multiple of the channels");
        let f = f64::from(frames);
        let mut sums = vec![(0.0f64, 0.0f64, 0.0f64, 0usize); channels]; // Σd, Σse², Σz², n
        let mut outliers = 0usize;
        for (i, ((&m, &e), &v)) in mean.iter().zip(exact).zip(variance).enumerate() {
            let se = (f64::from(v) / f).sqrt().max(1.0 / f);
            let d = f64::from(m) - f64::from(e);
            let z = d / se;
            let s = &mut sums[i % channels];
            s.0 += d;
            s.1 += se * se;
            s.2 += z * z;
            s.3 += 1;
            outliers += usize::from(z.abs() > Z_P01);
        }
        let per_channel = sums.iter().filter(|s| s.3 > 0);
        let global = per_channel.clone().map(|s| s.0.abs() / s.1.sqrt()).fold(0.0, f64::max);
        let spread =
            per_channel.map(|s| (s.2 - s.3 as f64) / (2.0 * s.3 as f64).sqrt()).fold(f64::NEG_INFINITY, f64::max);
        let n = mean.len();
        Self { global, spread, outliers: outliers as f64 / n.max(1) as f64, n }
    }

    /// Whether all three criteria hold.
    pub fn passes(&self) -> bool {
        self.global <= GLOBAL_MAX && self.spread <= SPREAD_MAX && self.outliers <= OUTLIERS_MAX
    }
}

/// Welch's t statistic of two means with their variances and sample counts.
pub fn welch_t(mean_a: f64, var_a: f64, n_a: u64, mean_b: f64, var_b: f64, n_b: u64) -> f64 {
    let se2 = var_a / n_a as f64 + var_b / n_b as f64;
    if se2 <= 0.0 { if mean_a == mean_b { 0.0 } else { f64::INFINITY } } else { (mean_a - mean_b) / se2.sqrt() }
}

/// Root mean square difference of two equally sized images.
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "image sizes differ");
    let sum: f64 = a.iter().zip(b).map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2)).sum();
    (sum / a.len().max(1) as f64).sqrt()
}

/// Least-squares slope of log(y) against log(x).
pub fn log_log_slope(x: &[f64], y: &[f64]) -> f64 {
    let (lx, ly): (Vec<f64>, Vec<f64>) = x.iter().zip(y).map(|(a, b)| (a.ln(), b.ln())).unzip();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let cov: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let var: f64 = lx.iter().map(|a| (a - mx).powi(2)).sum();
    cov / var
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
    }

    /// Simulated Bernoulli estimators on 40 × 30 pixels at F = 256 (docs/architecture.md): the
    /// unbiased one passes, a 1 % low bias and a ±5 % checkerboard bias are rejected.
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
    }
}
