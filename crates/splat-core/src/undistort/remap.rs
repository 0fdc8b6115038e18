//! The trainers' photographs, undistorted as OpenCV resamples them: a port of `cv::remap`'s
//! bilinear interpolation of 8-bit images with a constant black border.
//!
//! Each source coordinate is rounded to 1/32 px (`INTER_BITS` = 5, ties to even) and the four
//! taps weighted by 15-bit integers, (32 − a)(32 − b) · 32 for fractions a/32 and b/32, summed
//! and rounded: (Σ w p + 2¹⁴) >> 15. (OpenCV's table saturates the weight of a whole-pixel
//! sample, 2¹⁵, to 2¹⁵ − 1 and moves the missing unit to the opposite tap; the result is the
//! pixel itself either way.) OpenCV 4.14 (the pinned opencv-python-headless) interpolates 8-bit
//! images so through both kinds of map the trainers build; the maps differ in where the
//! coordinate is rounded from:
//!
//! - **fixed-point maps** (`CV_16SC2`, `cv2.undistort`: splatfacto's perspective lenses): from
//!   the map's double-precision coordinate;
//! - **float maps** (`CV_32FC1` and `cv2.remap`: gsplat, splatfacto's fisheyes): from that
//!   coordinate stored in f32 first.
//!
//! A sample whose four taps all lie outside the photo is the border (0); one that straddles its
//! edge takes 0 for the taps outside.

use super::{Undistorting, Undistortion};
use crate::camera::{Camera, CameraError};
use glam::DVec2;

/// Where a map's coordinates are rounded to 1/32 px from (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Sampling {
    /// `CV_16SC2` maps: from double precision.
    FixedPointMap,
    /// `CV_32FC1` maps: from f32.
    FloatMap,
}

/// Bits of a map's fraction (OpenCV's `INTER_BITS`).
const INTER_BITS: u32 = 5;
/// Bits of a weight (OpenCV's `INTER_REMAP_COEF_BITS`).
const COEF_BITS: u32 = 15;

/// An 8-bit photograph: rows top to bottom, each pixel's `channels` values together.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Photo {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Values a pixel (1 to 4).
    pub channels: u32,
    /// width × height × channels values.
    pub data: Vec<u8>,
}

impl Photo {
    /// Values of pixel (x, y), or `None` outside the photo (the constant border).
    fn tap(&self, x: i64, y: i64) -> Option<&[u8]> {
        let inside = (0..i64::from(self.width)).contains(&x) && (0..i64::from(self.height)).contains(&y);
        let c = self.channels as usize;
        inside.then(|| {
            let i = (y as usize * self.width as usize + x as usize) * c;
            &self.data[i..i + c]
        })
    }
}

impl Sampling {
    /// Pixel (the values of each channel) at source point `s` of `photo`, into `out`.
    fn sample(self, photo: &Photo, s: DVec2, out: &mut [u8]) {
        if !s.is_finite() {
            // OpenCV's rounding takes NaN to INT_MIN: the border.
            out.fill(0);
            return;
        }
        let s = match self {
            Sampling::FixedPointMap => s,
            Sampling::FloatMap => s.as_vec2().as_dvec2(),
        };
        // cvRound(s · 32): nearest, ties to even; saturated to i32.
        let fixed = |v: f64| (v * f64::from(1 << INTER_BITS)).round_ties_even() as i32;
        let (u, v) = (fixed(s.x), fixed(s.y));
        let (x, y) = (i64::from(u >> INTER_BITS), i64::from(v >> INTER_BITS));
        let mask = (1 << INTER_BITS) - 1;
        let (a, b) = (u & mask, v & mask);
        let side = 1 << INTER_BITS;
        let mut w = [(side - a) * (side - b), a * (side - b), (side - a) * b, a * b].map(|w| w * side);
        if w[0] == 1 << COEF_BITS {
            // The table's saturated whole-pixel entry.
            w = [(1 << COEF_BITS) - 1, 0, 0, 1];
        }
        bilinear(photo, x, y, out, |p| {
            let sum: i32 = p.iter().zip(w).map(|(&p, w)| p * w).sum();
            ((sum + (1 << (COEF_BITS - 1))) >> COEF_BITS).clamp(0, 255) as u8
        });
    }
}

/// Each channel of the pixel whose top-left tap is (x, y), from its four taps p₀₀, p₀₁
/// (right), p₁₀ (below), p₁₁ by `mix`; the border (0) where all four lie outside the photo.
fn bilinear(photo: &Photo, x: i64, y: i64, out: &mut [u8], mix: impl Fn([i32; 4]) -> u8) {
    if x < -1 || y < -1 || x >= i64::from(photo.width) || y >= i64::from(photo.height) {
        out.fill(0);
        return;
    }
    let taps = [photo.tap(x, y), photo.tap(x + 1, y), photo.tap(x, y + 1), photo.tap(x + 1, y + 1)];
    for (k, o) in out.iter_mut().enumerate() {
        *o = mix(taps.map(|t| t.map_or(0, |t| i32::from(t[k]))));
    }
}

