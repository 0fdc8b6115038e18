//! The wide BVH node as the GPU reads it: [`Node4`] with its children's boxes quantized to
//! 8 bits a plane and rounded outward, 64 bytes where the CPU's node is 128.
//!
//! Each axis of a node has an origin o (the lowest lower plane of its children) and a scale
//! s = 2ᵉ; lane l's planes are o + q s for bytes q of the lane (Ylitie, Karras and Laine 2017,
//! "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", §3.1, with the
//! origin at the children's lowest plane). Since q ≤ 255 and s is a power of two, q s is exact,
//! so o + q s rounds once, whether a GPU fuses it into one multiply-add or not, and the host
//! computes each plane as the kernel will ([`GpuNode::planes`], the twin of `node_planes` in
//! `shaders/bvh.wgsl`). The encoder picks each lower q as the largest whose plane lies at or
//! below the child's, each upper q as the smallest at or above, and the smallest scale that
//! lets the uppers fit in a byte, each bound holding whether or not the device flushes a
//! subnormal result to zero: every decoded box holds the child's box, so the traversal
//! reaches every leaf the exact tree reaches (and a few more), and every method's result,
//! which depends on the hits found and never on the order of the walk, is the CPU's.

use bytemuck::{Pod, Zeroable};
use splat_core::bvh::{Bvh4, LEAF, Node4};

/// Lanes of a node.
const WIDTH: usize = 4;
/// The largest quantized plane.
const Q_MAX: u32 = 255;
/// The biased exponent of the largest scale (2¹²⁷), which covers any finite extent.
const E_MAX: u32 = 254;

/// A wide BVH node as the kernel reads it (WGSL `Node`, 64 bytes): [`Node4`]'s four children,
/// their planes quantized on each axis, their references (a node's index in the node buffer,
/// or a leaf: [`LEAF`] set) and the lanes in use.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuNode {
    /// The bits of the origin's x, y and z (f32); then the biased exponents of the scales
    /// of x, y and z (bytes 0–2: s = 2^(e − 127), the f32 whose exponent field is e) and the
    /// lanes in use (byte 3).
    pub origin: [u32; 4],
    /// The lanes' quantized lower x, upper x, lower y and upper y planes, lane l in byte l.
    pub planes_xy: [u32; 4],
    /// The lower and upper z planes, then two unused words.
    pub planes_z: [u32; 4],
    /// Children's references.
    pub child: [u32; 4],
}

/// One axis of a node, quantized: its origin, the biased exponent of its scale, and each
/// lane's lower and upper q.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Axis {
    origin: f32,
    exponent: u32,
    lo: [u32; WIDTH],
    hi: [u32; WIDTH],
}

/// The scale 2^(e − 127) of biased exponent `e` (1 to 254): the f32 with that exponent field.
fn scale(e: u32) -> f32 {
    f32::from_bits(e << 23)
}

/// Plane q of an axis of origin `o` and scale `s`: o + q s, rounded once (q s is exact).
fn plane(o: f32, q: u32, s: f32) -> f32 {
    o + q as f32 * s
}

/// Plane p as a device that flushes subnormal results to zero reads it: the decoded planes keep
/// their bounds whether the device flushes or not ([`plane_either`]).
fn flushed(p: f32) -> f32 {
    if p.is_subnormal() { 0.0f32.copysign(p) } else { p }
}

/// Plane q of an axis, the lower and the higher of what a device that flushes subnormal results
/// to zero and one that does not read.
fn plane_either(o: f32, q: u32, s: f32) -> (f32, f32) {
    let p = plane(o, q, s);
    (p.min(flushed(p)), p.max(flushed(p)))
}

/// The four bytes of word `w`, lane l in byte l.
fn bytes(w: u32) -> [u32; WIDTH] {
    std::array::from_fn(|l| (w >> (8 * l)) & 0xff)
}

/// Four bytes packed in a word, lane l in byte l.
fn word(q: [u32; WIDTH]) -> u32 {
    q.iter().enumerate().map(|(l, &q)| q << (8 * l)).sum()
}

impl Axis {
    /// An axis of no lanes in use: each lane's lower q 255 and upper q 0 (the kernel masks
    /// lanes past the count).
    const UNUSED: Axis = Axis { origin: 0.0, exponent: 127, lo: [Q_MAX; WIDTH], hi: [0; WIDTH] };

