// The wide BVH's traversal, the twin of crates/splat-core/src/bvh/wide.rs (`Bvh4::traverse`),
// prepended to the kernels that trace rays (trace.wgsl, mesh_prepass.wgsl): a stack traversal
// that yields the leaves a ray overlaps, nearer child first, and lets the caller shrink t_max
// between leaves; the leaf loops are the callers' (trace.wgsl `traverse`, mesh.wgsl
// `mesh_traverse`). It reads `node_at(i)`, and counts loop iterations in `iterations`, both
// declared by the including kernel.

// One wide node (64 bytes), mirrored by splat_gpu::node::GpuNode: splat_core::bvh::Node4
// with the four children's boxes quantized on each axis to bytes q of an origin o and a scale
// s = 2^e, a plane at o + q s (splat_gpu's node.rs says how they are rounded outward):
// origin.xyz the origin's bits, origin.w the biased exponents of x, y, z (bytes 0-2) and the
// lanes in use (byte 3); planes_xy the lanes' lower x, upper x, lower y and upper y, planes_z
// the lower and upper z (lane l in byte l of a word); the children's references (a node's
// index, or a leaf: LEAF set).
struct Node {
    origin: vec4<u32>,
    planes_xy: vec4<u32>,
    planes_z: vec4<u32>,
    child: vec4<u32>,
}

// The four lanes' planes of word `w` on an axis of origin `o` and biased exponent `e`
// (node.rs `GpuNode::planes`): o + q s, where q s is exact, so the sum rounds once whether or
// not the compiler fuses it.
fn node_planes(w: u32, o: u32, e: u32) -> vec4<f32> {
    let q = (vec4<u32>(w) >> vec4<u32>(0u, 8u, 16u, 24u)) & vec4<u32>(255u);
    let s = bitcast<f32>((e & 255u) << 23u);
    return bitcast<f32>(o) + vec4<f32>(q) * s;
}

// bvh/wide.rs: a leaf reference is LEAF, the count − 1 from bit COUNT_SHIFT, then the first
// leaf-order primitive; a tree's walk starts at its ROOT node, of one lane, the tree's box.
// No leaf reference equals NONE: a tree holds at most 2^COUNT_SHIFT primitives.
const LEAF: u32 = 0x80000000u;
const COUNT_SHIFT: u32 = 29u;
const ROOT: u32 = 0u;
const WIDE_STACK: u32 = 196u;
const FAR: f32 = 3.0e38;
// The largest f32: a child the ray misses enters there, in its lane + 4, after every hit.
const MISSED: f32 = 3.40282347e38;

fn leaf_first(r: u32) -> u32 {
    return r & ((1u << COUNT_SHIFT) - 1u);
}

fn leaf_end(r: u32) -> u32 {
    return leaf_first(r) + ((r & ~LEAF) >> COUNT_SHIFT) + 1u;
}

fn safe_inverse(d: vec3<f32>) -> vec3<f32> {
    let tiny = select(vec3<f32>(1e-30), vec3<f32>(-1e-30), d < vec3<f32>(0.0));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(1e-30));
}

// Stack traversal state of the current ray (`Bvh4::traverse`): the pushed references and the
// distances at which the ray enters them, so that a popped one behind t_max is dropped without
// reading its node again; `trav_next` is the reference to go on with (NONE: pop).
var<private> trav_ref: array<u32, WIDE_STACK>;
var<private> trav_t: array<f32, WIDE_STACK>;
var<private> trav_top: u32;
var<private> trav_next: u32;

// Start a traversal at the root node `root`: ROOT for the splats, params.mesh_root for the
// meshes, whose nodes follow the splats' in the same buffer (splat_gpu::layout::nodes).
fn traversal_begin(root: u32) {
    trav_top = 0u;
    trav_next = root;
}

// A child the ray enters: its reference, the distance at which it enters, and its lane (+ 4
// for one it misses).
struct Entry {
    r: u32,
    t: f32,
    lane: u32,
}

// Whether entry a comes before entry b: nearer, or as near and in a lower lane (the order of
// `Bvh4::traverse`).
fn visited_before(a: Entry, b: Entry) -> bool {
    return a.t < b.t || (a.t == b.t && a.lane < b.lane);
}

