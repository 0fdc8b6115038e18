//! The camera a trainer trains a distorted capture through.
//!
//! Splatfacto (Nerfstudio's full-image datamanager, `_undistort_image` in
//! `nerfstudio/data/utils/dataloaders.py`) and gsplat's COLMAP parser
//! (`examples/datasets/colmap.py`) do not train through a capture's lens. They resample each
//! photo to a pinhole camera that OpenCV chooses (gsplat: a fisheye to an ideal fisheye) and
//! train on that, so their training and evaluation images are of that camera.
//! [`Camera::undistorted`] gives it, to render what they compare against, and
//! [`Camera::undistort_photo`] the photographs they compare with, resampled as OpenCV resamples
//! them (`remap.rs`).
//!
//! | lens | [`Undistortion::Splatfacto`] | [`Undistortion::Gsplat`] |
//! |---|---|---|
//! | perspective (`OPENCV`, `RADIAL`, …) | `cv2.getOptimalNewCameraMatrix(K, D, (w, h), 0)` of K in OpenCV's pixel centres (c − ½); the image cropped to its valid-pixel rectangle, the principal point moved with the crop | the same of K as it is; cropped, the principal point not moved |
//! | fisheye (`OPENCV_FISHEYE`) | `cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(K, D, (w, h), I, balance = 0)` of c − ½, the same size | an ideal (equidistant) fisheye of K, cropped to where its map lands inside the photo, the principal point moved with the crop: gsplat's map, which samples about the image's middle (w // 2, h // 2), not about c (below) |
//! | pinhole, equirectangular | unchanged | unchanged |
//!
//! Nerfstudio leaves a camera whose coefficients are all zero as it is; gsplat undistorts every
//! camera of a distorted model. OpenCV's estimates undistort a few image points by its own
//! iterations, which are not exact, and are ported as they are, since the camera is whatever
//! OpenCV returned:
//! - perspective (`undistortPoints`' default, five steps): x ← (x₀ − δ(x)) · d(r²) / n(r²),
//!   with n / d the radial factor and δ the tangential and prism terms of [`Distortion`];
//! - fisheye (`fisheye::undistortPoints`' default): Newton's method on θ_d = θ (1 + k₁θ² + k₂θ⁴ +
//!   k₃θ⁶ + k₄θ⁸), at most 10 steps, until a step is below 1e-8.
//!
//! gsplat's fisheye is not OpenCV's: its pixel q of the new image, at x₁ = (q − c) / f and
//! θ = |x₁|, samples the photo at f x₁ (1 + k₁θ² + k₂θ⁴ + k₃θ⁶ + k₄θ⁸) + (w // 2, h // 2), in
//! double precision rounded to f32. That is an ideal fisheye of K, the angle θ of a ray
//! mapped through the lens, but about the image's middle and not about c. The image is cropped
//! to the box of the pixels whose sample lies strictly inside (0, w − 1) × (0, h − 1).
//! simple_trainer renders the cropped image through K, with the principal point moved by the
//! crop, as its `--camera_model` says: the ideal fisheye is `--camera_model fisheye`, the
//! only one that matches these images.

mod remap;

pub use remap::Photo;

use crate::camera::{Camera, CameraError};
use crate::lens::{Distortion, Lens};
use glam::DVec2;

/// Whose undistortion (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Undistortion {
    /// Nerfstudio's splatfacto (its full-image datamanager).
    Splatfacto,
    /// gsplat's `simple_trainer` (its COLMAP parser).
    Gsplat,
}

impl Undistortion {
    /// Every trainer's undistortion.
    pub const ALL: [Undistortion; 2] = [Undistortion::Splatfacto, Undistortion::Gsplat];

    /// Its name, as the CLI and Python take it.
    pub const fn name(self) -> &'static str {
        match self {
            Undistortion::Splatfacto => "splatfacto",
            Undistortion::Gsplat => "gsplat",
        }
    }

    /// Its refusal of a camera or photograph, for reason `why`.
    fn refuse(self, why: String) -> CameraError {
        CameraError::Undistort { trainer: self.name(), why }
    }

    /// What it does, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            Undistortion::Splatfacto => {
                "Nerfstudio's splatfacto: OpenCV's optimal pinhole (alpha 0, cropped) or fisheye pinhole (balance 0)"
            }
            Undistortion::Gsplat => {
                "gsplat's simple_trainer: OpenCV's optimal pinhole (alpha 0, cropped); a fisheye, gsplat's ideal fisheye"
            }
        }
    }
}

