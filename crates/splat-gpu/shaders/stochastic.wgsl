// Sun et al. 2025's Algorithm 1 and its N-samples-per-traversal extension (§3.5), the twin of
// splat-core's trace/stochastic.rs: n slots of Russian roulette in one traversal, each keeping
// its closest accepted hit. Part of the trace kernel (splat_gpu::TRACE_WGSL).

var<private> best_t: array<f32, MAX_HITS>;
var<private> best_id: array<u32, MAX_HITS>;
var<private> best_leaf: array<u32, MAX_HITS>;
var<private> slot_u: array<f32, MAX_HITS>;

fn stochastic_traverse(ray: Ray, pixel_key: u32, n: u32, first_slot: u32) {
    for (var s = 0u; s < n; s++) {
        iterations += 1u;
        best_t[s] = FAR;
        best_id[s] = NONE;
    }
    visit_in = VisitInputs(pixel_key, n, first_slot, 0u, 0.0, NONE, false);
    traverse(ray, VISIT_STOCHASTIC);
}

// One particle of Algorithm 1's traversal in each of the n slots (stochastic.rs
// `TraceScene::stochastic_n`); returns t_max clipped at the farthest slot's hit.
fn stochastic_visit(ray: Ray, leaf: u32, t_max: f32) -> f32 {
    let p = particle_at(leaf);
    let early = params.rng_scheme == RNG_HASH;
    if (early) {
        let bound = min(p.opacity, params.alpha_clamp);
        var any = false;
        for (var s = 0u; s < visit_in.n; s++) {
            iterations += 1u;
            slot_u[s] = particle_u(visit_in.pixel_key, p.id, visit_in.first_slot + s, vec3<f32>(0.0));
            any = any || slot_u[s] < bound;
        }
        if (!any) {
            return t_max;
        }
    }
    let h = intersect(p, ray);
    if (!h.ok) {
        return t_max;
    }
    var farthest = 0.0;
    for (var s = 0u; s < visit_in.n; s++) {
        iterations += 1u;
        if (before(h.t, p.id, best_t[s], best_id[s])) {
            var u = slot_u[s];
            if (!early) {
                u = particle_u(visit_in.pixel_key, p.id, visit_in.first_slot + s, ray.origin + h.t * ray.dir);
            }
            if (u < h.alpha) {
                best_t[s] = h.t;
                best_id[s] = p.id;
                best_leaf[s] = leaf;
            }
        }
        farthest = max(farthest, best_t[s]);
    }
    return min(farthest, ray.t_max);
}

// Algorithm 1 in n slots of one traversal (stochastic.rs `TraceScene::stochastic_n`), each accepted
// particle lit at its own position and normal; the pick is that of slot 0 of the frame. Returns
// the mean of the accepted colours (misses count zero) and the accepted share.
fn stochastic_n(ray: Ray, pixel_key: u32, n: u32, first_slot: u32) -> vec4<f32> {
    stochastic_traverse(ray, pixel_key, n, first_slot);
    var sum = vec4<f32>(0.0);
    for (var s = 0u; s < n; s++) {
        iterations += 1u;
        if (best_id[s] == NONE) {
            // What lies behind (background or mesh) is added in `finish`, once per frame.
            if (first_slot + s == 0u) {
                sample_pick = no_pick();
            }
        } else {
            let normal = particle_normal(best_leaf[s], ray);
            let c = lit(sh_color(best_id[s], ray.dir), best_id[s], best_t[s], normal, ray, pixel_key, first_slot + s);
            if (first_slot + s == 0u) {
                sample_pick = Pick(normal, best_t[s], best_id[s], 0u, 0u, 0u);
            }
            sum += vec4<f32>(c, 1.0);
        }
    }
    return sum / f32(n);
}
