//! The frame loop every CPU renderer stands on (docs/architecture.md, "The frame loop").
//!
//! A render is `frames.count` frames of one method; each frame gives every pixel one
//! [`Sample`], drawn with the counter-based decisions of [`crate::rng`] keyed by (pixel, frame
//! key). [`render_tiles`] runs the pixels tile by tile, each pixel folding its own frames into
//! f64 Welford accumulators ([`PixelFrames`]), and assembles one [`RenderOutput`]. The oracle,
//! the ray-tracing estimators ([`crate::trace`]) and the rasterizers ([`crate::raster`]) differ
//! only in the function that makes a pixel's sample; the images of the GPU backend have the
//! same type.

use crate::camera::Camera;
use crate::image::Image;
use crate::rng::{RayRng, RngScheme, frame_key};
use crate::settings::RenderError;
use crate::stats::Welford;
use crate::tile::{map_tiles, tile_coords};
use glam::{DVec3, Vec2, Vec3};

/// Receives the number of pixels finished since its last call (a progress bar, or `&|_| {}`).
pub type Progress<'a> = &'a (dyn Fn(u64) + Sync);

/// How the running mean of the frames is stored between frames (vk_gaussian_splatting keeps it
/// in its output image: FP16 by default, with the advice to switch to FP32 past 150–200
/// frames, and UINT8 for speed without accumulation). The per-frame variance is kept in full
/// precision whatever the format: it is the project's statistic, not the display's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum AccumulationFormat {
    /// Full precision: f64 on the CPU, f32 on the GPU (the default, the reference).
    #[default]
    F32,
    /// The mean rounded to half precision after every frame (WGSL `pack2x16float`).
    F16,
    /// The mean rounded to 8-bit unorm after every frame, clamped to [0, 1] (`pack4x8unorm`).
    Unorm8,
}

impl AccumulationFormat {
    /// Every format, in the order the front ends list them.
    pub const ALL: [AccumulationFormat; 3] =
        [AccumulationFormat::F32, AccumulationFormat::F16, AccumulationFormat::Unorm8];

    /// Its name on the command line and in the viewer.
    pub fn name(self) -> &'static str {
        match self {
            AccumulationFormat::F32 => "f32",
            AccumulationFormat::F16 => "f16",
            AccumulationFormat::Unorm8 => "unorm8",
        }
    }

    /// One line on what it does (the CLI's help).
    pub fn describe(self) -> &'static str {
        match self {
            AccumulationFormat::F32 => "full precision (f64 on the CPU, f32 on the GPU)",
            AccumulationFormat::F16 => "half precision, vk_gaussian_splatting's default: drifts past ~150–200 frames",
            AccumulationFormat::Unorm8 => "8-bit unorm, clamped to [0, 1]: stalls once 1/(n + 1) of a step rounds away",
        }
    }

    /// Its code in the kernels (`ACCUMULATION_*` in `common.wgsl`).
    pub fn code(self) -> u32 {
        self as u32
    }

    /// `v` as this format stores it: itself (F32), rounded to the nearest f16, or to the
    /// nearest of 256 levels in [0, 1].
    pub fn store(self, v: f64) -> f64 {
        match self {
            AccumulationFormat::F32 => v,
            AccumulationFormat::F16 => f64::from(half::f16::from_f64(v)),
            AccumulationFormat::Unorm8 => (v.clamp(0.0, 1.0) * 255.0 + 0.5).floor() / 255.0,
        }
    }
}

/// How frames are drawn: how many, from which seed, with which generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frames {
    /// Frames (samples per pixel) averaged.
    pub count: u32,
    /// Index of the first frame: frames `first..first + count` of the run seeded by `seed`
    /// are rendered, each with the decisions, pixel sample and lens sample of that frame of
    /// the whole run, so that renders of disjoint ranges (a job array's shares, Ray tasks)
    /// merge ([`Accumulation::merge`]) into the render of their union. 0 by default.
    pub first: u32,
    /// Seed of the random stream; two seeds give independent runs.
    pub seed: u32,
    /// Generator of the decisions.
    pub rng: RngScheme,
    /// Test hook of the power study (docs/power.md): every uniform number of a stochastic
    /// decision is drawn as u − `u_shift`, so a particle is accepted when u < α + `u_shift`
    /// (a decision rule off by that much). Zero, the default, in every real render; the
    /// statistical suites set it to show that they catch a small error in a decision.
    pub u_shift: f32,
    /// How the running mean is stored between frames.
    pub accumulation: AccumulationFormat,
}