/// Intrinsics in pixels, in double precision: the focal lengths f and principal point c.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Intrinsics {
    f: DVec2,
    c: DVec2,
}

impl Intrinsics {
    fn of(camera: &Camera) -> Self {
        Self { f: DVec2::new(camera.fx.into(), camera.fy.into()), c: DVec2::new(camera.cx.into(), camera.cy.into()) }
    }

    /// Pixel coordinates of normalised `x`.
    fn pixel(&self, x: DVec2) -> DVec2 {
        self.f * x + self.c
    }

    /// Normalised coordinates of pixel `p`.
    fn normalised(&self, p: DVec2) -> DVec2 {
        (p - self.c) / self.f
    }

    /// The same with the principal point moved by `d` (OpenCV's pixel centres are at integers,
    /// ours at half-integers: d = −½ into OpenCV, +½ back).
    fn shifted(self, d: f64) -> Self {
        Self { c: self.c + d, ..self }
    }

    /// Rounded to single precision, as a trainer that keeps K in f32 (Nerfstudio's cameras are
    /// float32 tensors) hands OpenCV's estimate back to OpenCV.
    fn single(self) -> Self {
        Self { f: self.f.as_vec2().as_dvec2(), c: self.c.as_vec2().as_dvec2() }
    }

    /// The same in the image cropped to `rect`.
    fn cropped(self, rect: Rect) -> Self {
        Self { c: self.c - DVec2::new(rect.x as f64, rect.y as f64), ..self }
    }
}

/// An image rectangle in whole pixels, as OpenCV's `cv::Rect`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x: i64,
    y: i64,
    width: i64,
    height: i64,
}

impl Rect {
    /// `cv::Rect(Rect_<double>)`: each field rounded to the nearest integer, ties to even.
    fn rounded(x: f64, y: f64, width: f64, height: f64) -> Self {
        let r = |v: f64| v.round_ties_even() as i64;
        Self { x: r(x), y: r(y), width: r(width), height: r(height) }
    }

    /// The whole image of `size` (width, height).
    fn whole((width, height): (u32, u32)) -> Self {
        Rect { x: 0, y: 0, width: width.into(), height: height.into() }
    }

