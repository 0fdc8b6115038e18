//! The camera of each frame: where in the pixel and where on the lens its rays start.
//!
//! Sun et al. 2025 §4.2 perturb the camera rays of every frame by "frame-number-dependent
//! quasi-random numbers sampled from a stateful Sobol sequence"; vk_gaussian_splatting
//! (Lighting §1.5) renders depth of field with a thin lens in the ray tracer, StochasticSplats
//! and the hybrid. Both are one thing here: frame f of a render draws the point f of a 4-D
//! Owen-scrambled Sobol sequence seeded by the render's seed ([`frame_sample`]), the same for
//! every pixel of the frame, and looks through
//!
//! - the pixel at offset (ξ₀, ξ₁) ∈ [0, 1)² under a box filter, or at its centre;
//! - the lens at the concentric-disk point of (ξ₂, ξ₃), radius `aperture`, toward the point
//!   where the pinhole ray of that offset meets the plane in focus at depth `focus_distance`.
//!
//! The mean over frames is then the image integrated over the pixel's box and the lens: what an
//! unbiased estimator converges to, and what the oracle rendered with the same frames computes
//! exactly for those frames (the filtered oracle, [`crate::oracle::render_oracle`]), so that a
//! statistical test compares like with like.
//!
//! A ray tracer builds the frame's rays per pixel ([`CameraSampling::ray`], any lens);
//! splatting and the oracle's tile culling project through a pinhole, and draw each frame
//! through the frame's own pinhole camera ([`CameraSampling::pinhole`]): the eye moved to the
//! lens point and the principal point moved so that the plane in focus stays where it was and
//! the pixel centres fall on the sample offsets. The two give the same rays
//! (`tests::the_frame_pinhole_sees_along_the_sampled_rays`).

use crate::camera::Camera;
use crate::hit::Ray;
use crate::rng::xxhash32;
use crate::settings::RenderError;
use glam::{Vec2, Vec3};

/// Where a camera ray passes through its pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PixelFilter {
    /// Through the pixel centre, every frame (point sampling: aliased edges that never
    /// converge away).
    #[default]
    Center,
    /// Through a point of the pixel drawn per frame (a box filter over the pixel's square).
    Box,
}

impl PixelFilter {
    /// Every filter, in the order the front ends list them.
    pub const ALL: [PixelFilter; 2] = [PixelFilter::Center, PixelFilter::Box];

    /// Its name on the command line and in world files.
    pub fn name(self) -> &'static str {
        match self {
            PixelFilter::Center => "center",
            PixelFilter::Box => "box",
        }
    }

    /// One line on what it does (the CLI's help).
    pub fn describe(self) -> &'static str {
        match self {
            PixelFilter::Center => "every frame through the pixel centre (point sampling)",
            PixelFilter::Box => "a point of the pixel per frame, from a Sobol sequence (a box filter)",
        }
    }
}

/// A thin lens: depth of field around the plane in focus.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinLens {
    /// Lens radius in world units (0: a pinhole).
    pub aperture: f32,
    /// Distance of the plane in focus along the camera axis.
    pub focus_distance: f32,
}

/// How the camera rays of each frame are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraSampling {
    /// Where in the pixel.
    pub filter: PixelFilter,
    /// Depth of field, if any.
    pub lens: Option<ThinLens>,
}

/// The numbers of one frame's camera: the offset in the pixel and the point on the lens, each
/// in [0, 1)².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSample {
    /// Sub-pixel offset ((0.5, 0.5) is the centre).
    pub pixel: Vec2,
    /// Point of the unit square mapped onto the lens.
    pub lens: Vec2,
}

/// Salt of the frames' Sobol sequence (`FRAME_SOBOL_SALT` in `trace.wgsl`).
pub const FRAME_SOBOL_SALT: u32 = 0xCA3E_5A3F;

/// Point `frame` of the 4-D Owen-scrambled Sobol sequence of the run seeded by `seed` (Burley
/// 2020): dimensions 0–1 place the pixel sample, 2–3 the lens sample. Past 2¹⁶ frames a fresh
/// scramble continues the sequence. `trace.wgsl`'s `frame_sample` is its twin.
pub fn frame_sample(seed: u32, frame: u32) -> FrameSample {
    let scramble = xxhash32([seed, frame >> 16, FRAME_SOBOL_SALT]);
    let d = |dim| sobol_burley::sample(frame & 0xFFFF, dim, scramble);
    FrameSample { pixel: Vec2::new(d(0), d(1)), lens: Vec2::new(d(2), d(3)) }
}

impl CameraSampling {
    /// Whether the camera changes from frame to frame (a deterministic method then renders
    /// every frame, not one).
    pub fn is_random(&self) -> bool {
        self.filter == PixelFilter::Box || self.aperture() > 0.0
    }

    /// The lens radius (0 without a lens).
    pub fn aperture(&self) -> f32 {
        self.lens.map_or(0.0, |l| l.aperture)
    }

    /// Check the lens, naming a bad value.
    pub fn validate(&self) -> Result<(), RenderError> {
        match self.lens {
            Some(l)
                if !(l.aperture.is_finite()
                    && l.aperture >= 0.0
                    && l.focus_distance.is_finite()
                    && l.focus_distance > 0.0) =>
            {
                Err(RenderError::Settings(format!(
                    "lens aperture {} must be finite and ≥ 0 and focus distance {} finite and > 0",
                    l.aperture, l.focus_distance
                )))
            }
            _ => Ok(()),
        }
    }

