//! Binned SAH build (Wald 2007, "On fast construction of SAH-based bounding volume
//! hierarchies"), parallel over subtrees with rayon: the two halves of every split large enough
//! are built on separate threads, and the largest splits also bin their primitives in parallel
//! chunks. Every decision depends only on the boxes, never on the thread count, so the tree is
//! the same on one thread or many.

use super::{BvhNode, MAX_LEAF};
use crate::par::{join, map};
use crate::particle::Aabb;
use glam::Vec3A;

/// Bins per axis of the SAH sweep (a node of n < 16 primitives uses n).
const BINS: usize = 16;
/// Cost of visiting a node relative to testing one primitive.
const TRAVERSAL_COST: f32 = 1.0;
/// Subtrees with at least this many primitives build their two halves in parallel.
const PARALLEL_SUBTREE: usize = 4096;
/// Splits over at least this many primitives bin them in parallel chunks of this size.
const PARALLEL_BINNING: usize = 32 * 1024;

/// A subtree before flattening: the parallel recursion returns these, and [`flatten`] lays them
/// out with siblings adjacent (the layout of [`super::Bvh::nodes`]).
enum Tree {
    Leaf { bounds: Box3, first: u32, count: u32 },
    Inner { bounds: Box3, children: Box<[Tree; 2]> },
}

impl Tree {
    fn node(&self) -> BvhNode {
        match *self {
            Tree::Leaf { bounds, first, count } => {
                let b = bounds.aabb();
                BvhNode { min: b.min.to_array(), first, max: b.max.to_array(), count }
            }
            Tree::Inner { bounds, .. } => {
                let b = bounds.aabb();
                BvhNode { min: b.min.to_array(), first: 0, max: b.max.to_array(), count: 0 }
            }
        }
    }
}

/// A box as two SIMD corners (the build's working form of [`Aabb`]).
#[derive(Clone, Copy)]
struct Box3 {
    min: Vec3A,
    max: Vec3A,
}

impl Box3 {
    const EMPTY: Box3 = Box3 { min: Vec3A::INFINITY, max: Vec3A::NEG_INFINITY };

