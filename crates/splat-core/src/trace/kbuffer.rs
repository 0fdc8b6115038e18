//! The methods that keep hits sorted by (t, id) — `exact` (every hit), the k-buffer of
//! 3DGRT and vk_gaussian_splatting, vk's stochastic pass and 3DGRT's depth sampling — and the
//! sorted buffer they share ([`KBuf`]). The GPU twin is `shaders/kbuffer.wgsl` (the buffer and
//! the traversal collecting the next k hits) with the passes in `trace.wgsl`'s `step`.

use super::{Bounce, Integrator, MAX_HITS, Method, Segment, TraceScene};
use crate::composite::depth_order;
use crate::frame::{Decide, Sample, depth_before};
use crate::hit::Ray;
use glam::{DVec3, Vec3};

/// A candidate hit in a k-buffer, ordered by (t, id).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    pub(crate) t: f32,
    pub(crate) id: u32,
    pub(crate) leaf: u32,
    pub(crate) alpha: f32,
}

impl Candidate {
    pub(crate) const EMPTY: Candidate = Candidate { t: f32::INFINITY, id: u32::MAX, leaf: 0, alpha: 0.0 };

    /// Whether it holds a hit (not [`Candidate::EMPTY`]).
    pub(crate) fn is_hit(&self) -> bool {
        self.id != u32::MAX
    }
}

/// Up to `cap` hits kept sorted by (t, id).
pub(crate) struct KBuf {
    hits: [Candidate; MAX_HITS],
    len: usize,
    cap: usize,
}

impl KBuf {
    pub(crate) fn new(cap: usize) -> Self {
        Self { hits: [Candidate::EMPTY; MAX_HITS], len: 0, cap }
    }

    pub(crate) fn is_full(&self) -> bool {
        self.len == self.cap
    }

    /// The last kept hit (the farthest).
    pub(crate) fn last(&self) -> Candidate {
        if self.len == 0 { Candidate::EMPTY } else { self.hits[self.len - 1] }
    }

    /// Whether a hit at (t, id) would be kept.
    pub(crate) fn admits(&self, t: f32, id: u32) -> bool {
        !self.is_full() || depth_before(t, id, self.last().t, self.last().id)
    }

    /// Insert, dropping the farthest when full (insertion sort, as the vk any-hit shader does).
    pub(crate) fn insert(&mut self, s: Candidate) {
        let mut i = if self.is_full() { self.len - 1 } else { self.len };
        if !self.is_full() {
            self.len += 1;
        }
        while i > 0 && depth_before(s.t, s.id, self.hits[i - 1].t, self.hits[i - 1].id) {
            self.hits[i] = self.hits[i - 1];
            i -= 1;
        }
        self.hits[i] = s;
    }

    pub(crate) fn as_slice(&self) -> &[Candidate] {
        &self.hits[..self.len]
    }
}