    /// The axis of lanes `lo[..lanes]`, `hi[..lanes]`: each used lane's decoded interval holds
    /// its own; the others are as [`Axis::UNUSED`]'s.
    fn quantize(lo: [f32; WIDTH], hi: [f32; WIDTH], lanes: usize) -> Axis {
        if lanes == 0 {
            return Axis::UNUSED;
        }
        let lo_min = lo[..lanes].iter().copied().fold(f32::INFINITY, f32::min);
        let hi_max = hi[..lanes].iter().copied().fold(f32::NEG_INFINITY, f32::max);
        if !(lo_min.is_finite() && hi_max.is_finite()) {
            // Not from a scene the loaders accept; still held: every plane from −f32::MAX up.
            let mut axis = Axis { origin: f32::MIN, exponent: E_MAX, ..Axis::UNUSED };
            (0..lanes).for_each(|l| (axis.lo[l], axis.hi[l]) = (0, Q_MAX));
            return axis;
        }
        // A GPU may flush a subnormal origin to zero: the next float at or below it that it
        // keeps.
        let origin = match lo_min {
            o if o.is_subnormal() && o < 0.0 => -f32::MIN_POSITIVE,
            o if o.is_subnormal() || o == 0.0 => 0.0,
            o => o,
        };
        // The least scale whose 255 steps span the extent and none of which is below a unit in
        // the last place of the planes (finer steps round to the same floats, and the search
        // below would walk them one by one: a scene far from the origin made of small splats),
        // then larger ones until the rounding of every upper plane fits.
        let steps = (f64::from(hi_max) - f64::from(origin)) / f64::from(Q_MAX);
        let spanning = if steps > 0.0 { steps.log2().ceil() as i64 + 127 } else { 1 };
        let ulp = |x: f32| i64::from((x.to_bits() >> 23) & 0xff) - 23;
        let least = spanning.max(ulp(origin)).max(ulp(hi_max)).clamp(1, E_MAX as i64) as u32;
        (least..=E_MAX)
            .find_map(|exponent| Self::with_scale(origin, exponent, lo, hi, lanes))
            .expect("the largest scale holds every finite plane")
    }

    /// The axis at scale 2^(`exponent` − 127), or `None` where an upper plane needs q > 255.
    fn with_scale(origin: f32, exponent: u32, lo: [f32; WIDTH], hi: [f32; WIDTH], lanes: usize) -> Option<Axis> {
        let s = scale(exponent);
        let mut axis = Axis { origin, exponent, lo: [Q_MAX; WIDTH], hi: [0; WIDTH] };
        for l in 0..lanes {
            let guess = |x: f32| (f64::from(x) - f64::from(origin)) / f64::from(s);
            let mut q_lo = guess(lo[l]).floor().clamp(0.0, f64::from(Q_MAX)) as u32;
            while q_lo > 0 && plane_either(origin, q_lo, s).1 > lo[l] {
                q_lo -= 1;
            }
            let mut q_hi = guess(hi[l]).ceil().clamp(0.0, f64::from(Q_MAX) + 1.0) as u32;
            while q_hi <= Q_MAX && plane_either(origin, q_hi, s).0 < hi[l] {
                q_hi += 1;
            }
            if q_hi > Q_MAX && exponent < E_MAX {
                return None;
            }
            (axis.lo[l], axis.hi[l]) = (q_lo, q_hi.min(Q_MAX));
        }
        Some(axis)
    }
}

impl GpuNode {
    /// `n` quantized, its node references moved by `offset` (a leaf's reference is kept).
    pub fn new(n: &Node4, offset: u32) -> GpuNode {
        let lanes = n.count() as usize;
        let axes = n.planes().map(|[lo, hi]| Axis::quantize(lo, hi, lanes));
        let child = std::array::from_fn(|lane| match n.children()[lane] {
            r if lane < lanes && r & LEAF == 0 => r + offset,
            r => r,
        });
        let [x, y, z] = axes;
        GpuNode {
            origin: [
                x.origin.to_bits(),
                y.origin.to_bits(),
                z.origin.to_bits(),
                word([x.exponent, y.exponent, z.exponent, n.count()]),
            ],
            planes_xy: [word(x.lo), word(x.hi), word(y.lo), word(y.hi)],
            planes_z: [word(z.lo), word(z.hi), 0, 0],
            child,
        }
    }