    /// Its width and height.
    fn size(self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// `a &= b`: the intersection, or the empty rectangle.
    fn intersect(self, b: Rect) -> Rect {
        let (x, y) = (self.x.max(b.x), self.y.max(b.y));
        let width = (self.x + self.width).min(b.x + b.width) - x;
        let height = (self.y + self.height).min(b.y + b.height) - y;
        if width <= 0 || height <= 0 { Rect { x: 0, y: 0, width: 0, height: 0 } } else { Rect { x, y, width, height } }
    }
}

/// OpenCV's `undistortPoints(p, K, D)` with its default criteria (five fixed-point steps):
/// the normalised coordinates of distorted pixel `p` (see the module documentation).
fn opencv_undistort(p: DVec2, k: Intrinsics, d: &Distortion) -> DVec2 {
    let [a1, a2, a3, _] = d.radial.map(f64::from);
    let [b1, b2, b3] = d.rational.map(f64::from);
    let [p1, p2] = d.tangential.map(f64::from);
    let [s1, s2] = d.prism.map(f64::from);
    let x0 = k.normalised(p);
    let mut x = x0;
    for _ in 0..5 {
        let r2 = x.length_squared();
        let inverse_factor = (1.0 + ((b3 * r2 + b2) * r2 + b1) * r2) / (1.0 + ((a3 * r2 + a2) * r2 + a1) * r2);
        if inverse_factor < 0.0 {
            return x0;
        }
        let delta = DVec2::new(
            2.0 * p1 * x.x * x.y + p2 * (r2 + 2.0 * x.x * x.x) + s1 * r2,
            p1 * (r2 + 2.0 * x.y * x.y) + 2.0 * p2 * x.x * x.y + s2 * r2,
        );
        x = (x0 - delta) * inverse_factor;
    }
    x
}

/// The inscribed rectangle of OpenCV's `getUndistortRectangles` as (x₀, y₀, x₁, y₁): a 9 × 9
/// grid of pixels from (0, 0) to (w − 1, h − 1) undistorted, then mapped through `to` (the
/// normalised coordinates where `to` is `None`); the innermost of its left column, right
/// column, top row and bottom row.
fn inscribed(k: Intrinsics, d: &Distortion, (w, h): (u32, u32), to: Option<Intrinsics>) -> [f64; 4] {
    const N: u32 = 9;
    let [mut x0, mut x1, mut y0, mut y1] = [f64::MIN, f64::MAX, f64::MIN, f64::MAX];
    for j in 0..N {
        for i in 0..N {
            let p = DVec2::new(f64::from(i * (w - 1)), f64::from(j * (h - 1))) / f64::from(N - 1);
            let x = opencv_undistort(p, k, d);
            let q = to.map_or(x, |to| to.pixel(x));
            if i == 0 {
                x0 = x0.max(q.x);
            }
            if i == N - 1 {
                x1 = x1.min(q.x);
            }
            if j == 0 {
                y0 = y0.max(q.y);
            }
            if j == N - 1 {
                y1 = y1.min(q.y);
            }
        }
    }
    [x0, y0, x1, y1]
}

/// `cv2.getOptimalNewCameraMatrix(K, D, (w, h), alpha = 0)` and its valid-pixel rectangle:
/// the pinhole that maps the inscribed rectangle onto [0, w − 1] × [0, h − 1].
fn optimal_pinhole(k: Intrinsics, d: &Distortion, size: (u32, u32)) -> (Intrinsics, Rect) {
    let (w, h) = (f64::from(size.0), f64::from(size.1));
    let [x0, y0, x1, y1] = inscribed(k, d, size, None);
    let f = DVec2::new((w - 1.0) / (x1 - x0), (h - 1.0) / (y1 - y0));
    let new = Intrinsics { f, c: -f * DVec2::new(x0, y0) };
    let [x0, y0, x1, y1] = inscribed(k, d, size, Some(new));
    (new, Rect::rounded(x0, y0, x1 - x0, y1 - y0).intersect(Rect::whole(size)))
}

/// OpenCV's `fisheye::undistortPoints(p, K, D)` with its default criteria: the undistorted
/// normalised (pinhole) coordinates of distorted pixel `p`, `None` where OpenCV marks the point
/// invalid (θ not within 90° of the axis, or no convergence).
fn opencv_fisheye_undistort(p: DVec2, k: Intrinsics, coefficients: [f64; 4]) -> Option<DVec2> {
    let [k1, k2, k3, k4] = coefficients;
    let x = k.normalised(p);
    let theta_d = x.length();
    if theta_d <= 1e-8 {
        return Some(DVec2::ZERO);
    }
    let mut theta = theta_d;
    let mut converged = false;
    for _ in 0..10 {
        let t2 = theta * theta;
        let (t4, t6, t8) = (t2 * t2, t2 * t2 * t2, t2 * t2 * t2 * t2);
        let fix = (theta * (1.0 + k1 * t2 + k2 * t4 + k3 * t6 + k4 * t8) - theta_d)
            / (1.0 + 3.0 * k1 * t2 + 5.0 * k2 * t4 + 7.0 * k3 * t6 + 9.0 * k4 * t8);
        theta -= fix;
        if fix.abs() < 1e-8 {
            converged = true;
            break;
        }
    }
    let valid = converged && theta > -std::f64::consts::FRAC_PI_2 && theta < std::f64::consts::FRAC_PI_2;
    (valid && theta >= 0.0).then(|| x * (theta.tan() / theta_d))
}

/// `cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(K, D, (w, h), I, balance = 0)`:
/// the pinhole whose focal length fits the undistorted middles of the four image edges to the
/// image (the largest of the four fits), in square pixels of the aspect ratio f_x / f_y; `None`
/// where OpenCV cannot undistort one of them.
fn fisheye_pinhole(k: Intrinsics, coefficients: [f64; 4], (w, h): (u32, u32)) -> Option<Intrinsics> {
    let edges = [(w / 2, 0), (w, h / 2), (w / 2, h), (0, h / 2)]
        .map(|(x, y)| opencv_fisheye_undistort(DVec2::new(x.into(), y.into()), k, coefficients));
    let aspect = k.f.x / k.f.y;
    let square = |p: DVec2| DVec2::new(p.x, p.y * aspect);
    let mut points = [DVec2::ZERO; 4];
    for (point, edge) in points.iter_mut().zip(edges) {
        *point = edge?;
    }
    let centre = square(points.iter().sum::<DVec2>() / 4.0);
    let points = points.map(square);
    let min = points.iter().fold(DVec2::MAX, |m, &p| m.min(p));
    let max = points.iter().fold(DVec2::MIN, |m, &p| m.max(p));
    let (w, h) = (f64::from(w), f64::from(h));
    let f = [
        w * 0.5 / (centre.x - min.x),
        w * 0.5 / (max.x - centre.x),
        h * 0.5 * aspect / (centre.y - min.y),
        h * 0.5 * aspect / (max.y - centre.y),
    ]
    .into_iter()
    .fold(f64::MIN, f64::max);
    let c = -centre * f + DVec2::new(w, h * aspect) * 0.5;
    Some(Intrinsics { f: DVec2::new(f, f / aspect), c: DVec2::new(c.x, c.y / aspect) })
}

/// The lens OpenCV undistorts, in its own terms.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    /// `cv::undistort` and `cv::initUndistortRectifyMap`'s model: [`Distortion`].
    Perspective(Distortion),
    /// `cv::fisheye`'s k₁…k₄.
    Fisheye([f64; 4]),
    /// gsplat's own fisheye map, k₁…k₄ about the image's middle (module documentation).
    GsplatFisheye([f64; 4], DVec2),
}

