//! The 4-wide BVH the CPU traverses: the binary tree of [`Bvh`] collapsed so that every node
//! holds up to four children, their boxes stored as SIMD lanes (structure of arrays) and tested
//! against the ray together (Wald et al. 2008, "Getting rid of packets"; Dammertz et al. 2008,
//! "Shallow bounding volume hierarchies"). It is a conversion of the same tree: the same leaves
//! over the same leaf order. Both backends walk it: [`Bvh4::traverse`] on the CPU and its twin
//! `traversal_next_leaf` in splat-gpu's `shaders/bvh.wgsl`, which uploads these nodes with
//! their planes quantized to a byte and rounded outward (`splat_gpu::node::GpuNode`), so that
//! it reaches the same leaves and a few more, in nearly the same order.

use super::{Bvh, STACK_DEPTH, inverse_direction, slab};
use crate::hit::Ray;
use crate::particle::Aabb;
use glam::{Vec3A, Vec4};

/// Lanes of a wide node.
const WIDTH: usize = 4;
/// A child reference that is a leaf: this bit, the count − 1 in the next two bits, then the
/// first leaf-order primitive. A reference without it is a node's index.
pub const LEAF: u32 = 1 << 31;
/// Where a leaf reference's count − 1 starts.
pub const COUNT_SHIFT: u32 = 29;
/// The node every traversal starts from: a node of one lane, the whole tree's box, whose child
/// is the root (a leaf when the whole scene fits in one); with no lane for no primitives.
pub const ROOT: u32 = 0;
/// Largest leaf-order index a leaf reference can hold.
pub const MAX_PRIMITIVES: usize = 1 << COUNT_SHIFT;
/// Entries of a traversal stack: each popped node pushes at most `WIDTH` entries and removes
/// itself, so the stack grows by at most WIDTH − 1 per level of the binary tree, whose depth
/// [`STACK_DEPTH`] bounds, and by one for the [`ROOT`] node above it.
pub const WIDE_STACK: usize = (WIDTH - 1) * (STACK_DEPTH + 1) + 1;

/// One wide node, 128 bytes: the bounding planes of the four children as lanes, `planes[axis][0]`
/// the lower and `planes[axis][1]` the upper (so that a ray picks its near and far plane per axis
/// by a 0/1 index); empty lanes are masked off by `count`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct Node4 {
    planes: [[Vec4; 2]; 3],
    child: [u32; WIDTH],
    count: u32,
}

impl Node4 {
    /// A node with no children.
    const EMPTY: Node4 = Node4 { planes: [[Vec4::INFINITY, Vec4::NEG_INFINITY]; 3], child: [0; WIDTH], count: 0 };

    /// The children's bounding planes, `[axis][lower, upper][lane]` (empty lanes: +∞ below −∞).
    pub fn planes(&self) -> [[[f32; WIDTH]; 2]; 3] {
        self.planes.map(|axis| axis.map(|v| v.to_array()))
    }

    /// The children's references: a node's index, or a leaf ([`LEAF`] set); 0 in empty lanes.
    pub fn children(&self) -> [u32; WIDTH] {
        self.child
    }

    /// Lanes in use, 1 to 4 (0 only for the root of an empty tree).
    pub fn count(&self) -> u32 {
        self.count
    }

    /// Set lane `lane` to a child of box `min`–`max` and reference `r`.
    fn set(&mut self, lane: usize, min: [f32; 3], max: [f32; 3], r: u32) {
        for axis in 0..3 {
            self.planes[axis][0][lane] = min[axis];
            self.planes[axis][1][lane] = max[axis];
        }
        self.child[lane] = r;
    }
}

/// Bytes of a wide node.
pub(super) const NODE_BYTES: usize = std::mem::size_of::<Node4>();

/// A 4-wide BVH over the leaf order of a [`Bvh`]: node [`ROOT`] holds the root's box, the
/// others follow in depth-first order.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh4 {
    nodes: Vec<Node4>,
}