    /// Lanes in use.
    pub fn count(&self) -> u32 {
        self.origin[3] >> 24
    }

    /// The children's planes as the kernel decodes them, `[axis][lower, upper][lane]`: the
    /// twin of `node_planes` in `shaders/bvh.wgsl`.
    pub fn planes(&self) -> [[[f32; WIDTH]; 2]; 3] {
        let words = [
            [self.planes_xy[0], self.planes_xy[1]],
            [self.planes_xy[2], self.planes_xy[3]],
            [self.planes_z[0], self.planes_z[1]],
        ];
        std::array::from_fn(|axis| {
            let o = f32::from_bits(self.origin[axis]);
            let s = scale(bytes(self.origin[3])[axis]);
            words[axis].map(|w| bytes(w).map(|q| plane(o, q, s)))
        })
    }
}

/// The nodes of `bvh` placed at index `offset` of a node buffer, its root first (a reference to
/// a node is its index, moved by the offset; a leaf's reference is kept). Encoded on every core
/// where splat-core runs in parallel (its `rayon` feature), in order either way.
pub fn bvh_nodes(bvh: &Bvh4, offset: u32) -> Vec<GpuNode> {
    splat_core::par::map(bvh.nodes(), |n| GpuNode::new(n, offset))
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::rng::SplitMix64;

    /// Whether each used lane's decoded box holds its exact one, and the unused lanes' are empty.
    fn holds(n: &Node4, g: &GpuNode) -> Result<(), String> {
        let (exact, decoded) = (n.planes(), g.planes());
        for axis in 0..3 {
            for lane in 0..WIDTH {
                let ([lo, hi], [dlo, dhi]) = (exact[axis].map(|p| p[lane]), decoded[axis].map(|p| p[lane]));
                let ok = if lane < n.count() as usize { dlo <= lo && hi <= dhi } else { dlo > dhi };
                if !ok {
                    return Err(format!("axis {axis} lane {lane}: [{lo}, {hi}] decoded as [{dlo}, {dhi}]"));
                }
            }
        }
        Ok(())
    }

    /// Every child's box of real trees (a random cloud's and a plane mesh's, flat on one axis)
    /// and of hard cases (boxes far from the origin and tiny, subnormal, straddling the
    /// smallest normal float so that some decoded planes are subnormal, spanning ±10³⁰) lies
    /// within its decoded box, whether or not the device flushes subnormals to zero (control,
    /// by hand: bounds checked unflushed only fail there), with references and counts kept;
    /// no scale is below a unit in the last place of the origin; and the quantization is
    /// tight: a decoded plane lies within one step of 8 bits of the node's extent from the
    /// exact one on average, so the GPU does not walk a much looser tree. Control: the
    /// rounding to nearest that a plain quantizer would use loses boxes.
    #[test]
    fn decoded_boxes_hold_the_exact_ones() {
        let mut rng = SplitMix64::new(7);
        let mut cases: Vec<[[f32; 2]; WIDTH]> = Vec::new();
        let span = |centre: f32, size: f32, rng: &mut SplitMix64| -> [[f32; 2]; WIDTH] {
            std::array::from_fn(|_| {
                let a = centre + size * (rng.next_f32() - 0.5);
                let b = a + size * rng.next_f32() * 0.3;
                [a, b]
            })
        };
        for (centre, size) in [
            (0.0, 1.0),
            (1.0e4, 1.0e-3),
            (-3.0e5, 7.0),
            (1.0e-39, 1.0e-39),
            (-1.5e-38, 2.0e-38),
            (0.0, 2.0e30),
            (5.0, 0.0),
        ] {
            for _ in 0..200 {
                cases.push(span(centre, size, &mut rng));
            }
        }
        let mut checked = 0;
        for boxes in &cases {
            for lanes in 1..=WIDTH {
                let lo: [f32; WIDTH] = std::array::from_fn(|l| boxes[l][0]);
                let hi: [f32; WIDTH] = std::array::from_fn(|l| boxes[l][1]);
                let axis = Axis::quantize(lo, hi, lanes);
                let s = scale(axis.exponent);
                // No step below a unit in the last place of the origin (the search would walk
                // such steps one by one: 256 of them a unit for the boxes at 10⁴ of 10⁻³).
                let ulp = f32::from_bits(axis.origin.abs().to_bits() + 1) - axis.origin.abs();
                assert!(axis.origin == 0.0 || s >= ulp, "a scale {s} below the origin {}'s unit {ulp}", axis.origin);
                for l in 0..WIDTH {
                    let (dlo, dhi) = (plane(axis.origin, axis.lo[l], s), plane(axis.origin, axis.hi[l], s));
                    if l < lanes {
                        assert!(
                            dlo <= lo[l] && hi[l] <= dhi,
                            "[{}, {}] decoded as [{dlo}, {dhi}] ({axis:?})",
                            lo[l],
                            hi[l]
                        );
                        let (flo, fhi) = (flushed(dlo), flushed(dhi));
                        assert!(flo <= lo[l] && hi[l] <= fhi, "[{}, {}] flushed to [{flo}, {fhi}]", lo[l], hi[l]);
                    } else {
                        assert!(dlo > dhi || (dlo == dhi && axis.lo[l] == Q_MAX && axis.hi[l] == 0), "unused lane {l}");
                    }
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, cases.len() * WIDTH * WIDTH);
        // Real trees: every node of a random cloud's BVH and of a mesh's.
        let (scene, _) = splat_core::scenes::cloud();
        let trace = splat_core::trace::TraceScene::new(&scene, splat_core::RenderSettings::default()).unwrap();
        let mesh = splat_core::mesh::Meshes::new(&[(
            splat_core::mesh::TriangleMesh::plane(),
            splat_core::mesh::MeshMaterial::default(),
        )])
        .unwrap();
        for bvh in [trace.bvh(), mesh.bvh()] {
            let gpu = bvh_nodes(bvh, 5);
            let (mut loose, mut planes) = (0.0f64, 0usize);
            for (n, g) in bvh.nodes().iter().zip(&gpu) {
                holds(n, g).unwrap();
                assert_eq!(g.count(), n.count());
                let lanes = n.count() as usize;
                for lane in 0..lanes {
                    let r = n.children()[lane];
                    assert_eq!(g.child[lane], if r & LEAF == 0 { r + 5 } else { r });
                }
                for axis in 0..3 {
                    let [lo, hi] = n.planes()[axis];
                    let extent = (0..lanes).map(|l| hi[l]).fold(f32::MIN, f32::max)
                        - (0..lanes).map(|l| lo[l]).fold(f32::MAX, f32::min);
                    let [dlo, dhi] = g.planes()[axis];
                    for l in 0..lanes.min(WIDTH) {
                        if extent > 0.0 {
                            loose += f64::from((lo[l] - dlo[l]) + (dhi[l] - hi[l])) / f64::from(extent) * 255.0;
                            planes += 2;
                        }
                    }
                }
            }
            let mean = loose / planes.max(1) as f64;
            assert!(planes > 100 || bvh.nodes().len() < 4, "{planes} planes");
            assert!(mean < 1.0, "decoded planes lie {mean:.2} steps of the extent/255 out on average");
        }
        // Control: rounding to nearest loses some boxes.
        let nearest = |lo: f32, hi: f32, o: f32, s: f32| {
            let q = |x: f32| ((x - o) / s).round().clamp(0.0, 255.0) as u32;
            plane(o, q(lo), s) <= lo && hi <= plane(o, q(hi), s)
        };
        let lost = cases
            .iter()
            .filter(|b| {
                let (lo, hi): ([f32; WIDTH], [f32; WIDTH]) = (b.map(|p| p[0]), b.map(|p| p[1]));
                let a = Axis::quantize(lo, hi, WIDTH);
                (0..WIDTH).any(|l| !nearest(lo[l], hi[l], a.origin, scale(a.exponent)))
            })
            .count();
        assert!(lost > cases.len() / 2, "rounding to nearest lost only {lost} of {} nodes' boxes", cases.len());
    }
}