    /// The sub-pixel offset of a frame under this filter.
    pub fn offset(&self, s: &FrameSample) -> Vec2 {
        match self.filter {
            PixelFilter::Center => Vec2::splat(0.5),
            PixelFilter::Box => s.pixel,
        }
    }

    /// The camera ray of pixel (x, y) in the frame drawn as `s`, through any lens of `camera`
    /// ([`Camera::lens_ray`]).
    pub fn ray(&self, camera: &Camera, x: u32, y: u32, s: &FrameSample) -> Ray {
        let offset = self.offset(s);
        match self.lens {
            Some(l) => camera.lens_ray(x, y, offset, l.aperture, l.focus_distance, s.lens),
            None => camera.ray(x, y, offset),
        }
    }

    /// The pinhole camera of the frame drawn as `s`: its eye at the lens point L = (l_x, l_y, 0)
    /// (camera space), its principal point c′ = c + ½ − o + f l / F, so that its pixel centres
    /// look along [`CameraSampling::ray`] (offset o, focus distance F). Pinhole cameras only.
    pub fn pinhole(&self, camera: &Camera, s: &FrameSample) -> Result<Camera, RenderError> {
        camera.require_pinhole("a camera drawn per frame (pixel filter or thin lens) by projection")?;
        let o = self.offset(s);
        let (l, focus) = match self.lens {
            Some(lens) if lens.aperture > 0.0 => {
                (lens.aperture * crate::lighting::concentric_disk(s.lens), lens.focus_distance)
            }
            _ => (Vec2::ZERO, 1.0),
        };
        Ok(Camera {
            cx: camera.cx + 0.5 - o.x + camera.fx * l.x / focus,
            cy: camera.cy + 0.5 - o.y + camera.fy * l.y / focus,
            translation: camera.translation - Vec3::new(l.x, l.y, 0.0),
            ..*camera
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens_camera() -> (Camera, CameraSampling) {
        let (_, camera) = crate::scenes::cloud();
        let sampling =
            CameraSampling { filter: PixelFilter::Box, lens: Some(ThinLens { aperture: 0.2, focus_distance: 3.0 }) };
        (camera, sampling)
    }

    #[test]
    fn the_frame_pinhole_sees_along_the_sampled_rays() {
        let (camera, sampling) = lens_camera();
        for frame in 0..16 {
            let s = frame_sample(7, frame);
            let pinhole = sampling.pinhole(&camera, &s).unwrap();
            for (x, y) in [(0, 0), (13, 40), (camera.width - 1, camera.height - 1)] {
                let (a, b) = (sampling.ray(&camera, x, y, &s), pinhole.pixel_ray(x, y));
                assert!((a.origin - b.origin).length() < 1e-5, "frame {frame} ({x}, {y}): {a:?} {b:?}");
                assert!((a.dir - b.dir).length() < 1e-5, "frame {frame} ({x}, {y}): {a:?} {b:?}");
            }
        }
        // Without a lens and at the centre, the frame's camera is the camera.
        let still = CameraSampling::default();
        assert_eq!(still.pinhole(&camera, &frame_sample(7, 3)).unwrap(), camera);
        assert!(!still.is_random());
    }

    #[test]
    fn the_plane_in_focus_is_sharp_and_the_rest_is_not() {
        let (camera, sampling) = lens_camera();
        // A point on the plane in focus projects to the same pixel position through every
        // frame's camera (moved back by the pixel offset); a point nearer spreads over the lens.
        let on_focus = camera.center() + 3.0 * camera.forward();
        let near = camera.center() + 1.5 * camera.forward();
        let spread = |p: Vec3| {
            let xs: Vec<Vec2> = (0..64)
                .map(|f| {
                    let s = frame_sample(1, f);
                    let c = sampling.pinhole(&camera, &s).unwrap();
                    c.project_camera(c.to_camera(p)) + (s.pixel - Vec2::splat(0.5))
                })
                .collect();
            xs.iter().map(|x| (*x - xs[0]).length()).fold(0.0f32, f32::max)
        };
        assert!(spread(on_focus) < 1e-3, "in focus: {}", spread(on_focus));
        // The circle of confusion: f·a·|1/1.5 − 1/3| pixels in radius.
        let coc = camera.fx * 0.2 * (1.0 / 1.5 - 1.0 / 3.0);
        assert!(spread(near) > coc, "out of focus: {} against a radius of {coc}", spread(near));
    }

    #[test]
    fn frame_samples_are_stratified_and_seeds_differ() {
        // Sobol's first 16 points put one point in each 4 × 4 cell of the pixel.
        let mut cells = [0u32; 16];
        for f in 0..16 {
            let p = frame_sample(3, f).pixel;
            cells[(p.x * 4.0) as usize * 4 + (p.y * 4.0) as usize] += 1;
        }
        assert_eq!(cells, [1; 16]);
        assert_ne!(frame_sample(3, 0), frame_sample(4, 0));
        assert_ne!(frame_sample(3, 5), frame_sample(3, 5 + (1 << 16)));
    }

    #[test]
    fn a_bad_lens_is_refused() {
        let bad =
            CameraSampling { lens: Some(ThinLens { aperture: f32::NAN, focus_distance: 1.0 }), ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("aperture NaN"));
    }
}