/// What a trainer does to the photos of one distorted camera, in OpenCV's pixel convention
/// (pixel centres at integers): the photo of intrinsics `source` through `lens` is resampled
/// to the pinhole `target` (gsplat's fisheye: the ideal fisheye), whose image is then cropped
/// to `crop`; the trainer's camera of the cropped image has intrinsics `camera` in splat's
/// convention and the lens `trained`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Plan {
    source: Intrinsics,
    lens: Source,
    target: Intrinsics,
    crop: Rect,
    camera: Intrinsics,
    trained: Lens,
    sampling: remap::Sampling,
}

impl Plan {
    /// Where OpenCV samples the photo for pixel (x, y) of the cropped image: the map of
    /// `cv::initUndistortRectifyMap` (perspective) or `cv::fisheye::initUndistortRectifyMap`,
    /// in double precision as OpenCV computes it, or gsplat's fisheye map.
    fn source_pixel(&self, x: u32, y: u32) -> DVec2 {
        let q = DVec2::new(f64::from(x) + self.crop.x as f64, f64::from(y) + self.crop.y as f64);
        self.lens.sample(q, self.source, self.target)
    }
}

impl Source {
    /// Where pixel `q` of the resampled image of intrinsics `target` samples the photo of
    /// intrinsics `source` through this lens.
    fn sample(self, q: DVec2, source: Intrinsics, target: Intrinsics) -> DVec2 {
        let n = target.normalised(q);
        let (f, c) = (source.f, source.c);
        match self {
            Source::Perspective(d) => f * d.distort(n) + c,
            Source::Fisheye([k1, k2, k3, k4]) => {
                let r = n.length();
                let theta = r.atan();
                let (t2, t4, t6, t8) = (theta * theta, theta.powi(4), theta.powi(6), theta.powi(8));
                let theta_d = theta * (1.0 + k1 * t2 + k2 * t4 + k3 * t6 + k4 * t8);
                let scale = if r == 0.0 { 1.0 } else { theta_d / r };
                f * n * scale + c
            }
            Source::GsplatFisheye([k1, k2, k3, k4], middle) => {
                // numpy's `theta**2` squares; its other powers call pow.
                let theta = n.length();
                let r = 1.0 + k1 * (theta * theta) + k2 * theta.powf(4.0) + k3 * theta.powf(6.0) + k4 * theta.powf(8.0);
                f * n * r + middle
            }
        }
    }
}

/// Whether gsplat's fisheye `sample` of a photo of `(w, h)`, rounded to f32 as its map is,
/// lies strictly inside (0, w − 1) × (0, h − 1): its mask, and the box it crops to.
fn gsplat_inside(sample: DVec2, (w, h): (u32, u32)) -> bool {
    let s = sample.as_vec2();
    s.x > 0.0 && s.y > 0.0 && s.x < (w - 1) as f32 && s.y < (h - 1) as f32
}

/// gsplat's crop of its fisheye map over an image of `(w, h)`: the box of the pixels whose
/// sample is [`gsplat_inside`]; `None` where none is.
fn gsplat_fisheye_crop(lens: Source, k: Intrinsics, (w, h): (u32, u32)) -> Option<Rect> {
    let mut bounds: Option<(u32, u32, u32, u32)> = None;
    for y in 0..h {
        for x in 0..w {
            if gsplat_inside(lens.sample(DVec2::new(x.into(), y.into()), k, k), (w, h)) {
                let (x0, y0, x1, y1) = bounds.unwrap_or((x, y, x, y));
                bounds = Some((x0.min(x), y0.min(y), x1.max(x), y1.max(y)));
            }
        }
    }
    let (x0, y0, x1, y1) = bounds?;
    Some(Rect { x: x0.into(), y: y0.into(), width: (x1 - x0 + 1).into(), height: (y1 - y0 + 1).into() })
}

