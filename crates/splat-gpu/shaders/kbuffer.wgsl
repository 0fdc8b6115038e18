// The k closest hits behind a given one, kept sorted by (t, id): the buffer of the k-buffer,
// the stochastic pass, depth sampling and exact (the k-buffer without limits); the twin of
// splat-core's trace/kbuffer.rs. Part of the trace kernel (splat_gpu::TRACE_WGSL).

// Up to k hits kept sorted by (t, id) (kbuffer.rs `KBuf`), with each hit's alpha and leaf.
struct HitBuf {
    t: array<f32, MAX_HITS>,
    id: array<u32, MAX_HITS>,
    alpha: array<f32, MAX_HITS>,
    leaf: array<u32, MAX_HITS>,
    len: u32,
}

// The primary ray's k-buffer, and the sorted shadow ray's (which may run while kb is read).
var<private> kb: HitBuf;
var<private> sb: HitBuf;

// Keep the hit (t, id) in the sorted buffer `b` of capacity k when it is before the farthest
// kept hit or the buffer is not full (kbuffer.rs `KBuf::admits` and `KBuf::insert`: insertion
// sort, dropping the farthest when full); returns t_max clipped at the farthest kept hit once
// the buffer is full.
fn hitbuf_insert(b: ptr<private, HitBuf>, k: u32, t: f32, id: u32, alpha: f32, leaf: u32, t_max: f32) -> f32 {
    if ((*b).len == k && !before(t, id, (*b).t[k - 1u], (*b).id[k - 1u])) {
        return t_max;
    }
    var i = select((*b).len, k - 1u, (*b).len == k);
    if ((*b).len < k) {
        (*b).len += 1u;
    }
    loop {
        iterations += 1u;
        if (i == 0u || !before(t, id, (*b).t[i - 1u], (*b).id[i - 1u])) {
            break;
        }
        (*b).t[i] = (*b).t[i - 1u];
        (*b).id[i] = (*b).id[i - 1u];
        (*b).alpha[i] = (*b).alpha[i - 1u];
        (*b).leaf[i] = (*b).leaf[i - 1u];
        i -= 1u;
    }
    (*b).t[i] = t;
    (*b).id[i] = id;
    (*b).alpha[i] = alpha;
    (*b).leaf[i] = leaf;
    if ((*b).len == k) {
        return (*b).t[k - 1u];
    }
    return t_max;
}

// Collect the k closest hits strictly behind (after_t, after_id) into kb; with `accepted`,
// only hits accepted by roulette in slot 0 count (depth sampling).
fn next_k(ray: Ray, k: u32, after_t: f32, after_id: u32, accepted: bool, pixel_key: u32) {
    kb.len = 0u;
    visit_in = VisitInputs(pixel_key, 1u, 0u, k, after_t, after_id, accepted);
    traverse(ray, VISIT_NEXT_K);
}

// One particle of next_k's traversal: kept when it is behind the previous pass (and, for depth
// sampling, accepted).
fn next_k_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let p = particle_at(leaf);
    let k = visit_in.k;
    let h = intersect(p, ray);
    if (!h.ok || !before(visit_in.after_t, visit_in.after_id, h.t, p.id)) {
        return t_max;
    }
    if (kb.len == k && !before(h.t, p.id, kb.t[k - 1u], kb.id[k - 1u])) {
        return t_max;
    }
    if (visit_in.accepted && !(particle_u(visit_in.pixel_key, p.id, 0u, ray.origin + h.t * ray.dir) < h.alpha)) {
        return t_max;
    }
    return hitbuf_insert(&kb, k, h.t, p.id, h.alpha, leaf, t_max);
}
