//! Bounding volume hierarchy over particle boxes: a parallel binned SAH build ([`Bvh::build`])
//! into flattened binary nodes, their 4-wide collapse that both backends traverse ([`Bvh4`]),
//! and its stack traversal that visits children front to back and lets the caller shrink t_max,
//! so that an accepted hit clips the rest of the ray.

mod build;
mod wide;
pub mod work;

pub use wide::{Bvh4, COUNT_SHIFT, LEAF, MAX_PRIMITIVES, Node4, ROOT, WIDE_STACK};

#[cfg(test)]
use crate::hit::Ray;
use crate::particle::Aabb;
#[cfg(test)]
use glam::Vec3;
use glam::Vec3A;

/// Largest number of primitives in a leaf.
pub const MAX_LEAF: u32 = 4;
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
    #[cfg(test)]
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

/// Half the surface area of a node's box (the SAH's measure).
fn node_area(n: &BvhNode) -> f32 {
    let e = (Vec3A::from_array(n.max) - Vec3A::from_array(n.min)).max(Vec3A::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// 1/d with zero components replaced by ±1e-30, so that 1/d is finite and no 0 × ∞ = NaN can
/// make a slab test drop a box the ray touches.
#[inline(always)]
fn inverse_direction(dir: glam::Vec3) -> Vec3A {
    let d = Vec3A::from(dir);
    let tiny = Vec3A::splat(1e-30).copysign(d);
    Vec3A::select(d.abs().cmplt(Vec3A::splat(1e-30)), tiny, d).recip()
}

impl Bvh {
    /// Build over `boxes` with a binned surface area heuristic, in parallel with the `rayon`
    /// feature. Deterministic: the same tree on any number of threads.
    pub fn build(boxes: &[Aabb]) -> Self {
        let (nodes, order) = build::build(boxes);
        Self { nodes, order }
    }

    /// Levels below the root of the deepest leaf (0 for an empty tree, whose root is a node of
    /// no children).
    fn depth(&self) -> usize {
        if self.order.is_empty() {
            return 0;
        }
        let mut deepest = 0;
        let mut stack = vec![(0usize, 0usize)];
        while let Some((i, d)) = stack.pop() {
            deepest = deepest.max(d);
            let n = &self.nodes[i];
            if n.count == 0 {
                stack.extend([(n.first as usize, d + 1), (n.first as usize + 1, d + 1)]);
            }
        }
        deepest
    }

    /// Refuse a tree deeper than the traversals' stacks hold ([`STACK_DEPTH`] levels, which
    /// [`WIDE_STACK`] entries cover on both backends): a binned SAH tree over f32 boxes stays
    /// well within it (a split peels off at least a bin's worth, and f32 spans about 280
    /// octaves), but a deeper one would overflow the CPU's stack (a panic) and the GPU's (a
    /// wrong image), so it is refused by name instead.
    fn check_depth(&self, what: &str) -> Result<(), String> {
        let depth = self.depth();
        if depth > STACK_DEPTH {
            return Err(format!(
                "the BVH over these {what} is {depth} levels deep, more than the {STACK_DEPTH} its traversals hold: \
                 their positions span too many orders of magnitude; rescale or split the scene"
            ));
        }
        Ok(())
    }

    /// Bytes of the nodes and the leaf order.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<BvhNode>() + self.order.len() * 4
    }

    /// The binary tree's own traversal, the reference [`Bvh4::traverse`] is checked against
    /// (and the walk the GPU took before it walked the wide nodes): every leaf primitive whose
    /// node box the ray overlaps within (t_min, t_max], nearer child first. `visit(k, t_max)`
    /// receives the leaf-order index k and may lower `t_max`; nodes entered beyond the current
    /// t_max are skipped. Returns its loop steps (a node entered or a node popped) and the nodes
    /// it read (each step's node, an interior node's two children, a popped node again).
    #[cfg(test)]
    pub fn traverse(&self, ray: &Ray, t_max: &mut f32, mut visit: impl FnMut(u32, &mut f32)) -> (u32, u32) {
        if self.order.is_empty() {
            return (0, 0);
        }
        let inv = inverse_direction(ray.dir);
        let origin = Vec3A::from(ray.origin);
        let mut stack = [0u32; STACK_DEPTH];
        let mut top = 0usize;
        let mut node = 0u32;
        let (mut steps, mut reads) = (0, 1);
        if self.nodes[0].enter(origin, inv, ray.t_min, *t_max).is_none() {
            return (steps, reads);
        }
        loop {
            steps += 1;
            reads += 1;
            let n = &self.nodes[node as usize];
            if n.count > 0 {
                for k in n.first..n.first + n.count {
                    visit(k, t_max);
                }
            } else {
                reads += 2;
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
                    return (steps, reads);
                }
                steps += 1;
                reads += 1;
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

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// `n` boxes centred in [−5, 5]³ with half-extents drawn in `half.0..half.1` per axis.
    pub(super) fn random_boxes(n: usize, seed: u64, half: (Vec3, Vec3)) -> Vec<Aabb> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| {
                let c = Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0));
                let h = Vec3::new(
                    rng.range(half.0.x, half.1.x),
                    rng.range(half.0.y, half.1.y),
                    rng.range(half.0.z, half.1.z),
                );
                Aabb { min: c - h, max: c + h }
            })
            .collect()
    }

    /// Half-extents of [`random_boxes`] for the binary tree's tests.
    const HALF: (Vec3, Vec3) = (Vec3::splat(0.01), Vec3::splat(0.5));

    #[test]
    fn every_primitive_is_in_exactly_one_leaf_inside_its_ancestors() {
        let boxes = random_boxes(2000, 3, HALF);
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
        let boxes = random_boxes(3000, 9, HALF);
        let bvh = Bvh::build(&boxes);
        let wide = Bvh4::from_binary(&bvh);
        let mut rng = SplitMix64::new(11);
        for _ in 0..200 {
            let o = Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
            let d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize();
            let ray = Ray::new(o, d);
            let mut found = Vec::new();
            wide.traverse(&ray, &mut ray.t_max.clone(), |k, _| found.push(bvh.order[k as usize]));
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
        let wide = Bvh4::from_binary(&Bvh::build(&boxes));
        let ray = Ray::new(Vec3::ZERO, Vec3::Z);
        let mut count = 0;
        wide.traverse(&ray, &mut ray.t_max.clone(), |_, _| count += 1);
        assert_eq!(count, 9);
    }

    /// A tree within the stacks' depth passes; a chain of leaves one level deeper than the
    /// stacks hold is refused by name.
    #[test]
    fn a_tree_deeper_than_the_stacks_is_refused() {
        let bvh = Bvh::build(&random_boxes(3000, 9, HALF));
        assert!(bvh.depth() > 5 && bvh.check_depth("particles").is_ok());
        // Level L holds the pair 2L − 1 (a leaf) and 2L (the next interior node, a leaf at the
        // last level).
        let levels = STACK_DEPTH + 1;
        let mut chain = vec![BvhNode { min: [0.0; 3], first: 1, max: [1.0; 3], count: 0 }];
        for level in 1..=levels {
            let leaf = BvhNode { min: [0.0; 3], first: level as u32 - 1, max: [1.0; 3], count: 1 };
            let last = level == levels;
            let next = BvhNode {
                min: [0.0; 3],
                first: if last { level as u32 } else { chain.len() as u32 + 2 },
                max: [1.0; 3],
                count: u32::from(last),
            };
            chain.extend([leaf, next]);
        }
        let deep = Bvh { nodes: chain, order: (0..=levels as u32).collect() };
        assert_eq!(deep.depth(), levels);
        let refused = deep.check_depth("particles").unwrap_err();
        assert!(refused.contains(&format!("{levels} levels deep")) && refused.contains("particles"), "{refused}");
    }

    #[test]
    fn identical_centroids_still_make_small_leaves() {
        let boxes = vec![Aabb { min: Vec3::ZERO, max: Vec3::ONE }; 100];
        let bvh = Bvh::build(&boxes);
        assert!(bvh.nodes.iter().all(|n| n.count <= MAX_LEAF));
        assert_eq!(Bvh::build(&[]).order.len(), 0);
    }
}