impl TraceScene<'_> {
    /// Exact: every hit along the ray through the BVH, sorted front to back, Eq. 3 (lit by the
    /// look when lighting is on; `decide` draws only shadow rays and area-light samples).
    pub(super) fn exact<D: Decide>(&self, seg: &Segment<D>) -> Sample {
        let mut acc = Integrator::START;
        for s in &self.sorted_hits(&seg.ray) {
            self.add(&mut acc, &self.shade(s.leaf, s.t, s.alpha, &seg.ray), seg);
        }
        self.finish(&acc, seg)
    }

    /// Every hit of `ray` through the BVH, sorted front to back by (t, id) (the order of
    /// `composite::sort_front_to_back`), as small records: each is shaded once, in that order.
    pub(crate) fn sorted_hits(&self, ray: &Ray) -> Vec<Candidate> {
        let mut found = Vec::with_capacity(64);
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, _| {
            if let Some(h) = self.hit(leaf, ray) {
                found.push(Candidate { t: h.t, id: h.index, leaf, alpha: h.alpha });
            }
        });
        found.sort_unstable_by(|a, b| depth_order(a.t, a.id, b.t, b.id));
        found
    }

    /// The k closest hits strictly behind (after_t, after_id), by (t, id); when `decide` is
    /// given, only hits accepted in slot 0 count (depth sampling).
    pub(super) fn next_k(
        &self,
        ray: &Ray,
        k: usize,
        after: (f32, u32),
        accepted: Option<&dyn Fn(u32, Vec3, f32) -> bool>,
    ) -> KBuf {
        let mut buf = KBuf::new(k);
        let mut t_max = ray.t_max;
        self.bvh().traverse(ray, &mut t_max, |leaf, t_max| {
            let Some(h) = self.hit(leaf, ray) else { return };
            let id = self.ids[leaf as usize];
            if !depth_before(after.0, after.1, h.t, id) || !buf.admits(h.t, id) {
                return;
            }
            if let Some(accept) = accepted
                && !accept(id, ray.at(h.t), h.alpha)
            {
                return;
            }
            buf.insert(Candidate { t: h.t, id, leaf, alpha: h.alpha });
            if buf.is_full() {
                *t_max = buf.last().t;
            }
        });
        buf
    }

    /// k-buffer multi-pass (3DGRT / vk baseline).
    pub(super) fn kbuffer<D: Decide>(
        &self,
        seg: &Segment<D>,
        k: usize,
        max_passes: u32,
        min_transmittance: f32,
    ) -> Sample {
        let mut acc = Integrator::START;
        let mut after = (seg.ray.t_min, u32::MAX);
        for _ in 0..max_passes {
            if acc.transmittance <= f64::from(min_transmittance) {
                break;
            }
            let buf = self.next_k(&seg.ray, k, after, None);
            self.integrate(&mut acc, &buf, seg);
            if !buf.is_full() {
                break;
            }
            after = (buf.last().t, buf.last().id);
        }
        self.finish(&acc, seg)
    }

    /// vk stochastic pass: each pass integrates its K sorted hits from T = 1; it is accepted
    /// with probability O = 1 − T_pass and returns L_pass / O, else it is discarded and the
    /// next pass starts behind it. E = Σⱼ (Πᵢ<ⱼ Tᵢ) Lⱼ + (Π Tⱼ) background: Eq. 3 exactly.
    pub(super) fn stochastic_pass<D: Decide>(&self, seg: &Segment<D>, k: usize, max_passes: u32) -> Sample {
        let mut accepted = None;
        self.passes(&seg.ray, k, max_passes, |pass, acc| {
            let opacity = 1.0 - acc.transmittance;
            if seg.decide.accepts_pass(f64::from(seg.decide.pass(pass)), opacity) {
                accepted = Some(self.pass_sample(acc, seg));
            }
            accepted.is_none()
        });
        accepted.unwrap_or_else(|| self.behind(seg))
    }

    /// The exact expectation of the stochastic pass (its oracle when lit): Σⱼ (Πᵢ<ⱼ Tᵢ) Oⱼ Sⱼ +
    /// (Π Tⱼ) behind, with Sⱼ the sample pass j returns when accepted and `behind` the
    /// background or the mesh surface clipping the ray. Unlit Sⱼ = Lⱼ / Oⱼ and this is Eq. 3;
    /// lit it is not, since the specular term is not proportional to the base colour. `decide`
    /// draws only shadow rays, area-light samples and the decisions of secondary rays — and of
    /// the ray continued past a transparent mesh, whose radiance `behind` samples once.
    pub fn stochastic_pass_expectation(&self, ray: &Ray, decide: &impl Decide, k: usize, max_passes: u32) -> DVec3 {
        let seg = self.segment(&Method::StochasticPass { k, max_passes }, ray, Bounce::camera(decide), 0.0);
        let mut reach = 1.0f64;
        let mut sum = DVec3::ZERO;
        self.passes(&seg.ray, k, max_passes, |_, acc| {
            let opacity = 1.0 - acc.transmittance;
            if opacity > 0.0 {
                sum += reach * opacity * self.pass_sample(acc, &seg).color;
            }
            reach *= acc.transmittance;
            true
        });
        sum + reach * self.behind(&seg).color
    }

    /// The passes of K sorted hits along `ray`, each integrated from T = 1 and handed to
    /// `visit(pass, integrator)` until it returns false, a pass is not full or `max_passes`.
    pub(super) fn passes(&self, ray: &Ray, k: usize, max_passes: u32, mut visit: impl FnMut(u32, &Integrator) -> bool) {
        let mut after = (ray.t_min, u32::MAX);
        for pass in 0..max_passes {
            let buf = self.next_k(ray, k, after, None);
            if buf.len == 0 {
                return;
            }
            let mut acc = Integrator::START;
            for s in buf.as_slice() {
                let h = self.shade(s.leaf, s.t, s.alpha, ray);
                acc.add(&h, h.color, self.settings.iso_threshold);
            }
            if !visit(pass, &acc) || !buf.is_full() {
                return;
            }
            after = (buf.last().t, buf.last().id);
        }
    }

    /// An accepted pass as one opaque sample: colour L_pass / O. Lit (vk_gaussian_splatting
    /// Lighting §1.3, §2.3), that base colour is lit with the pass's integrated normal at its
    /// iso-depth, or else at its farthest hit, with the material of the particle there.
    pub(super) fn pass_sample<D: Decide>(&self, acc: &Integrator, seg: &Segment<D>) -> Sample {
        let (t, id) = acc.depth.or(acc.farthest).expect("a pass with hits has a farthest hit");
        let normal = acc.unit_normal(seg.ray.dir);
        let base = acc.radiance / (1.0 - acc.transmittance);
        let color = if self.lighting.is_on() {
            self.lit(base.as_vec3(), id, t, normal, &seg.ray, &seg.decide, 0).as_dvec3()
        } else {
            base
        };
        Sample { color, alpha: 1.0, depth: Some(t), normal, picked: None }
    }

    /// 3DGRT stochastic depth sampling: the k closest hits accepted by roulette (slot 0),
    /// composited in order with their alphas (biased: α counts twice).
    pub(super) fn depth_sampling<D: Decide>(&self, seg: &Segment<D>, k: usize) -> Sample {
        let buf = self.first_k_accepted(&seg.ray, &seg.decide, k, 0);
        let mut acc = Integrator::START;
        self.integrate(&mut acc, &buf, seg);
        Sample { depth: buf.as_slice().first().map(|s| s.t), ..self.finish(&acc, seg) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::xxhash32;

    /// Inserting every hit the buffer admits keeps exactly the k first hits by (t, id) of any
    /// insertion order, sorted: what the k-buffer methods (and the GPU's `hitbuf_insert`)
    /// rely on. A hit is admitted while the buffer has room or when it lies before the
    /// farthest kept hit.
    #[test]
    fn a_full_buffer_keeps_the_k_nearest_hits_in_depth_order() {
        for (case, k) in [1usize, 3, 18, MAX_HITS].into_iter().enumerate() {
            // Depths on a coarse grid, so that ties are broken by id; ids distinct, as particles'.
            let hits: Vec<Candidate> = (0..200u32)
                .map(|i| {
                    let t = (xxhash32([i, case as u32, 0]) % 50) as f32 * 0.25;
                    Candidate { t, id: (i * 7919) % 200, leaf: i, alpha: 0.5 }
                })
                .collect();
            let mut buf = KBuf::new(k);
            for &h in &hits {
                let room = !buf.is_full();
                let admitted = buf.admits(h.t, h.id);
                assert_eq!(admitted, room || depth_before(h.t, h.id, buf.last().t, buf.last().id));
                if admitted {
                    buf.insert(h);
                }
            }
            let mut sorted = hits.clone();
            sorted.sort_by(|a, b| depth_order(a.t, a.id, b.t, b.id));
            let want: Vec<(f32, u32)> = sorted.iter().take(k).map(|s| (s.t, s.id)).collect();
            let got: Vec<(f32, u32)> = buf.as_slice().iter().map(|s| (s.t, s.id)).collect();
            assert_eq!(got, want, "k = {k}");
            assert!(buf.is_full());
        }
    }
}
