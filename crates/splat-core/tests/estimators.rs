//! Exact expectations of the ray-tracing estimators, computed by enumerating every outcome of
//! their random decisions through the very code that renders (`TraceScene::sample` with a
//! scripted [`Decide`]), against Eq. 3.

use glam::{DVec3, Quat, Vec3};
use proptest::prelude::*;
use splat_core::RenderSettings;
use splat_core::frame::Decide;
use splat_core::oracle::Oracle;
use splat_core::trace::{Method, TraceScene};
use splat_core::{HitDistance, Particle, Ray, Scene};
use std::collections::HashMap;

/// Which acceptance rules the scripted decisions apply: the production ones (the provided
/// methods of [`Decide`]) or one of the wrong rules the enumeration must reject.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
enum Rule {
    #[default]
    Production,
    /// u < opacity: the particle's opacity instead of its alpha at the hit.
    Opacity,
    /// u ≤ 1 − α.
    Complement,
    /// A pass accepted when u < T_pass instead of u < 1 − T_pass.
    PassTransmittance,
}

/// Scripted decisions at their thresholds: an accepted particle draws u = α (1 − 10⁻⁶), a
/// rejected one u = α exactly, with α from the shading code (`Oracle::shade`, the function
/// the tracer calls); an accepted pass draws u just below its opacity O, a rejected one the
/// first f32 at or above O. Every comparison therefore runs with values on both sides of its
/// boundary, one rounding step away.
#[derive(Default)]
struct Outcomes {
    alpha: HashMap<u32, f32>,
    opacity: HashMap<u32, f32>,
    accept: HashMap<(u32, u32), bool>,
    pass_opacity: Vec<f64>,
    accept_pass: Option<u32>,
    /// u depends on the hit position (the trig-hash path: no early opacity pre-check).
    late: bool,
    rule: Rule,
}

impl Outcomes {
    fn new(scene: &Scene, hits: &[(u32, f64)]) -> Self {
        Self {
            alpha: hits.iter().map(|&(id, a)| (id, a as f32)).collect(),
            opacity: hits.iter().map(|&(id, _)| (id, scene.particles[id as usize].opacity)).collect(),
            ..Self::default()
        }
    }
}

/// The smallest f32 at or above `x`.
fn f32_at_or_above(x: f64) -> f32 {
    let u = x as f32;
    if f64::from(u) < x { u.next_up() } else { u }
}

impl Decide for Outcomes {
    fn needs_position(&self) -> bool {
        self.late
    }
    fn particle(&self, id: u32, slot: u32, _: Vec3) -> f32 {
        let alpha = self.alpha.get(&id).copied().unwrap_or(1.0);
        if self.accept.get(&(id, slot)).copied().unwrap_or(false) { alpha * (1.0 - 1e-6) } else { alpha }
    }
    fn pass(&self, pass: u32) -> f32 {
        let o = self.pass_opacity.get(pass as usize).copied().unwrap_or(1.0);
        if self.accept_pass == Some(pass) { (o * (1.0 - 1e-6)) as f32 } else { f32_at_or_above(o) }
    }
    fn accepts(&self, id: u32, u: f32, alpha: f32) -> bool {
        match self.rule {
            Rule::Opacity => u < self.opacity[&id],
            Rule::Complement => u <= 1.0 - alpha,
            _ => u < alpha,
        }
    }
    fn accepts_pass(&self, u: f64, opacity: f64) -> bool {
        match self.rule {
            Rule::PassTransmittance => u < 1.0 - opacity,
            _ => u < opacity,
        }
    }
}

/// A stack of flat discs crossing the z axis in shuffled depth order, and the ray along it.
fn stack(opacities: &[f32], offsets: &[(f32, f32)], colors: &[[f32; 3]]) -> (Scene, Ray) {
    let n = opacities.len();
    let particles = (0..n)
        .map(|i| {
            let z = 1.0 + ((i * 7) % n) as f32 * 0.5; // BVH order differs from depth order
            let mean = Vec3::new(offsets[i].0, offsets[i].1, z);
            let tilt = Quat::from_rotation_x(0.3 * offsets[i].0);
            Particle::with_rgb(mean, Vec3::new(0.6, 0.6, 0.02), tilt, opacities[i], Vec3::from(colors[i]))
        })
        .collect();
    (Scene { particles, sh_degree: 0 }, Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z))
}

fn settings() -> RenderSettings {
    RenderSettings { background: Vec3::new(0.2, 0.3, 0.9), ..Default::default() }
}

fn settings_with(center: bool) -> RenderSettings {
    let hit_distance = if center { HitDistance::Center } else { HitDistance::Mean };
    RenderSettings { hit_distance, ..settings() }
}

