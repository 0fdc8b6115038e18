//! SSIM (Wang et al. 2004) as the Gaussian-splatting papers report it.
//!
//! Each channel of each image is blurred by an 11 × 11 Gaussian window of σ = 1.5 (normalised),
//! giving the local means μ, variances σ² and covariance σ₁₂, and
//!
//! ```text
//! SSIM = (2 μ₁ μ₂ + C₁) (2 σ₁₂ + C₂) / ((μ₁² + μ₂² + C₁) (σ₁² + σ₂² + C₂)),  C₁ = 0.01², C₂ = 0.03²
//! ```
//!
//! on values of range 1. Two means of the map are in use:
//! - **3DGS's** (`utils/loss_utils.py` `ssim`, which its `metrics.py` reports, and most papers'
//!   tables): every pixel, the window zero-padded past the border ([`Ssim::mean`]);
//! - **torchmetrics'** (`StructuralSimilarityIndexMeasure(data_range=1.0)`, which Nerfstudio's
//!   and gsplat's evaluations report): the pixels whose window lies inside the image
//!   ([`Ssim::mean_inside`]). It pads by reflection and crops the padded border, so its values
//!   there are the same map's.

use crate::par;

/// Side of the Gaussian window.
pub const WINDOW: usize = 11;
/// The window's standard deviation, pixels.
pub const SIGMA: f64 = 1.5;
/// C₁ = (0.01 L)², L = 1.
pub const C1: f64 = 0.01 * 0.01;
/// C₂ = (0.03 L)², L = 1.
pub const C2: f64 = 0.03 * 0.03;

/// The SSIM map of two images and its means.
#[derive(Clone, Debug, PartialEq)]
pub struct Ssim {
    /// SSIM per pixel and channel, interleaved as the images are.
    pub map: Vec<f64>,
    /// The mean over every pixel and channel (3DGS's).
    pub mean: f64,
    /// The mean over the pixels whose window lies inside the image (torchmetrics'); `None`
    /// where the image is narrower or lower than the window.
    pub mean_inside: Option<f64>,
}

/// The normalised Gaussian window's weights, g(x) ∝ exp(−(x − 5)² / (2σ²)).
fn weights() -> [f64; WINDOW] {
    let half = (WINDOW / 2) as f64;
    let g: [f64; WINDOW] = std::array::from_fn(|x| (-(x as f64 - half).powi(2) / (2.0 * SIGMA * SIGMA)).exp());
    let sum: f64 = g.iter().sum();
    g.map(|v| v / sum)
}

/// One channel blurred by the window, zero past the border (separable: rows, then columns).
fn blur(plane: &[f64], width: usize, height: usize) -> Vec<f64> {
    let g = weights();
    let half = WINDOW / 2;
    let taps = |i: usize, n: usize| (i.saturating_sub(half)..=(i + half).min(n - 1)).map(move |k| (k, g[k + half - i]));
    let mut rows = vec![0.0; plane.len()];
    for (src, dst) in plane.chunks_exact(width).zip(rows.chunks_exact_mut(width)) {
        for (x, d) in dst.iter_mut().enumerate() {
            *d = taps(x, width).map(|(k, weight)| weight * src[k]).sum();
        }
    }
    let mut out = vec![0.0; plane.len()];
    for (y, dst) in out.chunks_exact_mut(width).enumerate() {
        for (k, weight) in taps(y, height) {
            for (d, s) in dst.iter_mut().zip(&rows[k * width..(k + 1) * width]) {
                *d += weight * s;
            }
        }
    }
    out
}

/// The SSIM map of `a` against `b`, images of `width` × `height` pixels of `channels`
/// interleaved values each; every channel counts.
pub fn ssim(a: &[f32], b: &[f32], width: u32, height: u32, channels: u32) -> Ssim {
    let (w, h, c) = (width as usize, height as usize, channels as usize);
    assert!(a.len() == w * h * c && b.len() == a.len(), "images of {w}×{h}×{c} values");
    let channels: Vec<usize> = (0..c).collect();
    let planes: Vec<Vec<f64>> = par::map(&channels, |&k| channel_map(a, b, (w, h, c), k));
    let map: Vec<f64> = (0..w * h).flat_map(|p| planes.iter().map(move |plane| plane[p])).collect();
    let mean = map.iter().sum::<f64>() / map.len() as f64;
    let half = WINDOW / 2;
    let inside = (w >= WINDOW && h >= WINDOW).then(|| {
        let rows = half..h - half;
        let values = rows.flat_map(|y| (half..w - half).flat_map(move |x| (0..c).map(move |k| (y * w + x) * c + k)));
        let (sum, n) = values.fold((0.0, 0usize), |(s, n), i| (s + map[i], n + 1));
        sum / n as f64
    });
    Ssim { map, mean, mean_inside: inside }
}