impl Camera {
    /// What `trainer` does to this camera's photos; `None` for a camera it trains through as
    /// it is.
    fn plan(&self, trainer: Undistortion) -> Result<Option<Plan>, CameraError> {
        let refuse = |why: String| trainer.refuse(why);
        let k = Intrinsics::of(self);
        let size = (self.width, self.height);
        let plan = match (self.lens, trainer) {
            (Lens::Pinhole | Lens::Equirectangular, _) => return Ok(None),
            (Lens::Perspective(d), Undistortion::Splatfacto) if d == Distortion::default() => return Ok(None),
            (Lens::Fisheye(d), Undistortion::Splatfacto) if d == Distortion::default() => return Ok(None),
            (Lens::Perspective(d), _) if d.radial[3] != 0.0 => {
                return Err(refuse(format!(
                    "OpenCV's perspective model has no r⁸ term, and this lens has one ({}; Nerfstudio asserts k4 = 0)",
                    d.radial[3]
                )));
            }
            (Lens::Perspective(d), Undistortion::Splatfacto) => {
                // `cv2.undistort`, which samples through fixed-point maps.
                // Nerfstudio's K is float32, and so is OpenCV's estimate of it.
                let source = k.shifted(-0.5);
                let (target, crop) = optimal_pinhole(source, &d, size);
                let target = target.single();
                let camera = target.cropped(crop).shifted(0.5);
                Plan {
                    source,
                    lens: Source::Perspective(d),
                    target,
                    crop,
                    camera,
                    trained: Lens::Pinhole,
                    sampling: remap::Sampling::FixedPointMap,
                }
            }
            (Lens::Perspective(d), Undistortion::Gsplat) => {
                // `cv2.remap` through float maps; gsplat crops its images to the valid pixels
                // but keeps the principal point.
                let (target, crop) = optimal_pinhole(k, &d, size);
                Plan {
                    source: k,
                    lens: Source::Perspective(d),
                    target,
                    crop,
                    camera: target,
                    trained: Lens::Pinhole,
                    sampling: remap::Sampling::FloatMap,
                }
            }
            (Lens::Fisheye(d), _) if d.rational != [0.0; 3] || d.tangential != [0.0; 2] || d.prism != [0.0; 2] => {
                return Err(refuse(
                    "OpenCV's fisheye model has k1–k4 only, and this lens has tangential, rational or thin-prism \
                     coefficients"
                        .into(),
                ));
            }
            (Lens::Fisheye(d), Undistortion::Splatfacto) => {
                let source = k.shifted(-0.5);
                let coefficients = d.radial.map(f64::from);
                let target = fisheye_pinhole(source, coefficients, size).ok_or_else(|| {
                    refuse("OpenCV cannot undistort the middle of an image edge of this lens (it lies 90° or more from the axis, or its undistortion does not converge)".into())
                })?;
                let target = target.single();
                let crop = Rect::whole(size);
                let camera = target.shifted(0.5);
                Plan {
                    source,
                    lens: Source::Fisheye(coefficients),
                    target,
                    crop,
                    camera,
                    trained: Lens::Pinhole,
                    sampling: remap::Sampling::FloatMap,
                }
            }
            (Lens::Fisheye(d), Undistortion::Gsplat) => {
                // gsplat's own map, about (w // 2, h // 2), in f32 maps; the crop moves c.
                let middle = DVec2::new((self.width / 2).into(), (self.height / 2).into());
                let lens = Source::GsplatFisheye(d.radial.map(f64::from), middle);
                let crop = gsplat_fisheye_crop(lens, k, size)
                    .ok_or_else(|| refuse("gsplat's fisheye map lands outside the photo at every pixel".into()))?;
                Plan {
                    source: k,
                    lens,
                    target: k,
                    crop,
                    camera: k.cropped(crop),
                    trained: Lens::Fisheye(Distortion::default()),
                    sampling: remap::Sampling::FloatMap,
                }
            }
        };
        if plan.crop.width == 0 {
            return Err(refuse("OpenCV's valid-pixel rectangle of this lens is empty".into()));
        }
        Ok(Some(plan))
    }

    /// What `trainer` does to this camera's photos, planned once (gsplat's fisheye crop reads
    /// its whole map): its camera, its photos and its mask are [`Undistorting`]'s. The plan does
    /// not depend on the camera's pose, so the views of one physical camera can share it.
    pub fn undistorting(&self, trainer: Undistortion) -> Result<Undistorting, CameraError> {
        Ok(Undistorting { original: *self, trainer, plan: self.plan(trainer)? })
    }