/// The particles the ray hits, with their alphas.
fn hits(scene: &Scene, ray: &Ray, settings: &RenderSettings) -> Vec<(u32, f64)> {
    let tracer = Oracle::new(scene, *settings).unwrap();
    (0..scene.particles.len() as u32).filter_map(|i| tracer.shade(i, ray).map(|h| (i, f64::from(h.alpha)))).collect()
}

/// E[sample] over independent Bernoulli(α) decisions of every hit particle in `slots` slots,
/// with the decisions drawn `late` (after the kernel, as the trig hash does) or early, under
/// `rule`.
fn expectation_with(
    trace: &TraceScene,
    method: &Method,
    ray: &Ray,
    hits: &[(u32, f64)],
    slots: u32,
    late: bool,
    rule: Rule,
) -> DVec3 {
    let bits = hits.len() * slots as usize;
    assert!(bits <= 16);
    let mut sum = DVec3::ZERO;
    for mask in 0u32..(1 << bits) {
        let mut outcomes = Outcomes { late, rule, ..Outcomes::new(trace.scene(), hits) };
        let mut p = 1.0;
        for (b, &(id, alpha)) in hits.iter().cycle().take(bits).enumerate() {
            let accepted = mask >> b & 1 == 1;
            outcomes.accept.insert((id, b as u32 / hits.len() as u32), accepted);
            p *= if accepted { alpha } else { 1.0 - alpha };
        }
        sum += p * trace.sample(method, ray, &outcomes).color;
    }
    sum
}

/// [`expectation_with`] the production rules, decisions drawn early.
fn expectation(trace: &TraceScene, method: &Method, ray: &Ray, hits: &[(u32, f64)], slots: u32) -> DVec3 {
    expectation_with(trace, method, ray, hits, slots, false, Rule::Production)
}

/// E[sample] of the stochastic pass with k hits a pass: the pass at which it stops is
/// enumerated, with pass opacities from the sorted alphas, independently of the integrator.
fn pass_expectation(scene: &Scene, trace: &TraceScene, ray: &Ray, k: usize, rule: Rule) -> DVec3 {
    let tracer = Oracle::new(scene, *trace.settings()).unwrap();
    let mut sorted: Vec<_> = (0..scene.particles.len() as u32).filter_map(|i| tracer.shade(i, ray)).collect();
    splat_core::composite::sort_front_to_back(&mut sorted);
    let opacities: Vec<f64> =
        sorted.chunks(k).map(|c| 1.0 - c.iter().map(|h| 1.0 - f64::from(h.alpha)).product::<f64>()).collect();
    let method = Method::StochasticPass { k, max_passes: 200 };
    let script = |accept_pass| Outcomes { pass_opacity: opacities.clone(), accept_pass, rule, ..Outcomes::default() };
    let mut e = DVec3::ZERO;
    let mut reach = 1.0;
    for (j, &o) in opacities.iter().enumerate() {
        e += reach * o * trace.sample(&method, ray, &script(Some(j as u32))).color;
        reach *= 1.0 - o;
    }
    e + reach * trace.sample(&method, ray, &script(None)).color
}

/// Opacities, (x, y) offsets and colours of a stack of discs.
type Stack = (Vec<f32>, Vec<(f32, f32)>, Vec<[f32; 3]>);