impl Default for Frames {
    fn default() -> Self {
        Self { count: 1, first: 0, seed: 0, rng: RngScheme::Hash, u_shift: 0.0, accumulation: AccumulationFormat::F32 }
    }
}

impl Frames {
    /// The frame keys of a render: `count` frames for a stochastic method, one otherwise (a
    /// deterministic method gives the same sample every frame).
    pub fn keys(&self, stochastic: bool) -> Result<Vec<u32>, RenderError> {
        if self.count == 0 {
            return Err(RenderError::Settings("at least one frame is needed".into()));
        }
        if self.u_shift.is_nan() || self.u_shift.abs() >= 1.0 {
            return Err(RenderError::Settings(format!("u_shift {} is not in (−1, 1)", self.u_shift)));
        }
        if self.first.checked_add(self.count).is_none() {
            let (first, count) = (self.first, self.count);
            return Err(RenderError::Settings(format!(
                "{count} frames from frame {first} run past the last frame index {}",
                u32::MAX
            )));
        }
        let count = if stochastic { self.count } else { 1 };
        Ok((self.first..self.first + count).map(|f| frame_key(self.seed, f)).collect())
    }

    /// The index in the whole run of the `f`-th frame rendered.
    pub fn index(&self, f: u32) -> u32 {
        self.first + f
    }
}

/// A render's statistics over a range of frames of a run: what one share of the run (a job
/// array's task, a Ray task) contributes, and what merging disjoint shares gives, per pixel and
/// channel the mean, the per-frame variance and the frame count ([`Welford::merge`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulation {
    /// Index of the first frame in the run.
    pub first: u32,
    /// Frames averaged (one for a deterministic render, whatever was asked).
    pub count: u32,
    /// Mean radiance (RGB).
    pub mean: Image,
    /// Per-frame variance of the radiance (RGB, unbiased; 0 with one frame).
    pub variance: Image,
    /// Mean coverage 1 − T.
    pub alpha: Image,
}

impl Accumulation {
    /// The statistics of `out`, a render of `frames` that averaged `count` of them.
    pub fn of(out: &RenderOutput, frames: &Frames, count: u32) -> Self {
        let (mean, variance, alpha) = (out.mean.clone(), out.variance.clone(), out.alpha.clone());
        Self { first: frames.first, count, mean, variance, alpha }
    }

    /// The frames it holds, `first..first + count`.
    pub fn range(&self) -> std::ops::Range<u64> {
        u64::from(self.first)..u64::from(self.first) + u64::from(self.count)
    }

    /// Merge shares of one run whose frames follow on (0..4, 4..10, …) into the statistics of
    /// their union, in f64 and in order of their first frames, so that the result does not
    /// depend on the order the shares are given in. Refuses shares of different sizes,
    /// overlapping ranges (their frames would count twice) and gaps.
    pub fn merge(parts: &[Accumulation]) -> Result<Accumulation, RenderError> {
        let mut order: Vec<&Accumulation> = parts.iter().collect();
        order.sort_by_key(|p| p.first);
        let Some(head) = order.first() else {
            return Err(RenderError::Settings("no accumulation to merge".into()));
        };
        let size = |p: &Accumulation| (p.mean.width(), p.mean.height());
        for pair in order.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            if size(a) != size(b) {
                let ((w, h), (w2, h2)) = (size(a), size(b));
                return Err(RenderError::Settings(format!(
                    "the shares are {w}×{h} and {w2}×{h2}: one run has one size"
                )));
            }
            let (ra, rb) = (a.range(), b.range());
            if ra.end > rb.start {
                return Err(RenderError::Settings(format!(
                    "the shares' frames overlap: {}..{} and {}..{} (each frame may count once)",
                    ra.start, ra.end, rb.start, rb.end
                )));
            }
            if ra.end < rb.start {
                return Err(RenderError::Settings(format!(
                    "the shares leave frames {}..{} out: merge shares whose frames follow on (the merge is then \
                     frames {}.. of the run)",
                    ra.end, rb.start, head.first
                )));
            }
        }
        let pixels = head.alpha.data().len();
        let mut merged = head.mean.clone();
        let mut variance = head.variance.clone();
        let mut alpha = head.alpha.clone();
        for i in 0..pixels {
            let stats = |c: usize| {
                let at = 3 * i + c;
                let of = |p: &&Accumulation| {
                    Welford::of(p.count.into(), p.mean.data()[at].into(), p.variance.data()[at].into())
                };
                order.iter().map(of).fold(Welford::default(), Welford::merge)
            };
            for c in 0..3 {
                let w = stats(c);
                merged.data_mut()[3 * i + c] = w.mean as f32;
                variance.data_mut()[3 * i + c] = w.variance() as f32;
            }
            let coverage = order.iter().map(|p| Welford::of(p.count.into(), p.alpha.data()[i].into(), 0.0));
            alpha.data_mut()[i] = coverage.fold(Welford::default(), Welford::merge).mean as f32;
        }
        let count = order.iter().map(|p| u64::from(p.count)).sum::<u64>();
        let count = u32::try_from(count).map_err(|_| RenderError::Settings(format!("{count} frames in all")))?;
        Ok(Accumulation { first: head.first, count, mean: merged, variance, alpha })
    }
}

