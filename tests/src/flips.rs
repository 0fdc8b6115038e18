//! How close a frame's decisions came to flipping: for CPU = GPU comparisons, where a pixel
//! may differ between backends only if one of its decisions had u within rounding of its
//! threshold.

use glam::Vec3;
use splat_core::frame::Decide;
use splat_core::raster::{RasterMethod, Rasterizer};
use splat_core::rng::{RayRng, RngScheme, frame_key};
use splat_core::trace::{Method, TraceScene};
use splat_core::{Camera, Frames};
use std::cell::Cell;

/// Largest difference of one frame between the backends for the same decisions: f32
/// compositing on the GPU against f64 on the CPU.
pub const FLOAT_TOLERANCE: f32 = 1e-4;
/// A decision may flip between the backends only where u lies this close to its threshold
/// (the backends' alphas differ by f32 rounding of the same formula).
pub const FLIP_GAP: f64 = 1e-5;

/// Two fragments whose centre depths lie this close (relative, about 8 f32 ulps) may pass each
/// other's depth test in either order on the two backends: each scales the depth by its own
/// f32 |d| of the sample's ray.
pub const DEPTH_TIE: f64 = 1e-6;

/// A decision source that records the smallest |u − threshold| of the comparisons it
/// made (particles against α, passes against O, references against α).
pub struct Nearest<D> {
    inner: D,
    gap: Cell<f64>,
}

impl<D: Decide> Nearest<D> {
    /// Wrap `inner`; the gap starts at infinity (no decision made).
    pub fn new(inner: D) -> Self {
        Self { inner, gap: Cell::new(f64::INFINITY) }
    }

    /// The smallest |u − threshold| so far.
    pub fn gap(&self) -> f64 {
        self.gap.get()
    }

    fn saw(&self, u: f64, threshold: f64) {
        self.gap.set(self.gap.get().min((u - threshold).abs()));
    }
}

impl<D: Decide> Decide for Nearest<D> {
    fn needs_position(&self) -> bool {
        self.inner.needs_position()
    }
    fn particle(&self, id: u32, slot: u32, hit: Vec3) -> f32 {
        self.inner.particle(id, slot, hit)
    }
    fn pass(&self, pass: u32) -> f32 {
        self.inner.pass(pass)
    }
    fn light_sample(&self, light: u32, slot: u32) -> glam::Vec2 {
        self.inner.light_sample(light, slot)
    }
    fn accepts(&self, id: u32, u: f32, alpha: f32) -> bool {
        self.saw(f64::from(u), f64::from(alpha));
        self.inner.accepts(id, u, alpha)
    }
    fn accepts_pass(&self, u: f64, opacity: f64) -> bool {
        self.saw(u, opacity);
        self.inner.accepts_pass(u, opacity)
    }
    fn covers(&self, alpha: f32, reference: f32) -> bool {
        self.saw(f64::from(reference), f64::from(alpha));
        self.inner.covers(alpha, reference)
    }
}

/// The smallest |u − threshold| among the decisions of the frames of `frames` at pixel
/// (x, y) of the CPU ray tracer.
pub fn trace_gap(trace: &TraceScene, camera: &Camera, method: &Method, frames: &Frames, x: u32, y: u32) -> f64 {
    let ray = trace.clip(camera.pixel_ray(x, y));
    (0..frames.count)
        .map(|f| {
            let rng = RayRng::new(x, y, frame_key(frames.seed, f), frames.rng).shifted(frames.u_shift);
            let nearest = Nearest::new(rng);
            trace.sample(method, &ray, &nearest);
            nearest.gap()
        })
        .fold(f64::INFINITY, f64::min)
}

/// The same for the CPU rasterizer.
pub fn raster_gap(r: &Rasterizer, method: &RasterMethod, frames: &Frames, x: u32, y: u32) -> f64 {
    (0..frames.count)
        .map(|f| raster_frame_gap(r, method, frame_key(frames.seed, f), frames.u_shift, x, y))
        .fold(f64::INFINITY, f64::min)
}

/// The smallest |u − threshold| among the decisions at pixel (x, y) of the one frame of key
/// `key` (decisions shifted by `u_shift`) of the CPU rasterizer `r`: for a camera drawn per
/// frame, `r` is the rasterizer of that frame's camera.
pub fn raster_frame_gap(r: &Rasterizer, method: &RasterMethod, key: u32, u_shift: f32, x: u32, y: u32) -> f64 {
    let px = r.pixel(x, y);
    let mut fragments = r.fragments(&px);
    r.shuffle(&mut fragments, key);
    let nearest = Nearest::new(RayRng::new(x, y, key, RngScheme::Hash).shifted(u_shift));
    r.draw(method, &px, &fragments, &nearest, key);
    nearest.gap()
}

/// The smallest relative gap between two depths that Laine & Karras's line 9 (the survivors
/// sorted by the depth each sample holds) may compare at pixel (x, y): a sample's opaque mesh
/// against another's, or against a fragment's depth at any sample. Below [`DEPTH_TIE`] the
/// backends' f32 ray casts may order the samples differently (the same survivors, other
/// reference values).
pub fn raster_stored_depth_gap(r: &Rasterizer, x: u32, y: u32) -> f64 {
    let px = r.pixel(x, y);
    let meshes: Vec<f64> = (0..px.len()).filter_map(|s| px.surface(s)).map(|h| f64::from(h.t)).collect();
    let fragments = r.fragments(&px);
    let depths: Vec<f64> = fragments
        .iter()
        .flat_map(|f| (0..px.len()).filter(|s| f.covered >> s & 1 == 1).map(|s| f64::from(r.depth(&px, f, s))))
        .collect();
    let gap = |a: f64, b: f64| (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE);
    let mut least = f64::INFINITY;
    for (i, &m) in meshes.iter().enumerate() {
        for &other in meshes[i + 1..].iter().chain(&depths) {
            least = least.min(gap(m, other));
        }
    }
    least
}

/// The smallest relative gap between the depths of two fragments (splats or transparent
/// triangles) at one sample of pixel (x, y): below [`DEPTH_TIE`] their depth order may differ
/// between the backends (at centre depth a splat's gaps are those of the centre depths).
pub fn raster_depth_gap(r: &Rasterizer, x: u32, y: u32) -> f64 {
    let px = r.pixel(x, y);
    let fragments = r.fragments(&px);
    (0..64)
        .map(|s| {
            let covering = fragments.iter().filter(|f| f.covered >> s & 1 == 1);
            let mut depths: Vec<f64> = covering.map(|f| f64::from(r.depth(&px, f, s))).collect();
            depths.sort_by(f64::total_cmp);
            depths.windows(2).map(|w| (w[1] - w[0]) / w[0].abs().max(f64::MIN_POSITIVE)).fold(f64::INFINITY, f64::min)
        })
        .fold(f64::INFINITY, f64::min)
}
