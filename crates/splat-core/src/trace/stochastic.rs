//! Sun et al. 2025's stochastic any-hit ray tracing: Algorithm 1 (one traversal, Russian
//! roulette on alpha, the closest accepted hit shaded once) and its N-samples-per-traversal
//! extension (§3.5). The GPU twin is `shaders/stochastic.wgsl`.

use super::{Candidate, MAX_HITS, MAX_SAMPLES_PER_TRAVERSAL, Segment, TraceScene};
use crate::frame::{Decide, Sample, depth_before};
use crate::hit::Ray;
use glam::{DVec3, Vec3};

impl TraceScene<'_> {
    /// Algorithm 1: the closest hit accepted by Russian roulette (u < α), found in one
    /// traversal that clips t_max at every accept; shaded once (Eq. 6).
    ///
    /// With a position-free generator u is drawn before the kernel: α ≤ min(opacity, clamp),
    /// so u ≥ that bound rejects the hit without evaluating the exponential; the decision is
    /// the same because u is a hash, not a stream.
    pub(super) fn stochastic<D: Decide>(&self, seg: &Segment<D>, slot: u32) -> Sample {
        match self.first_accepted(&seg.ray, &seg.decide, slot) {
            Some(best) => self.opaque_sample(best.leaf, best.t, seg, slot),
            None => self.behind(seg),
        }
    }

    /// Algorithm 1's traversal: the closest hit of `ray` accepted in slot `slot`, if any.
    pub(crate) fn first_accepted(&self, ray: &Ray, decide: &impl Decide, slot: u32) -> Option<Candidate> {
        let early = !decide.needs_position();
        let mut best = Candidate::EMPTY;
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, t_max| {
            let id = self.ids[leaf as usize];
            let u = if early {
                let u = decide.particle(id, slot, Vec3::ZERO);
                if u >= self.alpha_bound[leaf as usize] {
                    return;
                }
                u
            } else {
                0.0
            };
            let Some(h) = self.hit(leaf, ray) else { return };
            if !depth_before(h.t, id, best.t, best.id) {
                return;
            }
            let u = if early { u } else { decide.particle(id, slot, ray.at(h.t)) };
            if decide.accepts(id, u, h.alpha) {
                best = Candidate { t: h.t, id, leaf, alpha: h.alpha };
                *t_max = h.t;
            }
        });
        best.is_hit().then_some(best)
    }

    /// §3.5: `n` independent instantiations of Algorithm 1 in one traversal, slots
    /// `first_slot..first_slot + n`; the traversal is clipped at the farthest slot's hit.
    pub(super) fn stochastic_n<D: Decide>(&self, seg: &Segment<D>, n: usize, first_slot: u32) -> Sample {
        if n <= MAX_HITS {
            let best = self.first_accepted_n::<MAX_HITS>(&seg.ray, &seg.decide, first_slot, n);
            self.shade_slots(seg, &best[..n], first_slot)
        } else {
            let best = self.first_accepted_n::<MAX_SAMPLES_PER_TRAVERSAL>(&seg.ray, &seg.decide, first_slot, n);
            self.shade_slots(seg, &best[..n], first_slot)
        }
    }

    /// Each slot's closest accepted hit (`best[i]` of slot `first_slot + i`) shaded, or what
    /// lies behind where none was; their mean, with the first slot's depth, normal and pick.
    fn shade_slots<D: Decide>(&self, seg: &Segment<D>, best: &[Candidate], first_slot: u32) -> Sample {
        let n = best.len();
        let mut color = DVec3::ZERO;
        let mut alpha = 0.0;
        let mut first = self.background_sample();
        for (slot, b) in (first_slot..).zip(best) {
            let s = if b.is_hit() { self.opaque_sample(b.leaf, b.t, seg, slot) } else { self.behind(seg) };
            color += s.color;
            alpha += s.alpha;
            if slot == first_slot {
                first = s;
            }
        }
        Sample { color: color / n as f64, alpha: alpha / n as f64, ..first }
    }

    /// The traversal of §3.5: for each slot of `first_slot..first_slot + n` (n ≤ `N`, the
    /// slots the stack holds), the closest hit of `ray` accepted in that slot
    /// ([`Candidate::EMPTY`] where none is); the traversal is clipped at the farthest slot's hit.
    pub(crate) fn first_accepted_n<const N: usize>(
        &self,
        ray: &Ray,
        decide: &impl Decide,
        first_slot: u32,
        n: usize,
    ) -> [Candidate; N] {
        assert!(n <= N, "{n} samples in a traversal of {N} slots");
        let early = !decide.needs_position();
        let mut best = [Candidate::EMPTY; N];
        let mut u = [0.0f32; N];
        let mut t_max = ray.t_max;
        let draw = decide.slot_draws(first_slot, n);
        self.bvh().traverse(ray, &mut t_max, |leaf, t_max| {
            let id = self.ids[leaf as usize];
            if early {
                let bound = self.alpha_bound[leaf as usize];
                draw(id, Vec3::ZERO, &mut u[..n]);
                if u[..n].iter().all(|&us| us >= bound) {
                    return;
                }
            }
            let Some(h) = self.hit(leaf, ray) else { return };
            let mut farthest = 0.0f32;
            for (s, (b, &us)) in best[..n].iter_mut().zip(&u[..n]).enumerate() {
                if depth_before(h.t, id, b.t, b.id) {
                    let us = if early { us } else { decide.particle(id, first_slot + s as u32, ray.at(h.t)) };
                    if decide.accepts(id, us, h.alpha) {
                        *b = Candidate { t: h.t, id, leaf, alpha: h.alpha };
                    }
                }
                farthest = farthest.max(b.t);
            }
            *t_max = farthest.min(ray.t_max);
        });
        best
    }
}