impl Camera {
    /// `photo`, taken through this camera, as `trainer` undistorts it for training and
    /// evaluation ([`Undistorting::photo`]).
    pub fn undistort_photo(&self, trainer: Undistortion, photo: &Photo) -> Result<Photo, CameraError> {
        self.undistorting(trainer)?.photo(photo)
    }
}

impl Undistorting {
    /// `photo`, taken through the camera, as the trainer undistorts it for training and
    /// evaluation: of [`Camera::undistorted`]'s size, resampled by OpenCV's bilinear
    /// interpolation (see the module documentation); a camera the trainer takes as it is keeps
    /// its photo. Refuses a photo of another size than the camera's.
    pub fn photo(&self, photo: &Photo) -> Result<Photo, CameraError> {
        let refuse = |why: String| self.trainer.refuse(why);
        let camera = &self.original;
        if (photo.width, photo.height) != (camera.width, camera.height) {
            return Err(refuse(format!(
                "the photograph is {} × {} and the camera {} × {}: scale the camera or the photograph to match",
                photo.width, photo.height, camera.width, camera.height
            )));
        }
        let c = photo.channels as usize;
        if !(1..=4).contains(&c) || photo.data.len() != photo.width as usize * photo.height as usize * c {
            return Err(refuse(format!(
                "a photograph of {} × {} × {c} values holds {}",
                photo.width,
                photo.height,
                photo.data.len()
            )));
        }
        let Some(plan) = &self.plan else { return Ok(photo.clone()) };
        let (width, height) = plan.crop.size();
        let rows = crate::par::map(&(0..height).collect::<Vec<u32>>(), |&y| {
            let mut row = vec![0u8; width as usize * c];
            for (x, out) in (0..width).zip(row.chunks_exact_mut(c)) {
                plan.sampling.sample(photo, plan.source_pixel(x, y), out);
            }
            row
        });
        Ok(Photo { width, height, channels: photo.channels, data: rows.concat() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn photo(width: u32, height: u32, f: impl Fn(u32, u32) -> u8) -> Photo {
        let data = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| f(x, y)).collect();
        Photo { width, height, channels: 1, data }
    }

    fn at(sampling: Sampling, p: &Photo, x: f64, y: f64) -> u8 {
        let mut out = [0u8];
        sampling.sample(p, DVec2::new(x, y), &mut out);
        out[0]
    }

    #[test]
    fn whole_pixels_are_the_pixels_and_halves_their_means_rounded_up() {
        let p = photo(4, 3, |x, y| (x * 50 + y * 7) as u8);
        for sampling in [Sampling::FixedPointMap, Sampling::FloatMap] {
            for (x, y) in [(0, 0), (3, 2), (2, 1)] {
                assert_eq!(at(sampling, &p, x.into(), y.into()), p.data[(y * 4 + x) as usize], "{sampling:?}");
            }
            // (50 + 100) / 2 = 75; (0 + 7) / 2 = 3.5 and (0 + 50 + 7 + 57) / 4 = 28.5 round up.
            assert_eq!(at(sampling, &p, 1.5, 0.0), 75);
            assert_eq!(at(sampling, &p, 0.0, 0.5), 4);
            assert_eq!(at(sampling, &p, 0.5, 0.5), 29);
        }
    }

    #[test]
    fn maps_are_rounded_to_thirty_seconds_from_their_own_precision() {
        // 0.2 px lies nearest 6/32: 255 × 0.1875 = 47.8 (f32 interpolation would give 51).
        let p = photo(2, 1, |x, _| if x == 0 { 0 } else { 255 });
        assert_eq!(at(Sampling::FixedPointMap, &p, 0.2, 0.0), 48);
        // 300 + 1/64 + 10⁻⁶ rounds to 1/32 past 300 from double precision, but is 300 + 1/64
        // in f32, whose 1/32 tie goes to the even 300.
        let p = photo(302, 1, |x, _| if x == 301 { 255 } else { 0 });
        let s = 300.0 + 1.0 / 64.0 + 1e-6;
        assert_eq!(at(Sampling::FixedPointMap, &p, s, 0.0), 8);
        assert_eq!(at(Sampling::FloatMap, &p, s, 0.0), 0);
    }

    #[test]
    fn the_border_is_black_and_straddling_taps_take_it() {
        let p = photo(3, 3, |_, _| 200);
        for sampling in [Sampling::FixedPointMap, Sampling::FloatMap] {
            assert_eq!(at(sampling, &p, -1.5, 1.0), 0, "all four taps outside");
            assert_eq!(at(sampling, &p, 1.0, 3.0), 0, "below the last row");
            assert_eq!(at(sampling, &p, -0.5, 1.0), 100, "half the taps outside");
            assert_eq!(at(sampling, &p, 2.5, 2.5), 50, "three of four outside");
            assert_eq!(at(sampling, &p, f64::INFINITY, 1.0), 0, "a fisheye map's ±∞");
            assert_eq!(at(sampling, &p, f64::NAN, 1.0), 0, "NaN");
        }
    }
}