/// The source of the stochastic decisions of one ray or pixel, and the rules that turn them
/// into outcomes.
///
/// Every estimator decides through [`Decide::accepts`] and [`Decide::accepts_pass`]; the
/// renderers use the provided rules, and the enumeration tests replace them with wrong ones
/// to show that they would be caught.
pub trait Decide {
    /// Whether [`Decide::particle`] reads the hit position.
    fn needs_position(&self) -> bool;
    /// u ∈ [0, 1) of particle `id` in sample `slot`.
    fn particle(&self, id: u32, slot: u32, hit: Vec3) -> f32;
    /// The draws of every particle in the slots `first_slot..first_slot + n` of one traversal,
    /// as a function `(id, hit, out)` prepared once before it: [`Decide::particle`] slot by slot,
    /// unless a generator can share work across the particles.
    fn slot_draws(&self, first_slot: u32, n: usize) -> impl Fn(u32, Vec3, &mut [f32]) {
        move |id, hit, out: &mut [f32]| {
            for (s, u) in (first_slot..).zip(&mut out[..n]) {
                *u = self.particle(id, s, hit);
            }
        }
    }
    /// u ∈ [0, 1) of pass `pass`.
    fn pass(&self, pass: u32) -> f32;
    /// A point of [0, 1)² choosing where on area light `light` the sample of slot `slot` is lit
    /// from (soft shadows); the emitter's centre unless a generator overrides it.
    fn light_sample(&self, _light: u32, _slot: u32) -> Vec2 {
        Vec2::splat(0.5)
    }
    /// Russian roulette (Sun et al. 2025, Algorithm 1, line 6): particle `id` with alpha α is
    /// accepted when u < α, so with probability α.
    fn accepts(&self, _id: u32, u: f32, alpha: f32) -> bool {
        u < alpha
    }
    /// The stochastic pass (vk_gaussian_splatting): a pass of opacity O = 1 − T_pass is
    /// accepted when u < O.
    fn accepts_pass(&self, u: f64, opacity: f64) -> bool {
        u < opacity
    }
    /// Laine & Karras 2011 §3: a fragment covers a sample when α exceeds the sample's
    /// reference value `reference` (CalcAlphaRef, Figure 7 line 13).
    fn covers(&self, alpha: f32, reference: f32) -> bool {
        alpha > reference
    }
}

impl Decide for RayRng {
    fn needs_position(&self) -> bool {
        RayRng::needs_position(self)
    }
    #[inline(always)]
    fn particle(&self, id: u32, slot: u32, hit: Vec3) -> f32 {
        RayRng::particle(self, id, slot, hit)
    }
    #[inline(always)]
    fn slot_draws(&self, first_slot: u32, n: usize) -> impl Fn(u32, Vec3, &mut [f32]) {
        let draws = RayRng::slot_draws(self, first_slot, n);
        move |id, hit, out: &mut [f32]| draws.draw(id, hit, out)
    }
    fn pass(&self, pass: u32) -> f32 {
        RayRng::pass(self, pass)
    }
    fn light_sample(&self, light: u32, slot: u32) -> Vec2 {
        RayRng::light_sample(self, light, slot)
    }
    fn covers(&self, alpha: f32, reference: f32) -> bool {
        alpha > reference - self.u_shift
    }
}

/// The total depth order of the whole crate: (t, id) strictly before (other_t, other_id) —
/// distance first, ties by particle id — so no result depends on traversal or draw order.
#[inline]
pub fn depth_before(t: f32, id: u32, other_t: f32, other_id: u32) -> bool {
    t < other_t || (t == other_t && id < other_id)
}

