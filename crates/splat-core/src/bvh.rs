//! Bounding volume hierarchy over particle boxes: binned SAH build, flattened nodes (the
//! layout the GPU traverses too), and a stack traversal that visits children front to back and
//! lets the caller shrink t_max, so that an accepted hit clips the rest of the ray.

use crate::hit::Ray;
use crate::particle::Aabb;
use glam::{Vec3, Vec3A};

/// Largest number of primitives in a leaf.
pub const MAX_LEAF: u32 = 4;
/// Bins per axis of the SAH sweep.
const BINS: usize = 16;
/// Cost of visiting a node relative to testing one primitive.
const TRAVERSAL_COST: f32 = 1.0;
/// Depth of the traversal stack; a SAH tree over 2³² primitives stays far below it.
pub const STACK_DEPTH: usize = 64;

/// One node, 32 bytes. A leaf (`count > 0`) holds primitives `first..first + count` of
/// [`Bvh::order`]; an interior node (`count == 0`) has children `first` and `first + 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhNode {
    /// Lower corner of the node's box.
    pub min: [f32; 3],
    /// First primitive (leaf) or left child (interior).
    pub first: u32,
    /// Upper corner of the node's box.
    pub max: [f32; 3],
    /// Number of primitives; 0 for an interior node.
    pub count: u32,
}

impl BvhNode {
    #[cfg(test)]
    fn aabb(&self) -> Aabb {
        Aabb { min: Vec3::from(self.min), max: Vec3::from(self.max) }
    }

    /// Entry distance of the ray into this node's box within (t_min, t_max].
    #[inline(always)]
    fn enter(&self, origin: Vec3A, inv: Vec3A, t_min: f32, t_max: f32) -> Option<f32> {
        slab(Vec3A::from_array(self.min), Vec3A::from_array(self.max), origin, inv, t_min, t_max)
    }
}

/// A flattened BVH: nodes (root first) and the primitive order of its leaves.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bvh {
    /// Nodes, root at 0.
    pub nodes: Vec<BvhNode>,
    /// Leaf order: `order[k]` is the index of the k-th primitive in the caller's array.
    pub order: Vec<u32>,
}

