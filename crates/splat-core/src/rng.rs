//! Deterministic random numbers for generating scenes.

/// SplitMix64 (Steele, Lea & Flood 2014): a tiny, fast, well-mixed sequential generator.
/// Used to generate fixtures and the demo scene reproducibly on every platform.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform f32 in [0, 1) from the top 24 bits (exactly representable, never 1.0).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform f32 in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_in_range_and_reproducible() {
        let mut a = SplitMix64::new(7);
        let mut b = SplitMix64::new(7);
        for _ in 0..10_000 {
            let x = a.next_f32();
            assert!((0.0..1.0).contains(&x));
            assert_eq!(x, b.next_f32());
        }
        let mean: f32 = (0..100_000).map(|_| a.next_f32()).sum::<f32>() / 100_000.0;
        assert!((mean - 0.5).abs() < 0.01);
    }
}

const XX_P2: u32 = 2_246_822_519;
const XX_P3: u32 = 3_266_489_917;
const XX_P4: u32 = 668_265_263;
const XX_P5: u32 = 374_761_393;

/// xxhash32 of three words (Jarzynski & Olano 2020, the hash of vk_gaussian_splatting).
#[inline(always)]
pub fn xxhash32(p: [u32; 3]) -> u32 {
    xxhash32_tail(xxhash32_head(p[0], p[2]), p[1])
}

/// The first round of [`xxhash32`], which reads words 0 and 2 only: a draw keyed by (pixel,
/// particle, slot) computes it once per (pixel, slot).
#[inline(always)]
pub fn xxhash32_head(p0: u32, p2: u32) -> u32 {
    let h = p2.wrapping_add(XX_P5).wrapping_add(p0.wrapping_mul(XX_P3));
    XX_P4.wrapping_mul(h.rotate_left(17))
}

/// The rest of [`xxhash32`]: word 1 mixed into a [`xxhash32_head`], then the avalanche.
#[inline(always)]
pub fn xxhash32_tail(head: u32, p1: u32) -> u32 {
    let mut h = head.wrapping_add(p1.wrapping_mul(XX_P3));
    h = XX_P4.wrapping_mul(h.rotate_left(17));
    h = XX_P2.wrapping_mul(h ^ (h >> 15));
    h = XX_P3.wrapping_mul(h ^ (h >> 13));
    h ^ (h >> 16)
}

/// One step of the PCG hash (vk_gaussian_splatting `pcg`).
#[inline]
pub fn pcg(v: u32) -> u32 {
    let s = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let w = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277_803_737);
    (w >> 22) ^ w
}

/// Uniform in [0, 1) from the top 24 bits of a word: exact in f32 and never 1.0
/// (`float(x) / float(0xffffffff)` can round to 1.0).
#[inline]
pub fn unit_f32(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Fractional part x − ⌊x⌋.
#[inline]
fn fract(x: f32) -> f32 {
    x - x.floor()
}

/// Sun et al. Eq. 8: r₁(q) = fract(b₁ sin(a₁ q)), a₁ = 91.3458, b₁ = 47453.5453.
#[inline]
pub fn trig_r1(q: f32) -> f32 {
    fract(47_453.547 * (91.3458 * q).sin())
}

/// Sun et al. Eq. 9: r₂(q) = fract(b₂ sin(a₂ᵀ q)), a₂ = (12.9898, 78.233), b₂ = 43758.5453 in
/// both components (so both components are equal; one is returned).
#[inline]
pub fn trig_r2(qx: f32, qy: f32) -> f32 {
    fract(43_758.547 * (12.9898 * qx + 78.233 * qy).sin())
}

/// Sun et al. Eq. 10: ξ(p) = r₂(p_xy + r₁(p_z)).
#[inline]
pub fn trig_hash(p: glam::Vec3) -> f32 {
    let r = trig_r1(p.z);
    trig_r2(p.x + r, p.y + r)
}

/// Which stateless generator makes the stochastic decisions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RngScheme {
    /// xxhash32 of (pixel, frame) then of (that, particle id, slot), PCG, top 24 bits
    /// (vk_gaussian_splatting).
    #[default]
    Hash,
    /// The trigonometric hash of Sun et al. Eqs. 8–10 on the hit position, perturbed per
    /// (pixel, frame, slot) by a hashed offset in [0, 1)³ (standing in for the paper's
    /// per-frame Sobol perturbation of the camera ray).
    Trig,
}

