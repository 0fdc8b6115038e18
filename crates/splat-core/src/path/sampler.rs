//! The random numbers of one path: every number the path draws (pixel position, lens point,
//! each Gaussian's and transparent triangle's acceptance, each BSDF and light sample, Russian
//! roulette) is a pure function of (pixel, sample index, dimension), so one sample index drives
//! the whole path and nothing depends on thread or traversal order.
//!
//! Two generators:
//!
//! - [`SamplerKind::Sobol`]: Owen-scrambled Sobol points (Burley 2020, "Practical Hash-based
//!   Owen Scrambling", through the `sobol_burley` crate), one sequence per pixel, sample index =
//!   frame. The path's dimensions are assigned per bounce ([`Dim`]); a Gaussian's acceptance is
//!   dimension 0 of a sequence seeded by (pixel, particle, decision), so that every particle's
//!   decisions over the frames are themselves a stratified sequence (Sun et al. 2025, §5: "global
//!   stratified sampling across the entire scene becomes crucial").
//! - [`SamplerKind::Hash`]: the counter-based hash of the rest of the project (xxhash32 and PCG,
//!   [`crate::rng`]), independent from frame to frame.

use crate::frame::Decide;
use crate::rng::{pcg, unit_f32, xxhash32};
use glam::{Vec2, Vec3};

/// Which generator draws a path's numbers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SamplerKind {
    /// Owen-scrambled Sobol, one sequence per pixel (the default).
    #[default]
    Sobol,
    /// The counter-based hash: independent frames.
    Hash,
}

/// The dimensions of a path: the camera's, then [`Dim::PER_BOUNCE`] per bounce.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dim {
    /// Sub-pixel position (two dimensions).
    Pixel,
    /// Lens position (two).
    Lens,
    /// Lobe choice at bounce b.
    Lobe(u32),
    /// BSDF direction at bounce b (two).
    Direction(u32),
    /// Emitter choice at bounce b.
    LightPick(u32),
    /// Point on the chosen emitter at bounce b (two).
    LightPoint(u32),
    /// Russian roulette at bounce b.
    Roulette(u32),
}

impl Dim {
    /// Dimensions a bounce uses.
    pub const PER_BOUNCE: u32 = 8;

    /// The first (or only) dimension index.
    pub fn index(self) -> u32 {
        let bounce = |b: u32, k: u32| 4 + Self::PER_BOUNCE * b + k;
        match self {
            Dim::Pixel => 0,
            Dim::Lens => 2,
            Dim::Lobe(b) => bounce(b, 0),
            Dim::Direction(b) => bounce(b, 1),
            Dim::LightPick(b) => bounce(b, 3),
            Dim::LightPoint(b) => bounce(b, 4),
            Dim::Roulette(b) => bounce(b, 6),
        }
    }
}

/// Particle ids above the scene's: the seeds of the path's own dimensions …
pub const PATH_DIM_ID: u32 = u32::MAX - 7;
/// … and of light j's samples (`LIGHT_STREAM − j`).
pub const LIGHT_STREAM: u32 = u32::MAX - 16;
/// Dimensions of one Sobol sequence; further dimensions continue with a fresh seed.
pub const SOBOL_DIMENSIONS: u32 = sobol_burley::NUM_DIMENSIONS;

/// The direction numbers behind [`SamplerKind::Sobol`], bit-reversed, 16 per dimension (the
/// sequence is 2¹⁶ points long): entry 16 d + k is what bit 31 − k of a reversed sample index
/// contributes to dimension d (`sobol_burley::parts::sobol_rev`). What a GPU uploads to draw
/// the same points.
pub fn sobol_directions() -> Vec<u32> {
    (0..SOBOL_DIMENSIONS)
        .flat_map(|d| (0..16).map(move |k| sobol_burley::parts::sobol_rev(1u32 << (31 - k), d)))
        .collect()
}

/// The numbers of one pixel's sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSampler {
    kind: SamplerKind,
    /// Sobol: the pixel's sequence seed (the same every frame). Hash: the pixel and frame.
    seed: u32,
    /// Sample index within the pixel's sequence (the frame).
    index: u32,
    /// Subtracted from every acceptance draw ([`crate::Frames::u_shift`], a test hook).
    u_shift: f32,
}

impl PathSampler {
    /// Sample `index` of pixel (x, y) in the run seeded by `seed`.
    pub fn new(kind: SamplerKind, x: u32, y: u32, seed: u32, index: u32) -> Self {
        let seed = match kind {
            SamplerKind::Sobol => xxhash32([x, y, seed ^ 0x50B0_1000]),
            SamplerKind::Hash => xxhash32([x, y, crate::rng::frame_key(seed, index)]),
        };
        Self { kind, seed, index, u_shift: 0.0 }
    }

    /// The same numbers with every acceptance draw lowered by `u_shift`.
    pub fn shifted(self, u_shift: f32) -> Self {
        Self { u_shift, ..self }
    }

    /// Dimension `dim` of this sample, in [0, 1).
    pub fn get(&self, dim: u32) -> f32 {
        self.draw(dim, PATH_DIM_ID)
    }

    /// Dimensions `dim` and `dim + 1`.
    pub fn get2(&self, dim: u32) -> Vec2 {
        Vec2::new(self.get(dim), self.get(dim + 1))
    }