// Entries a and b in visit order (a compare-exchange of the sorting network).
fn ordered(a: ptr<function, Entry>, b: ptr<function, Entry>) {
    if (visited_before(*b, *a)) {
        let x = *a;
        *a = *b;
        *b = x;
    }
}

fn traversal_push(e: Entry) {
    trav_ref[trav_top] = e.r;
    trav_t[trav_top] = e.t;
    trav_top += 1u;
}

// The next leaf (its reference) whose box the ray overlaps before t_max, nearer child first;
// NONE when the traversal is over. A node's four child boxes are tested at once (the near plane
// of each axis is the lower where the ray goes up the axis: 1/d is finite and non-zero, so its
// sign orders the two distances); of the children the ray enters, the traversal goes on with
// the nearest and pushes the others far to near with their entry distances, sorted by a
// network of five compare-exchanges (misses last), so that no loop or dynamic index
// over the lanes is needed. A popped entry behind the current t_max is dropped, so a caller
// that lowers t_max between leaves clips the rest of the traversal.
fn traversal_next_leaf(origin: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> u32 {
    let down = inv < vec3<f32>(0.0);
    loop {
        iterations += 1u;
        if (trav_next == NONE) {
            if (trav_top == 0u) {
                return NONE;
            }
            trav_top -= 1u;
            if (trav_t[trav_top] <= t_max) {
                trav_next = trav_ref[trav_top];
            }
            continue;
        }
        let r = trav_next;
        trav_next = NONE;
        if ((r & LEAF) != 0u) {
            return r;
        }
        let n = node_at(r);
        let e = n.origin.w;
        let lo_x = node_planes(n.planes_xy.x, n.origin.x, e);
        let hi_x = node_planes(n.planes_xy.y, n.origin.x, e);
        let lo_y = node_planes(n.planes_xy.z, n.origin.y, e >> 8u);
        let hi_y = node_planes(n.planes_xy.w, n.origin.y, e >> 8u);
        let lo_z = node_planes(n.planes_z.x, n.origin.z, e >> 16u);
        let hi_z = node_planes(n.planes_z.y, n.origin.z, e >> 16u);
        let near_x = (select(lo_x, hi_x, down.x) - origin.x) * inv.x;
        let far_x = (select(hi_x, lo_x, down.x) - origin.x) * inv.x;
        let near_y = (select(lo_y, hi_y, down.y) - origin.y) * inv.y;
        let far_y = (select(hi_y, lo_y, down.y) - origin.y) * inv.y;
        let near_z = (select(lo_z, hi_z, down.z) - origin.z) * inv.z;
        let far_z = (select(hi_z, lo_z, down.z) - origin.z) * inv.z;
        let enter = max(max(max(near_x, near_y), near_z), vec4<f32>(t_min));
        let exit = min(min(min(far_x, far_y), far_z), vec4<f32>(t_max));
        let hit = (enter <= exit) & (vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(e >> 24u));
        let t = select(vec4<f32>(MISSED), enter, hit);
        let lane = vec4<u32>(0u, 1u, 2u, 3u) + select(vec4<u32>(4u), vec4<u32>(0u), hit);
        var e0 = Entry(n.child.x, t.x, lane.x);
        var e1 = Entry(n.child.y, t.y, lane.y);
        var e2 = Entry(n.child.z, t.z, lane.z);
        var e3 = Entry(n.child.w, t.w, lane.w);
        ordered(&e0, &e1);
        ordered(&e2, &e3);
        ordered(&e0, &e2);
        ordered(&e1, &e3);
        ordered(&e1, &e2);
        let hits = dot(select(vec4<u32>(0u), vec4<u32>(1u), hit), vec4<u32>(1u));
        if (hits > 3u) {
            traversal_push(e3);
        }
        if (hits > 2u) {
            traversal_push(e2);
        }
        if (hits > 1u) {
            traversal_push(e1);
        }
        if (hits > 0u) {
            trav_next = e0.r;
        }
    }
    return NONE; // unreachable: the loop only ends by returning
}