/// Particle id reserved for per-pass decisions.
pub const PASS_ID: u32 = u32::MAX;
/// Particle id reserved for the trig hash's per-slot offsets.
pub const OFFSET_ID: u32 = u32::MAX - 1;
/// Particle id reserved for area-light samples (ids − 2 and − 3 are the rasterizer's).
pub const LIGHT_ID: u32 = u32::MAX - 4;
/// Most slots whose hash heads one [`SlotDraws`] prepares (the GPU kernel's largest n); a
/// traversal of more draws each slot whole.
pub const MAX_SLOT_DRAWS: usize = 64;

/// The draws of one pixel's slots, prepared once per traversal ([`RayRng::slot_draws`]).
#[derive(Clone, Copy, Debug)]
pub struct SlotDraws {
    rng: RayRng,
    first_slot: u32,
    heads: [u32; MAX_SLOT_DRAWS],
    n: usize,
}

impl SlotDraws {
    /// u of particle `id` in each slot, into `out` (at most the prepared n):
    /// [`RayRng::particle`] slot by slot, bit for bit.
    #[inline(always)]
    pub fn draw(&self, id: u32, hit: glam::Vec3, out: &mut [f32]) {
        let out = &mut out[..self.n];
        if self.rng.scheme != RngScheme::Hash || self.n > MAX_SLOT_DRAWS {
            for (s, u) in (self.first_slot..).zip(out.iter_mut()) {
                *u = self.rng.particle(id, s, hit);
            }
            return;
        }
        for (u, &head) in out.iter_mut().zip(&self.heads) {
            *u = unit_f32(pcg(xxhash32_tail(head, id))) - self.rng.u_shift;
        }
    }
}

/// Largest particle count: ids up to `MAX_PARTICLES − 1` never collide with the reserved ones.
pub const MAX_PARTICLES: usize = (u32::MAX - 1) as usize;

/// Key of one frame of one render: the frame index mixed with the run's seed, so that two
/// seeds give independent streams.
#[inline]
pub fn frame_key(seed: u32, frame: u32) -> u32 {
    xxhash32([frame, seed, 0x5EED_F4A3])
}

/// The stochastic decisions of one ray: a pure function of (pixel, frame key, particle id,
/// slot), never of traversal order or thread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayRng {
    /// xxhash32(x, y, frame key).
    pub pixel_key: u32,
    /// Generator.
    pub scheme: RngScheme,
    /// Subtracted from every u ([`crate::Frames::u_shift`], a test hook; 0 otherwise).
    pub u_shift: f32,
}

impl RayRng {
    /// Decisions for pixel (x, y) in the frame with key `frame_key`.
    pub fn new(x: u32, y: u32, frame_key: u32, scheme: RngScheme) -> Self {
        Self { pixel_key: xxhash32([x, y, frame_key]), scheme, u_shift: 0.0 }
    }

    /// The same decisions with every u lowered by `u_shift` ([`crate::Frames::u_shift`]).
    pub fn shifted(self, u_shift: f32) -> Self {
        Self { u_shift, ..self }
    }

    /// Whether decisions depend on the hit position (then they cannot be drawn before the
    /// kernel is evaluated).
    pub fn needs_position(&self) -> bool {
        self.scheme == RngScheme::Trig
    }

    /// u ∈ [0, 1) deciding whether particle `id` is accepted in sample `slot`; `hit` is the
    /// hit position (used by [`RngScheme::Trig`] only).
    #[inline(always)]
    pub fn particle(&self, id: u32, slot: u32, hit: glam::Vec3) -> f32 {
        self.particle_u(id, slot, hit) - self.u_shift
    }

    #[inline(always)]
    fn particle_u(&self, id: u32, slot: u32, hit: glam::Vec3) -> f32 {
        match self.scheme {
            RngScheme::Hash => unit_f32(pcg(xxhash32([self.pixel_key, id, slot]))),
            RngScheme::Trig => {
                let o = |k: u32| unit_f32(pcg(xxhash32([self.pixel_key, OFFSET_ID, 3 * slot + k])));
                trig_hash(hit + glam::Vec3::new(o(0), o(1), o(2)))
            }
        }
    }