    /// One dimension of the stream `stream` (a particle id or [`PATH_DIM_ID`]).
    fn draw(&self, dim: u32, stream: u32) -> f32 {
        match self.kind {
            SamplerKind::Hash => unit_f32(pcg(xxhash32([self.seed, stream, dim]))),
            SamplerKind::Sobol => {
                // 2¹⁶ points and 256 dimensions per sequence; beyond either, a fresh seed
                // continues it (Burley's padding).
                let n = sobol_burley::NUM_DIMENSIONS;
                let (block, d) = (dim / n, dim % n);
                let seed = xxhash32([self.seed, stream, block | ((self.index >> 16) << 8)]);
                sobol_burley::sample(self.index & 0xFFFF, d, seed)
            }
        }
    }

    /// The acceptance draw of the transparent triangle in place `order` of the meshes' order
    /// on the segment after bounce `bounce` ([`surface_decision`]), lowered by the shift as every
    /// acceptance draw is.
    pub fn surface(&self, order: u32, bounce: u32) -> f32 {
        self.particle(order, surface_decision(bounce)) - self.u_shift
    }

    /// The acceptance draw of particle `id` in decision `decision` (of [`decision`]).
    fn particle(&self, id: u32, decision: u32) -> f32 {
        match self.kind {
            SamplerKind::Hash => self.draw(decision, id),
            // One 1-D sequence per (particle, decision): dimension 0 of its own seed.
            SamplerKind::Sobol => {
                let seed = xxhash32([self.seed, id, decision | ((self.index >> 16) << 24)]);
                sobol_burley::sample(self.index & 0xFFFF, 0, seed)
            }
        }
    }
}

/// The decision number of slot `slot` of the segment after bounce `bounce` (slots are the
/// instantiations of `stochastic-n`); shadow rays toward light j get `shadow_decision`.
pub fn decision(bounce: u32, slot: u32) -> u32 {
    (bounce << 12) | slot
}

/// The decision number of the shadow ray from the vertex of bounce `bounce` toward light
/// `light` (the emissive meshes' sample is light [`crate::lighting::MAX_LIGHTS`]).
pub fn shadow_decision(bounce: u32, light: u32) -> u32 {
    0x0080_0000 | (bounce << 12) | light
}

/// The decision number of the transparent triangles the segment after bounce `bounce` crosses
/// (each keyed by its place in the meshes' order, as a Gaussian by its id).
pub fn surface_decision(bounce: u32) -> u32 {
    0x0040_0000 | (bounce << 12)
}

/// The Gaussian decisions of a path as a [`Decide`]: slot s is decision s, light samples of the
/// world's lights are light-point dimensions seeded by the light.
#[derive(Clone, Copy, Debug)]
pub struct PathDecide<'s> {
    /// The pixel's numbers.
    pub sampler: &'s PathSampler,
    /// The bounce whose light samples `light_sample` draws.
    pub bounce: u32,
}

impl Decide for PathDecide<'_> {
    fn needs_position(&self) -> bool {
        false
    }
    #[inline(always)]
    fn particle(&self, id: u32, slot: u32, _hit: Vec3) -> f32 {
        self.sampler.particle(id, slot) - self.sampler.u_shift
    }
    fn pass(&self, pass: u32) -> f32 {
        self.sampler.particle(crate::rng::PASS_ID, pass) - self.sampler.u_shift
    }
    fn light_sample(&self, light: u32, _slot: u32) -> Vec2 {
        let dim = Dim::LightPoint(self.bounce).index();
        let stream = LIGHT_STREAM - light;
        Vec2::new(self.sampler.draw(dim, stream), self.sampler.draw(dim + 1, stream))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sobol_points_of_a_pixel_are_stratified_and_pixels_differ() {
        // 2ⁿ consecutive points of one pixel put exactly one in each of 2ⁿ equal intervals.
        let a: Vec<f32> = (0..64).map(|i| PathSampler::new(SamplerKind::Sobol, 3, 4, 9, i).get(5)).collect();
        let mut cells = [0u32; 64];
        a.iter().for_each(|&u| cells[(u * 64.0) as usize] += 1);
        assert!(cells.iter().all(|&c| c == 1), "{cells:?}");
        let b = PathSampler::new(SamplerKind::Sobol, 4, 4, 9, 0).get(5);
        assert_ne!(a[0], b);
        // Each particle's acceptance draws are a stratified sequence of their own.
        let s: Vec<f32> =
            (0..32).map(|i| PathSampler::new(SamplerKind::Sobol, 3, 4, 9, i).particle(77, decision(1, 0))).collect();
        let mut cells = [0u32; 32];
        s.iter().for_each(|&u| cells[(u * 32.0) as usize] += 1);
        assert!(cells.iter().all(|&c| c == 1), "{cells:?}");
    }

    #[test]
    fn the_direction_table_rebuilds_the_sequence() {
        // sobol_rev is linear over XOR in the index bits: the table reproduces it.
        let table = sobol_directions();
        for d in [0, 1, 5, 77, 255] {
            for index in [0u32, 1, 2, 3, 1000, 65_535] {
                let rev = index.reverse_bits();
                let by_table =
                    (0..16).filter(|k| rev & (1u32 << (31 - k)) != 0).fold(0, |s, k| s ^ table[(16 * d + k) as usize]);
                assert_eq!(by_table, sobol_burley::parts::sobol_rev(rev, d));
            }
        }
    }

    #[test]
    fn dimensions_do_not_overlap() {
        let dims = [Dim::Lobe(0), Dim::Direction(0), Dim::LightPick(0), Dim::LightPoint(0), Dim::Roulette(0)];
        let mut used: Vec<u32> = vec![0, 1, 2, 3];
        for d in dims {
            let width = if matches!(d, Dim::Direction(_) | Dim::LightPoint(_)) { 2 } else { 1 };
            used.extend(d.index()..d.index() + width);
        }
        let mut sorted = used.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), used.len());
        assert!(used.iter().all(|&d| d < Dim::Lobe(1).index()));
    }
}