impl Default for Bvh4 {
    fn default() -> Self {
        Self { nodes: vec![Node4::EMPTY] }
    }
}

fn leaf_ref(first: u32, count: u32) -> u32 {
    debug_assert!((1..=super::MAX_LEAF).contains(&count) && (first as usize) < MAX_PRIMITIVES);
    LEAF | ((count - 1) << COUNT_SHIFT) | first
}

/// Leaf-order range of a leaf reference.
#[inline(always)]
fn leaf_range(r: u32) -> std::ops::Range<u32> {
    let first = r & (MAX_PRIMITIVES as u32 - 1);
    let count = ((r & !LEAF) >> COUNT_SHIFT) + 1;
    first..first + count
}

/// The binary nodes a wide node over binary interior node `b` takes as its children, in order:
/// `b`'s two children, the interior one of largest surface area (the first of equal ones)
/// replaced by its own two until there are four or none is interior.
fn wide_children(bvh: &Bvh, b: usize) -> ([usize; WIDTH], usize) {
    let first = bvh.nodes[b].first as usize;
    let (mut children, mut count) = ([first, first + 1, 0, 0], 2);
    while count < WIDTH {
        let mut widest: Option<(usize, f32)> = None;
        for (k, &c) in children[..count].iter().enumerate() {
            let area = super::node_area(&bvh.nodes[c]);
            if bvh.nodes[c].count == 0 && widest.is_none_or(|(_, a)| area > a) {
                widest = Some((k, area));
            }
        }
        let Some((k, _)) = widest else { break };
        let first = bvh.nodes[children[k]].first as usize;
        children.copy_within(k + 1..count, k + 2);
        children[k] = first;
        children[k + 1] = first + 1;
        count += 1;
    }
    (children, count)
}

impl Bvh4 {
    /// Collapse a binary BVH: every wide node takes its binary node's two children and keeps
    /// opening the interior child with the largest surface area until it has four. Leaves hold
    /// at most [`super::MAX_LEAF`] = 4 primitives and at most [`MAX_PRIMITIVES`] of them.
    pub fn from_binary(bvh: &Bvh) -> Self {
        assert!(bvh.order.len() <= MAX_PRIMITIVES, "a wide BVH holds at most {MAX_PRIMITIVES} primitives");
        if bvh.order.is_empty() {
            return Self::default();
        }
        let root = bvh.nodes[0];
        let mut wide = Self { nodes: Vec::with_capacity(bvh.nodes.len() / 3 + 2) };
        wide.nodes.push(Node4 { count: 1, ..Node4::EMPTY });
        let r = if root.count > 0 { leaf_ref(root.first, root.count) } else { wide.collapse(bvh, 0) };
        wide.nodes[ROOT as usize].set(0, root.min, root.max, r);
        wide
    }

    /// Build the binary tree over `what` of `boxes` (dropped once built), refuse it when it
    /// is deeper than the traversals' stacks hold, and collapse it: the wide tree and its leaf
    /// order (`order[k]`, the index in `boxes` of the k-th leaf primitive). The binary nodes
    /// are only the build's and are dropped here, before the caller lays anything out.
    pub fn build(boxes: Vec<Aabb>, what: &str) -> Result<(Self, Vec<u32>), String> {
        let binary = Bvh::build(&boxes);
        drop(boxes);
        binary.check_depth(what)?;
        Ok((Self::from_binary(&binary), binary.order))
    }

    /// The wide node for binary interior node `b`, its subtree after it; returns its index.
    fn collapse(&mut self, bvh: &Bvh, b: usize) -> u32 {
        let (children, count) = wide_children(bvh, b);
        let index = self.nodes.len();
        self.nodes.push(Node4 { count: count as u32, ..Node4::EMPTY });
        for (lane, &c) in children[..count].iter().enumerate() {
            let n = bvh.nodes[c];
            let r = if n.count > 0 { leaf_ref(n.first, n.count) } else { self.collapse(bvh, c) };
            self.nodes[index].set(lane, n.min, n.max, r);
        }
        index as u32
    }