    /// The draws of the slots `first_slot..first_slot + n` with the first round of the hash,
    /// which depends on the pixel and the slot only, done once where n ≤ [`MAX_SLOT_DRAWS`]
    /// (beyond, each slot is drawn whole, the same numbers): what one traversal of
    /// `stochastic-n` asks for every particle it visits.
    #[inline(always)]
    pub fn slot_draws(&self, first_slot: u32, n: usize) -> SlotDraws {
        let mut heads = [0u32; MAX_SLOT_DRAWS];
        if self.scheme == RngScheme::Hash && n <= MAX_SLOT_DRAWS {
            for (s, h) in (first_slot..).zip(&mut heads[..n]) {
                *h = xxhash32_head(self.pixel_key, s);
            }
        }
        SlotDraws { rng: *self, first_slot, heads, n }
    }

    /// A point of [0, 1)² on area light `light` for sample slot `slot` (not shifted by
    /// `u_shift`: it places a light sample, it decides nothing).
    pub fn light_sample(&self, light: u32, slot: u32) -> glam::Vec2 {
        let u = |k: u32| unit_f32(pcg(xxhash32([self.pixel_key, LIGHT_ID, (slot << 7) | (light << 1) | k])));
        glam::Vec2::new(u(0), u(1))
    }

    /// u ∈ [0, 1) deciding whether pass `pass` is accepted (stochastic pass).
    #[inline]
    pub fn pass(&self, pass: u32) -> f32 {
        unit_f32(pcg(xxhash32([self.pixel_key, PASS_ID, pass]))) - self.u_shift
    }
}

/// The four multiply–XOR constants of Laine & Karras 2011, Figure 4.
pub const LK_SCRAMBLE: [u32; 4] = [0x6C50_B47C, 0xB82F_1E52, 0xC7AF_E638, 0x8D22_F6E6];

/// Laine & Karras 2011, Figure 4 (CalcAlphaRef): the opacity reference value of sample
/// `sample_id` of pixel `pixel_id` for surface `surface_id`, in [0, 1).
///
/// x = sampleId + pixelId · samplesPerPixel; x = reverseBits(x) + surfaceId; then four rounds
/// x ^= x · C. Each C is even, so bit i of x · C depends only on bits below i: every round flips
/// each bit by a hash of the bits below it, an Owen scramble that keeps every aligned
/// power-of-two span of indices stratified while making disjoint spans uncorrelated (§3).
/// `scramble = false` skips the rounds: the plain radical inverse, whose spans are shifted
/// copies of each other, the correlated sequence §3 warns about (a negative control).
#[inline]
pub fn calc_alpha_ref(sample_id: u32, pixel_id: u32, surface_id: u32, samples_per_pixel: u32, scramble: bool) -> f32 {
    let mut x = sample_id.wrapping_add(pixel_id.wrapping_mul(samples_per_pixel));
    x = x.reverse_bits().wrapping_add(surface_id);
    if scramble {
        for c in LK_SCRAMBLE {
            x ^= x.wrapping_mul(c);
        }
    }
    unit_f32(x)
}

/// Laine & Karras 2011, Figure 3b: the opacity reference value of the Sobol sequence in place
/// of CalcAlphaRef's scramble. The index is formed as Figure 4 forms it (sample + pixel ·
/// samples, bits reversed, plus the surface id, reversed back), and mapped through the
/// generator matrix of Sobol's second dimension (direction numbers vⱼ₊₁ = vⱼ ⊕ (vⱼ ≫ 1), the
/// polynomial x + 1): each output bit is the parity of the index ANDed with a bit-specific
/// constant. Every aligned power-of-two span stays stratified, but spans of different surfaces
/// are linear images of each other: the correlation the figure shows.
pub fn sobol_alpha_ref(sample_id: u32, pixel_id: u32, surface_id: u32, samples_per_pixel: u32) -> f32 {
    let x = sample_id.wrapping_add(pixel_id.wrapping_mul(samples_per_pixel));
    let index = x.reverse_bits().wrapping_add(surface_id).reverse_bits();
    let (mut v, mut out) = (0x8000_0000u32, 0u32);
    for j in 0..32 {
        if index >> j & 1 == 1 {
            out ^= v;
        }
        v ^= v >> 1;
    }
    unit_f32(out)
}