    #[inline(always)]
    fn union(self, o: Box3) -> Box3 {
        Box3 { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    #[inline(always)]
    fn grow(self, p: Vec3A) -> Box3 {
        Box3 { min: self.min.min(p), max: self.max.max(p) }
    }

    fn aabb(self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }

    /// Half the surface area (the SAH's measure).
    fn area(&self) -> f32 {
        let e = (self.max - self.min).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// A primitive reference, 32 bytes: its box and its index. The build partitions these records
/// themselves, not indices into the boxes, so that every pass reads memory in order.
#[derive(Clone, Copy)]
struct PrimRef {
    min: [f32; 3],
    id: u32,
    max: [f32; 3],
}

impl PrimRef {
    #[inline(always)]
    fn bounds(&self) -> Box3 {
        Box3 { min: Vec3A::from_array(self.min), max: Vec3A::from_array(self.max) }
    }

    /// The centroid, as [`Aabb::center`] computes it.
    #[inline(always)]
    fn centroid(&self) -> Vec3A {
        0.5 * (Vec3A::from_array(self.min) + Vec3A::from_array(self.max))
    }
}

/// Build the flattened nodes and the leaf order over `boxes`.
pub(super) fn build(boxes: &[Aabb]) -> (Vec<BvhNode>, Vec<u32>) {
    if boxes.is_empty() {
        let empty = BvhNode { min: [f32::INFINITY; 3], first: 0, max: [f32::NEG_INFINITY; 3], count: 0 };
        return (vec![empty], Vec::new());
    }
    let ids: Vec<u32> = (0..boxes.len() as u32).collect();
    let mut refs = map(&ids, |&i| {
        let b = &boxes[i as usize];
        PrimRef { min: b.min.to_array(), id: i, max: b.max.to_array() }
    });
    let tree = subtree(&mut refs, 0);
    (flatten(&tree, boxes.len()), refs.iter().map(|r| r.id).collect())
}

/// The subtree over `refs` (reordered in place), whose first primitive sits at `offset` of the
/// whole leaf order.
fn subtree(refs: &mut [PrimRef], offset: usize) -> Tree {
    let b = bounds(refs);
    let n = refs.len();
    match split_point(refs, &b) {
        None => Tree::Leaf { bounds: b.bounds, first: offset as u32, count: n as u32 },
        Some(mid) => {
            let (left, right) = refs.split_at_mut(mid);
            let children = if n >= PARALLEL_SUBTREE {
                join(|| subtree(left, offset), || subtree(right, offset + mid))
            } else {
                (subtree(left, offset), subtree(right, offset + mid))
            };
            Tree::Inner { bounds: b.bounds, children: Box::new([children.0, children.1]) }
        }
    }
}

/// Lay the tree out as the node array: root at 0, the two children of every interior node at
/// `first` and `first + 1`, pairs allocated in depth-first order (left subtree first).
fn flatten(tree: &Tree, primitives: usize) -> Vec<BvhNode> {
    let mut nodes = Vec::with_capacity(2 * primitives);
    nodes.push(tree.node());
    let mut stack = vec![(tree, 0usize)];
    while let Some((t, index)) = stack.pop() {
        if let Tree::Inner { children, .. } = t {
            let first = nodes.len();
            nodes[index].first = first as u32;
            nodes.push(children[0].node());
            nodes.push(children[1].node());
            stack.push((&children[1], first + 1));
            stack.push((&children[0], first));
        }
    }
    nodes
}

/// A node's box and the box of its primitives' centroids.
#[derive(Clone, Copy)]
struct Bounds {
    bounds: Box3,
    centroids: Box3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds { bounds: Box3::EMPTY, centroids: Box3::EMPTY };

    fn merge(self, o: &Bounds) -> Bounds {
        Bounds { bounds: self.bounds.union(o.bounds), centroids: self.centroids.union(o.centroids) }
    }
}

/// Per-axis bins of a node's primitives by centroid.
#[derive(Clone, Copy)]
struct Bins {
    counts: [[u32; BINS]; 3],
    boxes: [[Box3; BINS]; 3],
}

impl Bins {
    const EMPTY: Bins = Bins { counts: [[0; BINS]; 3], boxes: [[Box3::EMPTY; BINS]; 3] };

    fn merge(mut self, other: &Bins) -> Bins {
        for axis in 0..3 {
            for b in 0..BINS {
                self.counts[axis][b] += other.counts[axis][b];
                self.boxes[axis][b] = self.boxes[axis][b].union(other.boxes[axis][b]);
            }
        }
        self
    }
}

/// The bin of a centroid along one axis of the centroid box, of `k` bins.
#[inline(always)]
fn bin_index(c: f32, lo: f32, scale: f32, k: usize) -> usize {
    (((c - lo) * scale) as usize).min(k - 1)
}

/// The node's bounds over `refs` (in parallel chunks for the largest nodes, merged in chunk
/// order so that the result is the same on any thread count: unions are exact).
fn bounds(refs: &[PrimRef]) -> Bounds {
    reduce_chunks(refs, Bounds::EMPTY, Bounds::merge, |chunk| {
        chunk.iter().fold(Bounds::EMPTY, |b, r| Bounds {
            bounds: b.bounds.union(r.bounds()),
            centroids: b.centroids.grow(r.centroid()),
        })
    })
}

/// Per-axis bins, `k` of them, over the centroid box `cb` (chunked like [`bounds`]; integer
/// sums are exact).
fn bin(refs: &[PrimRef], cb: &Box3, k: usize) -> Bins {
    let scale = Vec3A::splat(k as f32) / (cb.max - cb.min);
    let extent = cb.max - cb.min;
    let axes = [0, 1, 2].map(|a| extent[a] > 0.0);
    let fill = |chunk: &[PrimRef]| {
        let mut b = Bins::EMPTY;
        for r in chunk {
            let (c, bx) = (r.centroid(), r.bounds());
            for axis in (0..3).filter(|&a| axes[a]) {
                let i = bin_index(c[axis], cb.min[axis], scale[axis], k);
                b.counts[axis][i] += 1;
                b.boxes[axis][i] = b.boxes[axis][i].union(bx);
            }
        }
        b
    };
    reduce_chunks(refs, Bins::EMPTY, |a, b| a.merge(b), fill)
}

/// `f` over the whole slice, or over chunks (in parallel with rayon) merged in order.
fn reduce_chunks<T: Send + Sync + Copy>(
    refs: &[PrimRef],
    empty: T,
    merge: impl Fn(T, &T) -> T,
    f: impl Fn(&[PrimRef]) -> T + Sync + Send,
) -> T {
    if refs.len() < PARALLEL_BINNING {
        return f(refs);
    }
    let chunks: Vec<&[PrimRef]> = refs.chunks(PARALLEL_BINNING).collect();
    map(&chunks, |c| f(c)).iter().fold(empty, merge)
}

/// Choose a split of `order` (partitioning it in place) or `None` for a leaf.
fn split_point(refs: &mut [PrimRef], node: &Bounds) -> Option<usize> {
    let n = refs.len();
    if n <= 1 {
        return None;
    }
    let cb = node.centroids;
    let k = n.min(BINS);
    let bins = bin(refs, &cb, k);
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bin boundary)
    for axis in 0..3 {
        let (counts, boxes) = (&bins.counts[axis], &bins.boxes[axis]);
        let mut right_area = [0.0f32; BINS];
        let mut acc = Box3::EMPTY;
        for b in (1..k).rev() {
            acc = acc.union(boxes[b]);
            right_area[b] = acc.area();
        }
        let (mut left, mut left_count) = (Box3::EMPTY, 0usize);
        for b in 1..k {
            left = left.union(boxes[b - 1]);
            left_count += counts[b - 1] as usize;
            let right_count = n - left_count;
            if left_count == 0 || right_count == 0 {
                continue;
            }
            let cost = left.area() * left_count as f32 + right_area[b] * right_count as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let parent_area = node.bounds.area().max(f32::MIN_POSITIVE);
    match best {
        Some((cost, axis, boundary)) if TRAVERSAL_COST + cost / parent_area < n as f32 || n > MAX_LEAF as usize => {
            let scale = k as f32 / (cb.max[axis] - cb.min[axis]);
            let goes_left = |r: &PrimRef| bin_index(r.centroid()[axis], cb.min[axis], scale, k) < boundary;
            // The bins counted both sides non-empty with this very test, so neither side is.
            Some(partition(refs, goes_left))
        }
        Some(_) => None,
        // All centroids coincide: split by count when the leaf would be too large.
        None if n > MAX_LEAF as usize => Some(n / 2),
        None => None,
    }
}

/// In-place partition (Hoare): elements satisfying `pred` first; returns their count.
/// Deterministic, not stable.
fn partition<T>(items: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let (mut i, mut j) = (0, items.len());
    loop {
        while i < j && pred(&items[i]) {
            i += 1;
        }
        while i < j && !pred(&items[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        items.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same tree on one thread and on four, over enough boxes (80 000) that the parallel
    /// subtrees and the chunked binning both run.
    #[cfg(feature = "rayon")]
    #[test]
    fn the_tree_does_not_depend_on_the_thread_count() {
        let mut rng = crate::rng::SplitMix64::new(17);
        let boxes: Vec<Aabb> = (0..80_000)
            .map(|_| {
                let c = glam::Vec3::new(rng.range(-9.0, 9.0), rng.range(-9.0, 9.0), rng.range(-1.0, 1.0));
                let h = glam::Vec3::splat(rng.range(0.001, 0.1));
                Aabb { min: c - h, max: c + h }
            })
            .collect();
        let on =
            |threads| rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| build(&boxes));
        let (one, four) = (on(1), on(4));
        assert!(one.0 == four.0 && one.1 == four.1, "the trees differ");
        assert!(PARALLEL_BINNING < boxes.len() && one.0.len() > 2 * PARALLEL_SUBTREE / MAX_LEAF as usize);
    }

    #[test]
    fn partition_puts_matches_first() {
        let mut v: Vec<u32> = (0..100).rev().collect();
        let mid = partition(&mut v, |x| x % 3 == 0);
        assert_eq!(mid, 34);
        assert!(v[..mid].iter().all(|x| x % 3 == 0) && v[mid..].iter().all(|x| x % 3 != 0));
        let mut sorted = v.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..100).collect::<Vec<_>>());
        assert_eq!(partition(&mut [0u32; 0], |_| true), 0);
    }
}