/// What one frame of one method yields at one pixel (or for one ray).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Radiance over the background.
    pub color: DVec3,
    /// Coverage: 1 − T for deterministic methods, the fraction of accepting samples for
    /// stochastic ones.
    pub alpha: f64,
    /// Picked depth (iso-opacity for sorted methods, the accepted hit for stochastic ones).
    pub depth: Option<f32>,
    /// Unit normal of the pick (zero when nothing is hit).
    pub normal: Vec3,
    /// Scene index of the particle that set the depth, where the method tracks it.
    pub picked: Option<u32>,
}

impl Sample {
    /// Nothing hit: the background, no coverage.
    pub fn background(background: Vec3) -> Self {
        Self { color: background.as_dvec3(), alpha: 0.0, depth: None, normal: Vec3::ZERO, picked: None }
    }
}

/// The images of a render, whatever the method and backend.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOutput {
    /// Mean radiance over the frames (RGB): L + T × background (Eq. 3) in expectation.
    pub mean: Image,
    /// Per-frame variance of the radiance (RGB, unbiased; 0 with one frame).
    pub variance: Image,
    /// Mean coverage 1 − T.
    pub alpha: Image,
    /// Depth of frame 0 (ray distance t; NaN where none): picks are never averaged (vk_gaussian_splatting Lighting
    /// §2.3).
    pub depth: Image,
    /// Unit normal of frame 0, world space; zero where nothing is hit.
    pub normal: Image,
    /// Scene index of the particle that set frame 0's depth, per pixel (row-major); `None`
    /// where nothing was picked or the method does not track picks.
    pub picked: Vec<Option<u32>>,
}

impl RenderOutput {
    /// Colour-only images (depth NaN, normal zero, no picks), for backends that produce no
    /// picks.
    pub fn colour_only(mean: Image, variance: Image, alpha: Image) -> Self {
        let (w, h) = (mean.width(), mean.height());
        Self {
            mean,
            variance,
            alpha,
            depth: Image::filled(w, h, 1, f32::NAN),
            normal: Image::filled(w, h, 3, 0.0),
            picked: vec![None; w as usize * h as usize],
        }
    }
}

/// The frames of one pixel: f64 Welford mean and variance of colour and coverage, the mean
/// stored in its [`AccumulationFormat`] after every frame, and the depth, normal and pick of
/// the first frame (picks are never averaged).
#[derive(Default)]
pub struct PixelFrames {
    acc: [Welford; 4],
    first: Option<Sample>,
    format: AccumulationFormat,
}

impl PixelFrames {
    /// No frames yet; the mean will be stored in `format`.
    pub fn new(format: AccumulationFormat) -> Self {
        Self { format, ..Self::default() }
    }

    /// Fold the sample of every frame key: `sample(key)` is one frame of the pixel.
    pub fn over(keys: &[u32], format: AccumulationFormat, mut sample: impl FnMut(u32) -> Sample) -> Self {
        let mut pixel = Self::new(format);
        for &key in keys {
            pixel.push(&sample(key));
        }
        pixel
    }

    /// Add one frame's sample.
    pub fn push(&mut self, s: &Sample) {
        for (a, v) in self.acc.iter_mut().zip([s.color.x, s.color.y, s.color.z, s.alpha]) {
            push_stored(a, v, self.format);
        }
        self.first.get_or_insert(*s);
    }
}

/// Welford's step, then the mean as `format` stores it (the M2 update reads the stored mean,
/// as a GPU's would).
fn push_stored(a: &mut Welford, v: f64, format: AccumulationFormat) {
    a.push(v);
    a.mean = format.store(a.mean);
}

/// A pixel's frames once folded: the f32 values the output images hold. A tile keeps these,
/// not its [`PixelFrames`] (f64 accumulators and a whole first [`Sample`], three times the
/// size), so that a render's peak memory stays near twice its output images.
#[derive(Clone, Copy)]
struct Finished {
    mean: [f32; 4],
    variance: [f32; 3],
    depth: f32,
    normal: [f32; 3],
    picked: Option<u32>,
}

impl From<PixelFrames> for Finished {
    fn from(p: PixelFrames) -> Self {
        let first = p.first.unwrap_or(Sample::background(Vec3::ZERO));
        let var = p.acc.map(|a| a.variance() as f32);
        Self {
            mean: p.acc.map(|a| a.mean as f32),
            variance: [var[0], var[1], var[2]],
            depth: first.depth.unwrap_or(f32::NAN),
            normal: first.normal.to_array(),
            picked: first.picked,
        }
    }
}