/// Index of cell (x, y) along the Morton (Z) curve: the bits of x and y interleaved (x in the
/// even bits). Laine & Karras §3.1's control: every aligned 2ᵏ × 2ᵏ block gets the same
/// structure.
pub fn morton_index(x: u32, y: u32) -> u32 {
    let spread = |v: u32| (0..16).fold(0u32, |m, i| m | ((v >> i & 1) << (2 * i)));
    spread(x) | spread(y) << 1
}

/// Index of cell (x, y) along the Hilbert curve filling the 2^order × 2^order grid: cells with
/// consecutive indices are edge neighbours (Laine & Karras §3.1: a Morton curve gives every
/// aligned block the same structure; the Hilbert curve does not).
pub fn hilbert_index(order: u32, x: u32, y: u32) -> u32 {
    let n = 1u32 << order;
    let (mut x, mut y) = (x, y);
    let mut d = 0u32;
    let mut s = n >> 1;
    while s > 0 {
        let rx = u32::from(x & s != 0);
        let ry = u32::from(y & s != 0);
        d = d.wrapping_add(s.wrapping_mul(s).wrapping_mul((3 * rx) ^ ry));
        // Rotate the quadrant so that the sub-curve starts and ends where the parent needs.
        if ry == 0 {
            if rx == 1 {
                x = n - 1 - x;
                y = n - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s >>= 1;
    }
    d
}

/// Order of the smallest Hilbert grid 2^order × 2^order holding a `width` × `height` image.
pub fn hilbert_order(width: u32, height: u32) -> u32 {
    width.max(height).max(1).next_power_of_two().trailing_zeros()
}

#[cfg(test)]
mod lk_tests {
    use super::*;

    /// Consecutive Hilbert indices are edge neighbours and the map is a bijection of the grid.
    #[test]
    fn hilbert_curve_is_a_continuous_bijection() {
        for order in 0..=5 {
            let n = 1u32 << order;
            let mut cell = vec![(0u32, 0u32); (n * n) as usize];
            let mut seen = vec![false; (n * n) as usize];
            for y in 0..n {
                for x in 0..n {
                    let d = hilbert_index(order, x, y) as usize;
                    assert!(!seen[d], "index {d} twice");
                    seen[d] = true;
                    cell[d] = (x, y);
                }
            }
            for w in cell.windows(2) {
                let dist = w[0].0.abs_diff(w[1].0) + w[0].1.abs_diff(w[1].1);
                assert_eq!(dist, 1, "order {order}: {:?} → {:?}", w[0], w[1]);
            }
        }
        assert_eq!(hilbert_order(1200, 800), 11);
        assert_eq!(hilbert_order(1, 1), 0);
    }

    /// §3: every aligned power-of-two span of a surface's sequence is stratified (one value in
    /// each of its 2^k strata), with or without the scramble.
    #[test]
    fn aligned_spans_are_stratified() {
        for scramble in [true, false] {
            for span in [2u32, 4, 8, 16, 64] {
                for start in (0..1024).step_by(span as usize) {
                    let mut strata = vec![false; span as usize];
                    for i in start..start + span {
                        let u = calc_alpha_ref(i, 0, 17, 64, scramble);
                        let k = (u * span as f32) as usize;
                        assert!(!strata[k], "span {span} at {start}: stratum {k} twice");
                        strata[k] = true;
                    }
                }
            }
        }
    }

    /// Without the scramble, consecutive surfaces give nearly the same value to a sample (the
    /// correlation of §3); with it, their values are uncorrelated.
    #[test]
    fn scramble_decorrelates_surfaces() {
        let corr = |scramble: bool| {
            let n = 20_000u32;
            let (mut sxy, mut sx, mut sy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
            for i in 0..n {
                let x = f64::from(calc_alpha_ref(i % 16, i / 16, 5, 16, scramble));
                let y = f64::from(calc_alpha_ref(i % 16, i / 16, 6, 16, scramble));
                (sxy, sx, sy, sxx, syy) = (sxy + x * y, sx + x, sy + y, sxx + x * x, syy + y * y);
            }
            let n = f64::from(n);
            (sxy / n - sx * sy / n / n) / ((sxx / n - (sx / n).powi(2)) * (syy / n - (sy / n).powi(2))).sqrt()
        };
        assert!(corr(false) > 0.99, "plain radical inverse: {}", corr(false));
        assert!(corr(true).abs() < 0.05, "scrambled: {}", corr(true));
    }

    /// Figure 3b's Sobol sequence keeps every pixel's span stratified, for any surface id (its
    /// first digits depend on the index's low bits alone, through a unit triangular matrix),
    /// and its first values are those of Sobol's second dimension in the index's natural order
    /// (not Gray code): 0, 1/2, 3/4, 1/4, 5/8, 1/8.
    #[test]
    fn sobol_alpha_refs_are_stratified_sobol_points() {
        let first: Vec<f32> = (0..6).map(|n| sobol_alpha_ref(n, 0, 0, 64)).collect();
        assert_eq!(first, [0.0, 0.5, 0.75, 0.25, 0.625, 0.125]);
        for (pixel, surface) in [(0, 0), (5, 1), (77, 123_456_789)] {
            let mut strata = [false; 16];
            for n in 0..16 {
                let k = (sobol_alpha_ref(n, pixel, surface, 16) * 16.0) as usize;
                assert!(!strata[k], "pixel {pixel}, surface {surface}: stratum {k} twice");
                strata[k] = true;
            }
        }
    }

    /// The Morton index interleaves x (even bits) and y (odd bits): a bijection of each
    /// 2ᵏ × 2ᵏ block onto 0..4ᵏ, every aligned 2 × 2 block numbered alike.
    #[test]
    fn morton_index_interleaves_bits() {
        assert_eq!(
            [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (0, 2)].map(|(x, y)| morton_index(x, y)),
            [0, 1, 2, 3, 4, 8]
        );
        let mut seen = [false; 64];
        for y in 0..8 {
            for x in 0..8 {
                let i = morton_index(x, y) as usize;
                assert!(!seen[i]);
                seen[i] = true;
                assert_eq!(i % 4, (x % 2 + 2 * (y % 2)) as usize);
            }
        }
    }
}

#[cfg(test)]
mod hash_tests {
    use super::*;

    #[test]
    fn xxhash32_and_pcg_reference_values() {
        // Reference values from an independent Python transcription of the GLSL of
        // Jarzynski & Olano 2020.
        assert_eq!(pcg(0), 129_708_002);
        assert_eq!(xxhash32([1, 2, 3]), 243_197_822);
        assert_eq!(xxhash32([0, 0, 0]), 2_783_098_233);
        assert_ne!(xxhash32([0, 0, 0]), xxhash32([0, 0, 1]));
        assert_ne!(xxhash32([1, 0, 0]), xxhash32([0, 1, 0]));
    }

    /// The trig hash in f32 takes few distinct values: b ≈ 4.4·10⁴ < 2¹⁶ leaves at most 8–10
    /// fractional bits of fract(b sin(·)), so u lies on a grid of steps up to 1/256 and every
    /// acceptance probability is rounded to it. The xxhash/PCG scheme has 24 bits.
    #[test]
    fn trig_hash_is_quantised_in_f32() {
        let mut trig = std::collections::HashSet::new();
        let mut hash = std::collections::HashSet::new();
        for i in 0..200_000u32 {
            let p = glam::Vec3::new((i % 631) as f32 * 0.0037, (i / 631) as f32 * 0.0051, 1.0 + (i % 17) as f32 * 0.01);
            trig.insert(trig_hash(p).to_bits());
            hash.insert(unit_f32(pcg(xxhash32([i, 7, 0]))).to_bits());
        }
        assert!(trig.len() < 20_000, "{} distinct trig values", trig.len());
        assert!(hash.len() > 190_000, "{} distinct hash values", hash.len());
    }

    #[test]
    fn unit_f32_never_reaches_one() {
        assert_eq!(unit_f32(u32::MAX), 16_777_215.0 / 16_777_216.0);
        assert_eq!(unit_f32(0), 0.0);
    }

    /// Kolmogorov–Smirnov distance of draws from U[0, 1): sup over α of |P̂(u < α) − α|.
    fn ks_distance(mut u: Vec<f32>) -> f64 {
        u.sort_by(f32::total_cmp);
        let n = u.len() as f64;
        let mut d = 0.0f64;
        for (i, &x) in u.iter().enumerate() {
            let x = f64::from(x);
            d = d.max(x - i as f64 / n).max((i + 1) as f64 / n - x);
        }
        d
    }

    /// The KS distance a uniform sample of `n` exceeds with probability 10⁻³.
    fn ks_critical(n: usize) -> f64 {
        1.949 / (n as f64).sqrt()
    }

    /// χ² of a 16 × 16 histogram of pairs against independence, in standard units
    /// ((χ² − 255) / √510): about N(0, 1) for independent uniform pairs.
    fn pair_chi2(pairs: impl Iterator<Item = (f32, f32)>) -> f64 {
        let mut bins = [0u32; 256];
        let mut n = 0u32;
        for (a, b) in pairs {
            bins[(a * 16.0) as usize * 16 + (b * 16.0) as usize] += 1;
            n += 1;
        }
        let e = f64::from(n) / 256.0;
        let chi2: f64 = bins.iter().map(|&o| (f64::from(o) - e).powi(2) / e).sum();
        (chi2 - 255.0) / 510f64.sqrt()
    }

    /// The hit point of particle `id` (the trig hash reads it).
    fn hit(id: u32) -> glam::Vec3 {
        glam::Vec3::new((id % 97) as f32 * 0.013 - 0.6, (id % 89) as f32 * 0.021 - 0.9, 1.5 + (id % 13) as f32 * 0.07)
    }

    /// u of key i: pixel (x, y), frame, particle id and slot all vary with i.
    fn draw(scheme: RngScheme, i: u32, [dx, df, did, ds]: [u32; 4]) -> f32 {
        let (x, y, frame, id, slot) = (i % 640 + dx, (i / 640) % 480, i % 7 + df, i % 1000 + did, i % 4 + ds);
        RayRng::new(x, y, frame_key(1, frame), scheme).particle(id, slot, hit(id))
    }

    /// The draws prepared per traversal are the draws, for both generators and a shifted one.
    #[test]
    fn batched_draws_equal_single_draws() {
        for scheme in [RngScheme::Hash, RngScheme::Trig] {
            let rng = RayRng::new(3, 4, frame_key(1, 2), scheme).shifted(0.01);
            let hit = glam::Vec3::new(0.1, 0.2, 0.3);
            // Prepared heads (64 slots) and whole draws past them (256).
            for n in [64, 256] {
                let mut out = vec![0.0f32; n];
                rng.slot_draws(5, n).draw(77, hit, &mut out);
                for (s, u) in (5..).zip(out) {
                    assert_eq!(u.to_bits(), rng.particle(77, s, hit).to_bits());
                }
            }
        }
    }

    /// P(u < α) = α for every α (Kolmogorov–Smirnov over 10⁶ draws, p = 10⁻³), and u of keys
    /// that differ in one of pixel, frame, particle and slot are independent (χ² of 16 × 16
    /// bins over 2.5·10⁵ pairs each, within 6 standard units). The xxhash/PCG generator passes;
    /// the trig hash of Sun et al. Eqs. 8–10 fails in f32 (its u lies on a coarse grid), and
    /// the test says so; a 1 % distortion of the hash (u^1.01) is rejected too, the test's
    /// power.
    #[test]
    fn decisions_are_uniform_and_pairwise_independent() {
        let n = 1_000_000u32;
        let hash: Vec<f32> = (0..n).map(|i| draw(RngScheme::Hash, i, [0; 4])).collect();
        assert!(hash.iter().all(|u| (0.0..1.0).contains(u)));
        let d = ks_distance(hash.clone());
        assert!(d < ks_critical(n as usize), "hash: KS distance {d}");
        let distorted = ks_distance(hash.iter().map(|u| u.powf(1.01)).collect());
        assert!(distorted > ks_critical(n as usize), "u^1.01 passes: KS distance {distorted}");
        for (k, name) in ["pixel", "frame", "particle", "slot"].iter().enumerate() {
            let mut shift = [0; 4];
            shift[k] = 1;
            let chi =
                pair_chi2((0..n / 4).map(|i| (draw(RngScheme::Hash, i, [0; 4]), draw(RngScheme::Hash, i, shift))));
            assert!(chi.abs() < 6.0, "hash: neighbouring {name}s correlated (χ² {chi:.1} standard units)");
        }
        let trig = ks_distance((0..n).map(|i| draw(RngScheme::Trig, i, [0; 4])).collect());
        eprintln!(
            "KS distance over 10⁶ draws: hash {d:.2e}, u^1.01 {distorted:.2e}, trig hash {trig:.2e} (critical {:.2e})",
            ks_critical(n as usize)
        );
        assert!(trig > ks_critical(n as usize), "the trig hash passed the uniformity test in f32: {trig}");
    }
}