fn area(b: &Aabb) -> f32 {
    let e = (b.max - b.min).max(Vec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

impl Bvh {
    /// Build over `boxes` with a binned surface area heuristic. Deterministic.
    pub fn build(boxes: &[Aabb]) -> Self {
        let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * boxes.len().max(1));
        nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
        let centroids: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        let mut stack = vec![(0usize, 0usize, boxes.len())];
        while let Some((node, start, end)) = stack.pop() {
            let bounds = order[start..end].iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
            let split = split_point(&mut order[start..end], boxes, &centroids, &bounds);
            let n = &mut nodes[node];
            n.min = bounds.min.to_array();
            n.max = bounds.max.to_array();
            match split {
                None => {
                    n.first = start as u32;
                    n.count = (end - start) as u32;
                }
                Some(mid) => {
                    let left = nodes.len();
                    nodes[node].first = left as u32;
                    nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
                    nodes.push(BvhNode { min: [0.0; 3], first: 0, max: [0.0; 3], count: 0 });
                    stack.push((left + 1, start + mid, end));
                    stack.push((left, start, start + mid));
                }
            }
        }
        if boxes.is_empty() {
            nodes[0].min = [f32::INFINITY; 3];
            nodes[0].max = [f32::NEG_INFINITY; 3];
        }
        Self { nodes, order }
    }

    /// Visit every leaf primitive whose node box the ray overlaps within (t_min, t_max],
    /// nearer child first. `visit(k, t_max)` receives the leaf-order index k and may lower
    /// `t_max`; nodes entered beyond the current t_max are skipped.
    #[inline]
    pub fn traverse(&self, ray: &Ray, t_max: &mut f32, mut visit: impl FnMut(u32, &mut f32)) {
        if self.order.is_empty() {
            return;
        }
        // Zero direction components become ±1e-30 so that 1/d is finite and no 0 × ∞ = NaN can
        // make a slab test drop a box the ray touches.
        let d = Vec3A::from(ray.dir);
        let tiny = Vec3A::splat(1e-30).copysign(d);
        let inv = Vec3A::select(d.abs().cmplt(Vec3A::splat(1e-30)), tiny, d).recip();
        let origin = Vec3A::from(ray.origin);
        let mut stack = [0u32; STACK_DEPTH];
        let mut top = 0usize;
        let mut node = 0u32;
        if self.nodes[0].enter(origin, inv, ray.t_min, *t_max).is_none() {
            return;
        }
        loop {
            let n = &self.nodes[node as usize];
            if n.count > 0 {
                for k in n.first..n.first + n.count {
                    visit(k, t_max);
                }
            } else {
                let (a, b) = (n.first, n.first + 1);
                let ta = self.nodes[a as usize].enter(origin, inv, ray.t_min, *t_max);
                let tb = self.nodes[b as usize].enter(origin, inv, ray.t_min, *t_max);
                match (ta, tb) {
                    (Some(ta), Some(tb)) => {
                        let (near, far) = if ta <= tb { (a, b) } else { (b, a) };
                        stack[top] = far;
                        top += 1;
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = a;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = b;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next node that is still in front of t_max.
            loop {
                if top == 0 {
                    return;
                }
                top -= 1;
                let candidate = stack[top];
                if self.nodes[candidate as usize].enter(origin, inv, ray.t_min, *t_max).is_some() {
                    node = candidate;
                    break;
                }
            }
        }
    }
}

/// Entry distance of the ray into the box if the box overlaps (t_min, t_max]; ties at
/// t_max are kept so that callers can break equal distances by index. SIMD (`Vec3A`).
#[inline(always)]
fn slab(min: Vec3A, max: Vec3A, origin: Vec3A, inv: Vec3A, t_min: f32, t_max: f32) -> Option<f32> {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    // NaN (0 × ∞ on a slab plane) is ignored by min/max, which keeps the test conservative.
    let enter = t0.min(t1).max_element().max(t_min);
    let exit = t0.max(t1).min_element().min(t_max);
    (enter <= exit).then_some(enter)
}

/// Choose a split of `order` (reordering it) or `None` for a leaf.
fn split_point(order: &mut [u32], boxes: &[Aabb], centroids: &[Vec3], bounds: &Aabb) -> Option<usize> {
    let n = order.len();
    if n <= 1 {
        return None;
    }
    let cb = order
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.union(Aabb { min: centroids[i as usize], max: centroids[i as usize] }));
    let extent = cb.max - cb.min;
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bin boundary)
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |i: u32| (((centroids[i as usize][axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
        let mut counts = [0usize; BINS];
        let mut bin_boxes = [Aabb::EMPTY; BINS];
        for &i in order.iter() {
            let b = bin_of(i);
            counts[b] += 1;
            bin_boxes[b] = bin_boxes[b].union(boxes[i as usize]);
        }
        let mut right_area = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        for b in (1..BINS).rev() {
            acc = acc.union(bin_boxes[b]);
            right_area[b] = area(&acc);
        }
        let (mut left, mut left_count) = (Aabb::EMPTY, 0usize);
        for b in 1..BINS {
            left = left.union(bin_boxes[b - 1]);
            left_count += counts[b - 1];
            let right_count = n - left_count;
            if left_count == 0 || right_count == 0 {
                continue;
            }
            let cost = area(&left) * left_count as f32 + right_area[b] * right_count as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let parent_area = area(bounds).max(f32::MIN_POSITIVE);
    match best {
        Some((cost, axis, boundary)) if TRAVERSAL_COST + cost / parent_area < n as f32 || n > MAX_LEAF as usize => {
            let scale = BINS as f32 / extent[axis];
            let goes_left =
                |i: &u32| ((((centroids[*i as usize][axis] - cb.min[axis]) * scale) as usize).min(BINS - 1)) < boundary;
            let mid = partition(order, goes_left);
            Some(mid)
        }
        Some(_) => None,
        // All centroids coincide: split by count when the leaf would be too large.
        None if n > MAX_LEAF as usize => Some(n / 2),
        None => None,
    }
}

/// Stable partition: elements satisfying `pred` first; returns their count.
fn partition(order: &mut [u32], pred: impl Fn(&u32) -> bool) -> usize {
    let (left, right): (Vec<u32>, Vec<u32>) = order.iter().partition(|i| pred(i));
    let mid = left.len();
    order[..mid].copy_from_slice(&left);
    order[mid..].copy_from_slice(&right);
    mid
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn random_boxes(n: usize, seed: u64) -> Vec<Aabb> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| {
                let c = Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0));
                let h = Vec3::new(rng.range(0.01, 0.5), rng.range(0.01, 0.5), rng.range(0.01, 0.5));
                Aabb { min: c - h, max: c + h }
            })
            .collect()
    }

    #[test]
    fn every_primitive_is_in_exactly_one_leaf_inside_its_ancestors() {
        let boxes = random_boxes(2000, 3);
        let bvh = Bvh::build(&boxes);
        let mut seen = vec![0u32; boxes.len()];
        let mut stack = vec![(0usize, Aabb::EMPTY, true)];
        while let Some((i, parent, is_root)) = stack.pop() {
            let n = bvh.nodes[i];
            let b = n.aabb();
            if !is_root {
                assert!(parent.min.cmple(b.min).all() && parent.max.cmpge(b.max).all());
            }
            if n.count > 0 {
                assert!(n.count <= MAX_LEAF);
                for k in n.first..n.first + n.count {
                    let p = bvh.order[k as usize] as usize;
                    seen[p] += 1;
                    assert!(b.min.cmple(boxes[p].min).all() && b.max.cmpge(boxes[p].max).all());
                }
            } else {
                stack.push((n.first as usize, b, false));
                stack.push((n.first as usize + 1, b, false));
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }

    #[test]
    fn traversal_finds_every_box_the_ray_crosses() {
        let boxes = random_boxes(3000, 9);
        let bvh = Bvh::build(&boxes);
        let mut rng = SplitMix64::new(11);
        for _ in 0..200 {
            let o = Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize();
            let ray = Ray::new(o, d);
            let mut found = Vec::new();
            bvh.traverse(&ray, &mut ray.t_max.clone(), |k, _| found.push(bvh.order[k as usize]));
            found.sort_unstable();
            let len = found.len();
            found.dedup();
            assert_eq!(found.len(), len, "a primitive was visited twice");
            // Conservative: every box the ray crosses is visited (leaf-mates may come along).
            for (i, b) in boxes.iter().enumerate() {
                if slab(b.min.into(), b.max.into(), o.into(), d.recip().into(), ray.t_min, ray.t_max).is_some() {
                    assert!(found.binary_search(&(i as u32)).is_ok(), "box {i} missed");
                }
            }
        }
    }

    #[test]
    fn axis_aligned_rays_on_box_planes_are_not_lost() {
        // Origin exactly on the slab planes x = 0 and y = 0 with zero x and y direction.
        let boxes = vec![Aabb { min: Vec3::new(0.0, 0.0, 2.0), max: Vec3::new(1.0, 1.0, 3.0) }; 9];
        let bvh = Bvh::build(&boxes);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z);
        let mut count = 0;
        bvh.traverse(&ray, &mut ray.t_max.clone(), |_, _| count += 1);
        assert_eq!(count, 9);
    }

    #[test]
    fn identical_centroids_still_make_small_leaves() {
        let boxes = vec![Aabb { min: Vec3::ZERO, max: Vec3::ONE }; 100];
        let bvh = Bvh::build(&boxes);
        assert!(bvh.nodes.iter().all(|n| n.count <= MAX_LEAF));
        assert_eq!(Bvh::build(&[]).order.len(), 0);
    }
}