    /// Number of wide nodes, [`ROOT`] included.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the tree holds no primitives.
    pub fn is_empty(&self) -> bool {
        self.nodes[ROOT as usize].count == 0
    }

    /// The nodes, [`ROOT`] first.
    pub fn nodes(&self) -> &[Node4] {
        &self.nodes
    }

    /// Bytes of the wide nodes.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node4>()
    }

    /// Visit every leaf primitive whose node boxes the ray overlaps within (t_min, t_max],
    /// nearer children first (in the order of entry distance, then lane): `visit(k, t_max)`
    /// receives the leaf-order index k and may lower t_max, and nodes entered beyond it are
    /// skipped (the binary tree's walk, the test reference, keeps the same contract); four
    /// boxes tested per step, and the stack keeps each entry's distance so that a popped node
    /// is culled without a new test. Counts its work into the thread's [`super::work`]
    /// counters, [`ROOT`] among the nodes (tested here as one box, the GPU tests it as a node).
    #[inline]
    pub fn traverse(&self, ray: &Ray, t_max: &mut f32, mut visit: impl FnMut(u32, &mut f32)) {
        let inv = inverse_direction(ray.dir);
        let root = &self.nodes[ROOT as usize];
        let [lo, hi] =
            [0, 1].map(|side| Vec3A::new(root.planes[0][side].x, root.planes[1][side].x, root.planes[2][side].x));
        if root.count == 0 || slab(lo, hi, Vec3A::from(ray.origin), inv, ray.t_min, *t_max).is_none() {
            return super::work::record(1, 0, 0);
        }
        let (ox, oy, oz) = (Vec4::splat(ray.origin.x), Vec4::splat(ray.origin.y), Vec4::splat(ray.origin.z));
        let (ix, iy, iz) = (Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z));
        let t_min = Vec4::splat(ray.t_min);
        // Each axis's near plane is the lower one (0) where the ray goes up the axis, else the
        // upper one (1); the far plane is the other.
        let near = [inv.x, inv.y, inv.z].map(|i| usize::from(i < 0.0));
        let mut stack = [(0u32, 0.0f32); WIDE_STACK];
        let mut top = 0usize;
        let mut current = root.child[0];
        let (mut nodes, mut leaves, mut tests) = (1u32, 0u32, 0u32);
        loop {
            if current & LEAF != 0 {
                let range = leaf_range(current);
                leaves += 1;
                tests += range.len() as u32;
                for k in range {
                    visit(k, t_max);
                }
            } else {
                nodes += 1;
                let n = &self.nodes[current as usize];
                // Slab test of the four children: the arithmetic of `super::slab`, with the min
                // and max of each axis's two distances taken by choosing the planes (1/d is
                // finite and non-zero, so its sign orders them).
                let [px, py, pz] = &n.planes;
                let tx = ((px[near[0]] - ox) * ix, (px[near[0] ^ 1] - ox) * ix);
                let ty = ((py[near[1]] - oy) * iy, (py[near[1] ^ 1] - oy) * iy);
                let tz = ((pz[near[2]] - oz) * iz, (pz[near[2] ^ 1] - oz) * iz);
                let enter = tx.0.max(ty.0).max(tz.0).max(t_min);
                let exit = tx.1.min(ty.1).min(tz.1).min(Vec4::splat(*t_max));
                let mask = enter.cmple(exit).bitmask() & ((1 << n.count) - 1);
                if mask != 0 {
                    // Go on with the nearest child; push the others far to near. (Lanes are
                    // read from an array: glam's `Vec4` indexing is a jump table.)
                    let enter = enter.to_array();
                    let lane = mask.trailing_zeros() as usize;
                    let mut nearest = (n.child[lane], enter[lane]);
                    let mut rest = mask & (mask - 1);
                    let base = top;
                    while rest != 0 {
                        let lane = rest.trailing_zeros() as usize;
                        rest &= rest - 1;
                        let mut entry = (n.child[lane], enter[lane]);
                        if entry.1 < nearest.1 {
                            std::mem::swap(&mut entry, &mut nearest);
                        }
                        // Entries as near as this one but of lower lanes stay above it: the
                        // children are visited in the order of (entry distance, lane), as the
                        // GPU's sorting network orders them.
                        let mut i = top;
                        while i > base && stack[i - 1].1 <= entry.1 {
                            stack[i] = stack[i - 1];
                            i -= 1;
                        }
                        stack[i] = entry;
                        top += 1;
                    }
                    current = nearest.0;
                    continue;
                }
            }
            // Pop the nearest pushed entry still in front of t_max.
            loop {
                if top == 0 {
                    super::work::record(nodes, leaves, tests);
                    return;
                }
                top -= 1;
                if stack[top].1 <= *t_max {
                    current = stack[top].0;
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particle::Aabb;
    use crate::rng::SplitMix64;
    use glam::Vec3;

    /// Flat boxes (thin along z), as flat splats make them.
    fn random_boxes(n: usize, seed: u64) -> Vec<Aabb> {
        super::super::tests::random_boxes(n, seed, (Vec3::splat(0.001), Vec3::new(0.5, 0.5, 0.02)))
    }

    /// The leaf-order indices a traversal visits (sorted) and its final t_max; with `hit`, each
    /// visit lowers t_max to the primitive's hit distance, as a closest-hit search does.
    fn visits(
        traverse: impl FnOnce(&mut f32, &mut dyn FnMut(u32, &mut f32)),
        hit: Option<&dyn Fn(u32) -> f32>,
    ) -> (Vec<u32>, f32) {
        let mut found = Vec::new();
        let mut t_max = 1e4;
        traverse(&mut t_max, &mut |k, t| {
            found.push(k);
            if let Some(hit) = hit {
                *t = t.min(hit(k));
            }
        });
        found.sort_unstable();
        (found, t_max)
    }

    /// The wide tree visits exactly the primitives the binary tree visits for free rays, and
    /// with a closest-hit visitor that clips t_max it visits every primitive whose box the ray
    /// enters before the final t_max (what makes the closest hit exact), each once; on a tree of one
    /// leaf, of a few and of many, with axis-parallel rays among the random ones.
    #[test]
    fn wide_traversal_visits_what_the_binary_traversal_visits() {
        for (n, seed) in [(1, 1), (3, 2), (7, 3), (40, 4), (5000, 5)] {
            let boxes = random_boxes(n, seed);
            let bvh = Bvh::build(&boxes);
            let wide = Bvh4::from_binary(&bvh);
            let mut rng = SplitMix64::new(seed + 100);
            for r in 0..300 {
                let o = Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), rng.range(-8.0, 8.0));
                let mut d = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                if r % 10 == 0 {
                    d.x = 0.0;
                }
                let ray = Ray::new(o, d.normalize());
                let (binary, _) = visits(
                    |t, f| {
                        bvh.traverse(&ray, t, f);
                    },
                    None,
                );
                let (four, _) = visits(|t, f| wide.traverse(&ray, t, f), None);
                assert_eq!(binary, four, "n = {n}, ray {r}");
                // A hit at the distance of the box centre along the ray, when in front.
                let hit = |k: u32| {
                    let t = (boxes[bvh.order[k as usize] as usize].center() - ray.origin).dot(ray.dir);
                    if t > ray.t_min { t } else { f32::INFINITY }
                };
                let (clipped, t_final) = visits(|t, f| wide.traverse(&ray, t, f), Some(&hit));
                assert!(clipped.windows(2).all(|w| w[0] < w[1]), "a primitive visited twice");
                let inv = super::super::inverse_direction(ray.dir);
                for (k, &i) in bvh.order.iter().enumerate() {
                    let b = boxes[i as usize];
                    let entered =
                        super::super::slab(b.min.into(), b.max.into(), ray.origin.into(), inv, ray.t_min, t_final);
                    if entered.is_some() {
                        assert!(clipped.binary_search(&(k as u32)).is_ok(), "n = {n}, ray {r}: box {i} skipped");
                    }
                }
            }
        }
    }

    /// The wide walk reads fewer node bytes than the binary walk the GPU took before it (32 bytes
    /// for each step's node, an interior node's two children and a popped node read again),
    /// for free rays and for closest-hit rays, on flat boxes as splats make them.
    #[test]
    fn the_wide_walk_reads_fewer_node_bytes_than_the_binary_walk() {
        let boxes = random_boxes(20_000, 21);
        let bvh = Bvh::build(&boxes);
        let wide = Bvh4::from_binary(&bvh);
        let mut rng = SplitMix64::new(22);
        let (mut binary, mut four) = ([0u64; 2], [0u64; 2]);
        let _ = super::super::work::take();
        for _ in 0..500 {
            let o = Vec3::new(rng.range(-8.0, 8.0), rng.range(-8.0, 8.0), -9.0);
            let ray = Ray::new(o, (Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), 0.0) - o).normalize());
            let hit =
                |k: u32, t: &mut f32| *t = t.min((boxes[bvh.order[k as usize] as usize].center() - o).dot(ray.dir));
            for (closest, counts) in [(false, 0), (true, 1)] {
                let visit = |k: u32, t: &mut f32| {
                    if closest {
                        hit(k, t)
                    }
                };
                binary[counts] += u64::from(bvh.traverse(&ray, &mut 1e4, visit).1) * 32;
                wide.traverse(&ray, &mut 1e4, visit);
                four[counts] += super::super::work::take().bytes(0);
            }
        }
        for k in 0..2 {
            assert!(four[k] < binary[k], "node bytes: wide {} against binary {}", four[k], binary[k]);
        }
        eprintln!(
            "node bytes, wide / binary: free {:.2}, closest hit {:.2}",
            four[0] as f64 / binary[0] as f64,
            four[1] as f64 / binary[1] as f64
        );
    }

    /// A traversal adds itself, its nodes, its leaves and every primitive it visits to the
    /// thread's work counters, once; a ray that misses the root box counts a traversal and the
    /// root node alone.
    #[test]
    fn traversals_count_their_work() {
        let boxes = random_boxes(5000, 9);
        let wide = Bvh4::from_binary(&Bvh::build(&boxes));
        let _ = super::super::work::take();
        let ray = Ray::new(Vec3::new(0.1, 0.2, -8.0), Vec3::Z);
        let mut visited = 0u64;
        wide.traverse(&ray, &mut 1e4, |_, _| visited += 1);
        let work = super::super::work::take();
        assert_eq!((work.traversals, work.tests), (1, visited), "{work:?}");
        assert!(visited > 0 && work.leaves >= 1 && work.leaves <= visited && work.nodes >= 1, "{work:?}");
        assert!(work.nodes < wide.len() as u64, "a ray tests a few of {} nodes: {work:?}", wide.len());
        let away = Ray::new(Vec3::new(50.0, 50.0, 50.0), Vec3::X);
        wide.traverse(&away, &mut 1e4, |_, _| panic!("a ray away from the boxes visits nothing"));
        let missed = super::super::work::Work { traversals: 1, nodes: 1, ..Default::default() };
        assert_eq!(super::super::work::take(), missed);
        assert_eq!(super::super::work::take(), super::super::work::Work::default());
    }

    #[test]
    fn leaf_references_round_trip() {
        for (first, count) in [(0, 1), (12345, 4), (MAX_PRIMITIVES as u32 - 1, 2)] {
            let r = leaf_ref(first, count);
            assert!(r & LEAF != 0);
            assert_eq!(leaf_range(r), first..first + count);
        }
        assert!(Bvh4::from_binary(&Bvh::build(&[])).is_empty());
    }
}