    /// The camera `trainer` trains this camera's images through (see the module
    /// documentation): a pinhole, or gsplat's ideal fisheye; a camera without a distorted lens
    /// is its own.
    pub fn undistorted(&self, trainer: Undistortion) -> Result<Camera, CameraError> {
        self.undistorting(trainer)?.camera()
    }

    /// The pixels of [`Camera::undistorted`]'s image that `trainer` scores
    /// ([`Undistorting::mask`]).
    pub fn undistortion_mask(&self, trainer: Undistortion) -> Result<Option<Photo>, CameraError> {
        Ok(self.undistorting(trainer)?.mask())
    }
}

/// The undistortions of a capture's views by one trainer: the views share a few physical
/// cameras (intrinsics, lens and size), and each is planned once, its mask made once.
#[derive(Clone, Debug)]
pub struct Undistortions {
    trainer: Undistortion,
    planned: Vec<Planned>,
}

/// One physical camera's undistortion, and its mask once made.
#[derive(Clone, Debug)]
struct Planned {
    undistorting: Undistorting,
    mask: std::cell::OnceCell<Option<Photo>>,
}

impl Undistortions {
    /// No camera planned yet.
    pub fn new(trainer: Undistortion) -> Self {
        Self { trainer, planned: Vec::new() }
    }

    /// The undistortion of `camera`: the plan of an earlier view of the same physical camera,
    /// else a new one.
    pub fn of(&mut self, camera: &Camera) -> Result<Undistorting, CameraError> {
        let i = self.index(camera)?;
        let earlier = &self.planned[i].undistorting;
        Ok(Undistorting { original: *camera, ..earlier.clone() })
    }

    /// The mask of `camera`'s undistorted image ([`Undistorting::mask`]), made once for all the
    /// views of its physical camera (the mask does not depend on the pose).
    pub fn mask(&mut self, camera: &Camera) -> Result<Option<&Photo>, CameraError> {
        let i = self.index(camera)?;
        let planned = &self.planned[i];
        Ok(planned.mask.get_or_init(|| planned.undistorting.mask()).as_ref())
    }

    /// Where `camera`'s physical camera is planned, planning it on first sight.
    fn index(&mut self, camera: &Camera) -> Result<usize, CameraError> {
        let posed_here =
            |u: &Undistorting| Camera { rotation: camera.rotation, translation: camera.translation, ..u.original };
        if let Some(i) = self.planned.iter().position(|p| posed_here(&p.undistorting) == *camera) {
            return Ok(i);
        }
        let undistorting = camera.undistorting(self.trainer)?;
        self.planned.push(Planned { undistorting, mask: std::cell::OnceCell::new() });
        Ok(self.planned.len() - 1)
    }
}

/// A camera's undistortion by one trainer, planned ([`Camera::undistorting`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Undistorting {
    original: Camera,
    trainer: Undistortion,
    /// `None`: the trainer takes the camera as it is.
    plan: Option<Plan>,
}

impl Undistorting {
    /// The camera the trainer trains the images through ([`Camera::undistorted`]).
    pub fn camera(&self) -> Result<Camera, CameraError> {
        let Some(plan) = &self.plan else { return Ok(self.original) };
        let (width, height) = plan.crop.size();
        let new = plan.camera;
        let camera = Camera {
            width,
            height,
            fx: new.f.x as f32,
            fy: new.f.y as f32,
            cx: new.c.x as f32,
            cy: new.c.y as f32,
            lens: plan.trained,
            ..self.original
        };
        camera
            .validate()
            .map_err(|e| self.trainer.refuse(format!("OpenCV's estimate for this lens is not a camera ({e})")))?;
        Ok(camera)
    }

    /// The pixels of the undistorted image that the trainer scores, where it masks some, as a
    /// one-channel image of that size (255 where a pixel counts, 0 where not): gsplat's fisheye
    /// masks those whose sample falls outside the photo (its parser's `mask`, which its loss
    /// leaves out and its evaluation renders as black); `None` where every pixel counts.
    pub fn mask(&self) -> Option<Photo> {
        let plan = self.plan.as_ref().filter(|plan| matches!(plan.lens, Source::GsplatFisheye(..)))?;
        let (width, height) = plan.crop.size();
        let size = (self.original.width, self.original.height);
        let pixels = (0..height).flat_map(|y| (0..width).map(move |x| (x, y)));
        let data = pixels.map(|(x, y)| if gsplat_inside(plan.source_pixel(x, y), size) { 255 } else { 0 }).collect();
        Some(Photo { width, height, channels: 1, data })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec3};

