// BVH traversal of crates/splat-core/src/bvh.rs (`Bvh::traverse`), prepended to the kernels
// that trace rays (trace.wgsl, mesh_prepass.wgsl): a stack traversal that yields the leaves a
// ray overlaps, nearer child first, and lets the caller shrink t_max between leaves; the leaf
// loops are the callers' (trace.wgsl `traverse`, mesh.wgsl `mesh_traverse`). It reads `node_at(i)`,
// and counts loop iterations in `iterations`, both declared by the including
// kernel.

// One BVH node (32 bytes), mirrored by splat_core::bvh::BvhNode.
struct Node {
    min: vec3<f32>,
    first: u32,
    max: vec3<f32>,
    count: u32,
}

const STACK_DEPTH: u32 = 64u;
const FAR: f32 = 3.0e38;

// Entry distance into the node's box within (t_min, t_max], FAR when the ray misses it.
fn enter(n: Node, origin: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> f32 {
    let t0 = (n.min - origin) * inv;
    let t1 = (n.max - origin) * inv;
    let near = min(t0, t1);
    let far = max(t0, t1);
    let e = max(max(max(near.x, near.y), near.z), t_min);
    let x = min(min(min(far.x, far.y), far.z), t_max);
    return select(FAR, e, e <= x);
}

fn safe_inverse(d: vec3<f32>) -> vec3<f32> {
    let tiny = select(vec3<f32>(1e-30), vec3<f32>(-1e-30), d < vec3<f32>(0.0));
    return 1.0 / select(d, tiny, abs(d) < vec3<f32>(1e-30));
}

// Stack traversal state of the current ray (bvh.rs `Bvh::traverse`).
var<private> trav_stack: array<u32, STACK_DEPTH>;
var<private> trav_top: u32;
var<private> trav_next: u32;

// Start a traversal at node `root`: 0 for the splats, params.mesh_root for the meshes, whose
// nodes follow the splats' in the same buffer (splat_gpu::layout::nodes).
fn traversal_begin(root: u32, origin: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) {
    trav_top = 0u;
    trav_next = select(NONE, root, enter(node_at(root), origin, inv, t_min, t_max) < FAR);
}

// The next leaf whose box the ray overlaps before t_max, nearer child first; NONE when the
// traversal is over. Nodes are re-tested against the current t_max when popped, so a caller
// that lowers t_max between leaves clips the rest of the traversal.
fn traversal_next_leaf(origin: vec3<f32>, inv: vec3<f32>, t_min: f32, t_max: f32) -> u32 {
    loop {
        iterations += 1u;
        if (trav_next == NONE) {
            if (trav_top == 0u) {
                return NONE;
            }
            trav_top -= 1u;
            let c = trav_stack[trav_top];
            if (enter(node_at(c), origin, inv, t_min, t_max) < FAR) {
                trav_next = c;
            }
            continue;
        }
        let node = trav_next;
        let nd = node_at(node);
        if (nd.count > 0u) {
            trav_next = NONE;
            return node;
        }
        let a = nd.first;
        let b = nd.first + 1u;
        let ta = enter(node_at(a), origin, inv, t_min, t_max);
        let tb = enter(node_at(b), origin, inv, t_min, t_max);
        if (ta < FAR && tb < FAR) {
            trav_stack[trav_top] = select(a, b, ta <= tb);
            trav_next = select(b, a, ta <= tb);
            trav_top += 1u;
        } else if (ta < FAR) {
            trav_next = a;
        } else if (tb < FAR) {
            trav_next = b;
        } else {
            trav_next = NONE;
        }
    }
    return NONE; // unreachable: the loop only ends by returning
}