fn stacks(max: usize) -> impl Strategy<Value = Stack> {
    (2..=max).prop_flat_map(|n| {
        (
            prop::collection::vec(0.05f32..1.0, n),
            prop::collection::vec((-0.5f32..0.5, -0.5f32..0.5), n),
            prop::collection::vec(prop::array::uniform3(0.0f32..1.0), n),
        )
    })
}

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).abs().max_element() <= tol
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Algorithm 1 through the BVH: E[L̂] = Eq. 3 (with background) to 1e-9, with either hit
    /// distance convention, with decisions drawn before the kernel (hash) or after it (the
    /// trig hash's position-dependent path).
    #[test]
    fn stochastic_is_unbiased((o, off, c) in stacks(12), center in any::<bool>(), late in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings_with(center)).unwrap();
        let exact = trace.exact(&ray).color;
        let h = hits(&scene, &ray, trace.settings());
        let e = expectation_with(&trace, &Method::Stochastic, &ray, &h, 1, late, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// §3.5 with two samples per traversal: every slot is an independent Algorithm 1.
    #[test]
    fn stochastic_n_is_unbiased((o, off, c) in stacks(7), late in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let exact = trace.exact(&ray).color;
        let h = hits(&scene, &ray, trace.settings());
        let e = expectation_with(&trace, &Method::StochasticN { m: 1, n: 2 }, &ray, &h, 2, late, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// vk stochastic pass with 3 hits a pass: enumerate the pass at which it stops.
    #[test]
    fn stochastic_pass_is_unbiased((o, off, c) in stacks(12), center in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings_with(center)).unwrap();
        let exact = trace.exact(&ray).color;
        let e = pass_expectation(&scene, &trace, &ray, 3, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// The k-buffer with no early-out equals exact for any k; with the vk early-out at
    /// T ≤ 0.01 it differs by at most the truncated tail.
    #[test]
    fn kbuffer_matches_exact((o, off, c) in stacks(12), k in 1usize..6) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let exact = trace.exact(&ray);
        let full = trace.kbuffer(&ray, k, 1000, 0.0);
        prop_assert!(close(full.color, exact.color, 1e-12));
        prop_assert_eq!(full.depth, exact.depth);
        let early = trace.kbuffer(&ray, k, 200, 0.01);
        prop_assert!(close(early.color, exact.color, 0.01 * 1.0001));
    }

    /// One slot of `stochastic-n` is Algorithm 1 with the same decisions, outcome by outcome.
    #[test]
    fn stochastic_n_with_one_slot_is_algorithm_1((o, off, c) in stacks(8), mask in any::<u16>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let mut outcomes = Outcomes::new(&scene, &hits(&scene, &ray, trace.settings()));
        for id in 0..o.len() as u32 {
            outcomes.accept.insert((id, 0), mask >> id & 1 == 1);
        }
        let a = trace.stochastic(&ray, &outcomes, 0);
        let b = trace.stochastic_n(&ray, &outcomes, 1, 0);
        prop_assert_eq!(a.color, b.color);
        prop_assert_eq!(a.depth, b.depth);
    }
}

/// 3DGRT depth sampling with k = 1 (and k = 2) is biased: the same enumeration that proves
/// the other estimators equal to Eq. 3 shows it is not.
#[test]
fn depth_sampling_is_rejected_by_the_same_enumeration() {
    let (scene, ray) = stack(
        &[0.6, 0.5, 0.7, 0.4],
        &[(0.0, 0.0); 4],
        &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]],
    );
    let trace = TraceScene::new(&scene, settings()).unwrap();
    let exact = trace.exact(&ray).color;
    let h = hits(&scene, &ray, trace.settings());
    assert_eq!(h.len(), 4);
    for k in [1, 2] {
        let e = expectation(&trace, &Method::DepthSampling { k }, &ray, &h, 1);
        assert!(!close(e, exact, 0.05), "k = {k}: {e} vs {exact}");
    }
    let unbiased = expectation(&trace, &Method::Stochastic, &ray, &h, 1);
    assert!(close(unbiased, exact, 1e-9));
}

/// The enumeration is tight enough to catch a wrong acceptance rule: u < opacity, u ≤ 1 − α
/// (on particles, drawn early and late) and a pass accepted when u < T_pass each move the
/// expectation away from Eq. 3, while the production rules meet it to 1e-9.
#[test]
fn wrong_acceptance_rules_are_rejected_by_the_enumeration() {
    let (scene, ray) = stack(
        &[0.6, 0.3, 0.8, 0.45, 0.7],
        &[(0.1, 0.2), (-0.2, 0.1), (0.05, -0.3), (0.2, 0.2), (-0.1, -0.1)],
        &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]],
    );
    let trace = TraceScene::new(&scene, settings()).unwrap();
    let exact = trace.exact(&ray).color;
    let h = hits(&scene, &ray, trace.settings());
    assert_eq!(h.len(), 5, "every disc is hit");
    assert!(h.iter().all(|&(id, a)| a < f64::from(scene.particles[id as usize].opacity)), "alpha = opacity at a hit");
    for late in [false, true] {
        for method in [Method::Stochastic, Method::StochasticN { m: 1, n: 1 }] {
            let production = expectation_with(&trace, &method, &ray, &h, 1, late, Rule::Production);
            assert!(close(production, exact, 1e-9), "{method:?} late {late}: {production} vs {exact}");
            for rule in [Rule::Opacity, Rule::Complement] {
                let e = expectation_with(&trace, &method, &ray, &h, 1, late, rule);
                assert!(!close(e, exact, 1e-3), "{method:?} late {late}: {rule:?} passes ({e} vs {exact})");
            }
        }
    }
    for k in [1, 2] {
        assert!(close(pass_expectation(&scene, &trace, &ray, k, Rule::Production), exact, 1e-9));
        let e = pass_expectation(&scene, &trace, &ray, k, Rule::PassTransmittance);
        assert!(!close(e, exact, 1e-3), "k = {k}: u < T_pass passes ({e} vs {exact})");
    }
}