    fn camera(lens: Lens) -> Camera {
        Camera::from_intrinsics(800, 600, 700.0, 690.0, 405.0, 297.0, Mat3::IDENTITY, Vec3::ZERO)
            .and_then(|c| c.with_lens(lens))
            .expect("a valid camera")
    }

    fn barrel() -> Distortion {
        Distortion { radial: [-0.2, 0.05, 0.0, 0.0], tangential: [0.001, -0.002], ..Default::default() }
    }

    /// Where a pixel of `undistorted` lands in `original`'s image: its ray, projected through
    /// the original lens.
    fn source_pixel(original: &Camera, undistorted: &Camera, p: DVec2) -> DVec2 {
        let x = Intrinsics::of(undistorted).normalised(p);
        let distorted = original.lens.project(x.extend(1.0)).expect("in front");
        Intrinsics::of(original).pixel(distorted)
    }

    /// The views of one physical camera share its plan, each with its own pose, and give what
    /// each would alone; another camera (here f changed, or the lens) is planned anew.
    #[test]
    fn views_of_one_camera_share_its_plan() {
        let fisheye = Distortion { radial: [0.05, -0.01, 0.0, 0.0], ..Default::default() };
        for lens in [Lens::Perspective(barrel()), Lens::Fisheye(fisheye)] {
            let a = camera(lens);
            let moved = Camera { rotation: Mat3::from_rotation_y(0.3), translation: Vec3::new(1.0, 2.0, 3.0), ..a };
            let other = Camera { fx: 650.0, ..a };
            for trainer in Undistortion::ALL {
                let mut undistortions = Undistortions::new(trainer);
                for view in [a, moved, other, moved, a] {
                    let alone = view.undistorting(trainer).unwrap();
                    assert_eq!(undistortions.of(&view).unwrap(), alone, "{lens:?} {trainer:?}");
                    assert_eq!(alone.camera().unwrap().rotation, view.rotation);
                    assert_eq!(undistortions.mask(&view).unwrap(), alone.mask().as_ref(), "{lens:?} {trainer:?}");
                }
                assert_eq!(undistortions.planned.len(), 2, "{lens:?} {trainer:?}: one plan a physical camera");
            }
        }
    }

    #[test]
    fn cameras_without_distortion_are_their_own() {
        for trainer in Undistortion::ALL {
            for lens in [Lens::Pinhole, Lens::Equirectangular] {
                assert_eq!(camera(lens).undistorted(trainer), Ok(camera(lens)));
            }
        }
        let plain = [Lens::Perspective(Distortion::default()), Lens::Fisheye(Distortion::default())];
        for lens in plain {
            assert_eq!(camera(lens).undistorted(Undistortion::Splatfacto), Ok(camera(lens)));
        }
    }

    #[test]
    fn the_optimal_pinhole_sees_only_pixels_the_lens_saw() {
        // alpha = 0: every pixel of the cropped image comes from inside the photo. Under barrel
        // distortion the edges' middles are the innermost, so they reach the photo's edges,
        // within the pixel and a half the crop and OpenCV's approximate undistortion lose.
        let original = camera(Lens::Perspective(barrel()));
        for trainer in Undistortion::ALL {
            let new = original.undistorted(trainer).expect("undistorts");
            assert!(new.is_pinhole() && new.width < 800 && new.height < 600, "{new:?}");
            let (w, h) = (f64::from(new.width), f64::from(new.height));
            let corners = [(0.5, 0.5), (w - 0.5, 0.5), (0.5, h - 0.5), (w - 0.5, h - 0.5)];
            let middles = [(w / 2.0, 0.5), (w - 0.5, h / 2.0), (w / 2.0, h - 0.5), (0.5, h / 2.0)];
            let source = |(x, y)| source_pixel(&original, &new, DVec2::new(x, y));
            for s in corners.into_iter().chain(middles).map(source) {
                assert!(s.x > 0.0 && s.y > 0.0 && s.x < 800.0 && s.y < 600.0, "{trainer:?} {s}");
            }
            let m = middles.map(source);
            let gaps = [m[0].y, 800.0 - m[1].x, 600.0 - m[2].y, m[3].x];
            assert!(gaps.iter().all(|&g| g < 1.5), "{trainer:?} {gaps:?}");
        }
    }