/// Bytes a pixel of a CPU render holds at its peak: its finished values in its tile, and the
/// same values again in the [`RenderOutput`] they are copied into (its images and picks hold
/// exactly the fields of a tile's finished pixel). Hosts use it to refuse a render that cannot
/// fit before starting it.
pub const BYTES_PER_PIXEL: u64 = 2 * std::mem::size_of::<Finished>() as u64;

/// The one frame loop: `pixel(state, x, y)` folds the frames of pixel (x, y), with `state` made
/// once per tile by `tile_state(tile)` (scratch buffers, per-tile candidate lists). Tiles run in
/// parallel; each pixel loops over its own frames, so the result does not depend on the thread
/// count. `progress` receives finished pixel counts.
pub fn render_tiles<S>(
    camera: &Camera,
    progress: Progress,
    tile_state: impl Fn(u32) -> S + Sync + Send,
    pixel: impl Fn(&mut S, u32, u32) -> PixelFrames + Sync + Send,
) -> RenderOutput {
    let tiles = map_tiles(camera, |tile| {
        let mut state = tile_state(tile);
        let out: Vec<Finished> =
            tile_coords(camera, tile).map(|(x, y)| Finished::from(pixel(&mut state, x, y))).collect();
        progress(out.len() as u64);
        out
    });
    assemble(camera, &tiles)
}

/// The frame loop of a camera that moves from frame to frame where a renderer projects
/// through it (splatting, the oracle's tile culling: [`crate::camera_sampling`]): `frame(f,
/// key)` renders frame f, of key `key`, as a whole one-frame image through that frame's camera,
/// and the images are folded pixel by pixel into f64 Welford accumulators stored in `format`,
/// as [`PixelFrames`] folds a pixel's frames (the depth, normal and picks are frame 0's). Each frame is the same
/// pure function of (pixel, key) as in the pixel-major loop, so the image does not depend on
/// the thread count either. `progress` receives the pixels' share of each finished frame.
pub fn fold_frames<E: From<RenderError>>(
    camera: &Camera,
    keys: &[u32],
    format: AccumulationFormat,
    progress: Progress,
    mut frame: impl FnMut(u32, u32) -> Result<RenderOutput, E>,
) -> Result<RenderOutput, E> {
    let pixels = u64::from(camera.width) * u64::from(camera.height);
    let mut acc = vec![[Welford::default(); 4]; pixels as usize];
    let mut first = None;
    for (f, &key) in keys.iter().enumerate() {
        let out = frame(f as u32, key)?;
        for (i, a) in acc.iter_mut().enumerate() {
            let c = &out.mean.data()[3 * i..3 * i + 3];
            for (w, v) in a.iter_mut().zip([c[0], c[1], c[2], out.alpha.data()[i]]) {
                push_stored(w, f64::from(v), format);
            }
        }
        first.get_or_insert(out);
        let done = |f: u64| pixels * f / keys.len() as u64;
        progress(done(f as u64 + 1) - done(f as u64));
    }
    let mut out = first.ok_or_else(|| RenderError::Settings("at least one frame is needed".into()))?;
    for (i, a) in acc.iter().enumerate() {
        for (c, w) in a[..3].iter().enumerate() {
            out.mean.data_mut()[3 * i + c] = w.mean as f32;
            out.variance.data_mut()[3 * i + c] = w.variance() as f32;
        }
        out.alpha.data_mut()[i] = a[3].mean as f32;
    }
    Ok(out)
}

/// Scatter the tiles' pixels into the output images.
fn assemble(camera: &Camera, tiles: &[Vec<Finished>]) -> RenderOutput {
    let (w, h) = (camera.width, camera.height);
    let image = |c| Image::filled(w, h, c, 0.0);
    let mut out = RenderOutput {
        mean: image(3),
        variance: image(3),
        alpha: image(1),
        depth: image(1),
        normal: image(3),
        picked: vec![None; (w * h) as usize],
    };
    for (tile, pixels) in tiles.iter().enumerate() {
        for ((x, y), p) in tile_coords(camera, tile as u32).zip(pixels) {
            out.mean.pixel_mut(x, y).copy_from_slice(&p.mean[..3]);
            out.variance.pixel_mut(x, y).copy_from_slice(&p.variance);
            out.alpha.pixel_mut(x, y)[0] = p.mean[3];
            out.depth.pixel_mut(x, y)[0] = p.depth;
            out.normal.pixel_mut(x, y).copy_from_slice(&p.normal);
            out.picked[(y * w + x) as usize] = p.picked;
        }
    }
    out
}