/// Channel `k`'s SSIM map.
fn channel_map(a: &[f32], b: &[f32], (w, h, c): (usize, usize, usize), k: usize) -> Vec<f64> {
    let plane = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        let values: Vec<f64> = (0..w * h).map(|p| f(f64::from(a[p * c + k]), f64::from(b[p * c + k]))).collect();
        blur(&values, w, h)
    };
    let (mu1, mu2) = (plane(&|x, _| x), plane(&|_, y| y));
    let (xx, yy, xy) = (plane(&|x, _| x * x), plane(&|_, y| y * y), plane(&|x, y| x * y));
    (0..w * h)
        .map(|p| {
            let (m1, m2) = (mu1[p], mu2[p]);
            let (s1, s2, s12) = (xx[p] - m1 * m1, yy[p] - m2 * m2, xy[p] - m1 * m2);
            ((2.0 * m1 * m2 + C1) * (2.0 * s12 + C2)) / ((m1 * m1 + m2 * m2 + C1) * (s1 + s2 + C2))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth RGB test pattern with edges.
    fn pattern(w: u32, h: u32, phase: f32) -> Vec<f32> {
        (0..w * h)
            .flat_map(|p| {
                let (x, y) = ((p % w) as f32, (p / w) as f32);
                let edge = if x + phase > w as f32 / 2.0 { 0.8 } else { 0.2 };
                [edge, 0.5 + 0.4 * (0.3 * x + phase).sin(), (0.2 * y).cos() * 0.5 + 0.5]
            })
            .collect()
    }

    #[test]
    fn an_image_against_itself_is_one_everywhere() {
        let a = pattern(24, 16, 0.0);
        let s = ssim(&a, &a, 24, 16, 3);
        assert!(s.map.iter().all(|&v| (v - 1.0).abs() < 1e-12));
        assert_eq!(s.mean_inside.map(|m| (m - 1.0).abs() < 1e-12), Some(true));
    }

    #[test]
    fn the_blur_is_the_zero_padded_two_dimensional_window() {
        // Direct 2D convolution with the outer product of the weights, zero past the border.
        let (w, h) = (13usize, 12usize);
        let plane: Vec<f64> = (0..w * h).map(|p| ((p * 37) % 11) as f64 / 10.0).collect();
        let g = weights();
        let half = (WINDOW / 2) as i64;
        let direct = |x: i64, y: i64| {
            let mut s = 0.0;
            for dy in -half..=half {
                for dx in -half..=half {
                    let (u, v) = (x + dx, y + dy);
                    if u >= 0 && v >= 0 && u < w as i64 && v < h as i64 {
                        s += g[(dx + half) as usize] * g[(dy + half) as usize] * plane[v as usize * w + u as usize];
                    }
                }
            }
            s
        };
        let blurred = blur(&plane, w, h);
        for y in 0..h {
            for x in 0..w {
                assert!((blurred[y * w + x] - direct(x as i64, y as i64)).abs() < 1e-12, "({x}, {y})");
            }
        }
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-15 && g[5] > g[4] && g[4] == g[6]);
    }

    #[test]
    fn a_shifted_image_scores_lower_and_the_inside_mean_needs_a_window() {
        let (a, b) = (pattern(32, 20, 0.0), pattern(32, 20, 1.5));
        let s = ssim(&a, &b, 32, 20, 3);
        assert!(s.mean < 0.99 && s.mean > 0.0, "{}", s.mean);
        assert_ne!(s.mean_inside, Some(s.mean));
        assert_eq!(ssim(&a[..3 * 10 * 8], &b[..3 * 10 * 8], 10, 8, 3).mean_inside, None);
    }
}