    #[test]
    fn the_fisheye_pinhole_fits_the_edges_middles() {
        // balance = 0: the largest of the four focal lengths that fit an edge's middle to its
        // edge, so the nearest edge middle lands on its edge and the others outside the image
        // (with square pixels: OpenCV's centre is off by the aspect ratio otherwise).
        let d = Distortion { radial: [0.05, -0.01, 0.002, 0.0], ..Default::default() };
        let original = Camera { fy: 700.0, ..camera(Lens::Fisheye(d)) };
        let new = original.undistorted(Undistortion::Splatfacto).expect("undistorts");
        assert_eq!((new.width, new.height), (800, 600));
        let k = Intrinsics::of(&new);
        let edges = [(400.0, 0.0), (800.0, 300.0), (400.0, 600.0), (0.0, 300.0)].map(|(x, y)| {
            let ray = original.lens.unproject(Intrinsics::of(&original).normalised(DVec2::new(x, y))).0;
            k.pixel(DVec2::new(ray.x / ray.z, ray.y / ray.z))
        });
        let outside = [-edges[0].y, edges[1].x - 800.0, edges[2].y - 600.0, -edges[3].x];
        let nearest = outside.iter().fold(f64::MAX, |m, &v| m.min(v.abs()));
        assert!(nearest < 0.6, "{outside:?}");
        assert!(outside.iter().all(|&v| v > -0.6), "{outside:?}");
    }

    #[test]
    fn gsplats_fisheye_is_an_ideal_fisheye_cropped_to_its_maps_inside() {
        // Without coefficients and with c at the image's middle, gsplat's map is the identity:
        // the crop keeps the pixels strictly inside, and the lens is the ideal fisheye.
        let small = |lens| Camera { width: 64, height: 48, fx: 40.0, fy: 41.0, cx: 32.0, cy: 24.0, ..camera(lens) };
        let ideal = small(Lens::Fisheye(Distortion::default()));
        let plan = ideal.plan(Undistortion::Gsplat).unwrap().expect("gsplat undistorts every fisheye");
        assert_eq!(plan.crop, Rect { x: 1, y: 1, width: 62, height: 46 });
        assert!(plan.source_pixel(0, 0).abs_diff_eq(DVec2::new(1.0, 1.0), 1e-12));
        let undistorted = ideal.undistorted(Undistortion::Gsplat).unwrap();
        assert_eq!((undistorted.width, undistorted.height, undistorted.cx, undistorted.cy), (62, 46, 31.0, 23.0));
        assert_eq!(undistorted.lens, Lens::Fisheye(Distortion::default()));
        // A barrel fisheye samples nearer the middle: the crop grows to the whole image.
        let barrel = small(Lens::Fisheye(Distortion { radial: [-0.2, 0.05, 0.0, 0.0], ..Default::default() }));
        let plan = barrel.plan(Undistortion::Gsplat).unwrap().unwrap();
        assert_eq!(plan.crop, Rect::whole((64, 48)), "{plan:?}");
    }

    #[test]
    fn lenses_opencv_cannot_undistort_are_refused_by_name() {
        let k4 = Distortion { radial: [0.1, 0.0, 0.0, 0.01], ..Default::default() };
        let prism = Distortion { radial: [0.1, 0.0, 0.0, 0.0], prism: [0.01, 0.0], ..Default::default() };
        let wild = Distortion { radial: [2.0, 0.0, 0.0, 0.0], tangential: [5.0, 0.0], ..Default::default() };
        let cases = [
            (Lens::Perspective(k4), Undistortion::Splatfacto, "no r⁸ term"),
            (Lens::Perspective(k4), Undistortion::Gsplat, "no r⁸ term"),
            (Lens::Fisheye(prism), Undistortion::Splatfacto, "k1–k4 only"),
            // OpenCV's five steps diverge: its rectangle turns inside out.
            (Lens::Perspective(wild), Undistortion::Splatfacto, "rectangle of this lens is empty"),
        ];
        for (lens, trainer, why) in cases {
            let err = camera(lens).undistorted(trainer).expect_err("refused").to_string();
            assert!(err.contains(trainer.name()) && err.contains(why), "{err}");
        }
        // A fisheye whose edge lies past 90° from the axis.
        let wide = Camera { fx: 200.0, fy: 200.0, ..camera(Lens::Fisheye(Distortion::default())) };
        let wide = wide.with_lens(Lens::Fisheye(Distortion { radial: [0.01, 0.0, 0.0, 0.0], ..Default::default() }));
        let err = wide.expect("valid").undistorted(Undistortion::Splatfacto).expect_err("refused").to_string();
        assert!(err.contains("90°"), "{err}");
    }
}
