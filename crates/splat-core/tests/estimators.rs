//! Exact expectations of the ray-tracing estimators, computed by enumerating every outcome of
//! their random decisions through the very code that renders (`TraceScene::sample` with a
//! scripted [`Decide`]), against Eq. 3.

use glam::{Affine3A, DVec3, Quat, Vec3};
use proptest::prelude::*;
use splat_core::RenderSettings;
use splat_core::frame::Decide;
use splat_core::lighting::{Incident, Light, LightKind, Lighting, Look, Material, Shadows};
use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
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
    (Scene::new(particles, 0), Ray::new(Vec3::new(0.0, 0.0, -1.0), Vec3::Z))
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
    pass_expectation_before(scene, trace, ray, k, rule, f32::INFINITY)
}

/// [`pass_expectation`] over the hits in front of distance `clip` (a mesh there).
fn pass_expectation_before(scene: &Scene, trace: &TraceScene, ray: &Ray, k: usize, rule: Rule, clip: f32) -> DVec3 {
    let tracer = Oracle::new(scene, *trace.settings()).unwrap();
    let mut sorted: Vec<_> =
        (0..scene.particles.len() as u32).filter_map(|i| tracer.shade(i, ray)).filter(|h| h.t < clip).collect();
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
        let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        let h = hits(&scene, &ray, trace.settings());
        let e = expectation_with(&trace, &Method::Stochastic, &ray, &h, 1, late, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// §3.5 with two samples per traversal: every slot is an independent Algorithm 1.
    #[test]
    fn stochastic_n_is_unbiased((o, off, c) in stacks(7), late in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        let h = hits(&scene, &ray, trace.settings());
        let e = expectation_with(&trace, &Method::StochasticN { m: 1, n: 2 }, &ray, &h, 2, late, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// vk stochastic pass with 3 hits a pass: enumerate the pass at which it stops.
    #[test]
    fn stochastic_pass_is_unbiased((o, off, c) in stacks(12), center in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings_with(center)).unwrap();
        let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        let e = pass_expectation(&scene, &trace, &ray, 3, Rule::Production);
        prop_assert!(close(e, exact, 1e-9), "{e} vs {exact}");
    }

    /// The k-buffer with no early-out equals exact for any k; with the vk early-out at
    /// T ≤ 0.01 it differs by at most the truncated tail.
    #[test]
    fn kbuffer_matches_exact((o, off, c) in stacks(12), k in 1usize..6) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default());
        let full = trace.sample(&Method::KBuffer { k, max_passes: 1000, min_transmittance: 0.0 }, &ray, &Outcomes::default());
        prop_assert!(close(full.color, exact.color, 1e-12));
        prop_assert_eq!(full.depth, exact.depth);
        let early = trace.sample(&Method::KBuffer { k, max_passes: 200, min_transmittance: 0.01 }, &ray, &Outcomes::default());
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
        let a = trace.sample(&Method::Stochastic, &ray, &outcomes);
        let b = trace.sample(&Method::StochasticN { m: 1, n: 1 }, &ray, &outcomes);
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
    let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
    let h = hits(&scene, &ray, trace.settings());
    assert_eq!(h.len(), 4);
    for k in [1, 2] {
        let e = expectation(&trace, &Method::DepthSampling { k }, &ray, &h, 1);
        assert!(!close(e, exact, 0.05), "k = {k}: {e} vs {exact}");
    }
    let unbiased = expectation(&trace, &Method::Stochastic, &ray, &h, 1);
    assert!(close(unbiased, exact, 1e-9));
}

/// Five tilted discs of different opacities and colours, all hit by the ray.
fn five_discs() -> (Scene, Ray) {
    stack(
        &[0.6, 0.3, 0.8, 0.45, 0.7],
        &[(0.1, 0.2), (-0.2, 0.1), (0.05, -0.3), (0.2, 0.2), (-0.1, -0.1)],
        &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]],
    )
}

/// The enumeration is tight enough to catch a wrong acceptance rule: u < opacity, u ≤ 1 − α
/// (on particles, drawn early and late) and a pass accepted when u < T_pass each move the
/// expectation away from Eq. 3, while the production rules meet it to 1e-9.
#[test]
fn wrong_acceptance_rules_are_rejected_by_the_enumeration() {
    let (scene, ray) = five_discs();
    let trace = TraceScene::new(&scene, settings()).unwrap();
    let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
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

// ---------------------------------------------------------------------------------------------
// Lighting (vk_gaussian_splatting, "Lighting, Shading and Shadows"): the lit stochastic
// estimators against the volumetric oracle, the stochastic pass against its own expectation,
// the stochastic shadow ray against the transmittance, and one case known in closed form.

/// A material with every term and two lights that reach the stack from the camera's side, so
/// that shadow rays cross the discs in front of each hit.
fn lit(shadows: Shadows, look: Look) -> Lighting {
    let material = Material {
        emissive: Vec3::splat(0.1),
        ambient: Vec3::splat(0.05),
        diffuse: Vec3::new(0.8, 0.7, 0.9),
        specular: Vec3::splat(0.4),
        shininess: 16.0,
    };
    let lights = vec![
        Light {
            kind: LightKind::Directional { direction: Vec3::new(-0.3, -0.2, 1.0).normalize() },
            color: Vec3::new(1.0, 0.9, 0.8),
            intensity: 1.5,
            radius: 0.0,
        },
        Light {
            kind: LightKind::Point { position: Vec3::new(0.8, 0.5, -0.5) },
            color: Vec3::new(0.4, 0.5, 1.0),
            intensity: 2.0,
            radius: 0.0,
        },
    ];
    Lighting { look, shadow_offset: 0.05, ..Lighting::single(material, lights, shadows) }
}

/// The shadow kinds whose visibility is a deterministic function of the point.
fn deterministic_shadows() -> impl Strategy<Value = Shadows> {
    prop_oneof![Just(Shadows::None), Just(Shadows::Exact), Just(Shadows::SORTED)]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Lit, each accepted sample is shaded at its own position and normal (§1.2, §2.2), so
    /// E[Algorithm 1] and E[stochastic-n] are the volumetric oracle Σ Tᵢ αᵢ Lit(xᵢ, nᵢ, cᵢ)
    /// (exact in the volumetric look) to 1e-9, whatever the shadow kind.
    #[test]
    fn lit_stochastic_estimators_are_unbiased((o, off, c) in stacks(7), shadows in deterministic_shadows()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap().with_lighting(lit(shadows, Look::Volumetric)).unwrap();
        let oracle = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        let h = hits(&scene, &ray, trace.settings());
        let e = expectation(&trace, &Method::Stochastic, &ray, &h, 1);
        prop_assert!(close(e, oracle, 1e-9), "stochastic {e} vs {oracle}");
        let e = expectation(&trace, &Method::StochasticN { m: 1, n: 2 }, &ray, &h, 2);
        prop_assert!(close(e, oracle, 1e-9), "stochastic-n {e} vs {oracle}");
    }

    /// The lit stochastic pass (§1.3, §2.3) has its own expectation: enumerating the pass at
    /// which it stops gives `stochastic_pass_expectation`; unlit, that is Eq. 3.
    #[test]
    fn lit_stochastic_pass_meets_its_expectation((o, off, c) in stacks(10), shadows in deterministic_shadows()) {
        let (scene, ray) = stack(&o, &off, &c);
        let unlit = TraceScene::new(&scene, settings()).unwrap();
        let exact = unlit.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        prop_assert!(close(unlit.stochastic_pass_expectation(&ray, &Outcomes::default(), 3, 200), exact, 1e-9));
        let trace = unlit.with_lighting(lit(shadows, Look::Surface)).unwrap();
        let e = pass_expectation(&scene, &trace, &ray, 3, Rule::Production);
        let oracle = trace.stochastic_pass_expectation(&ray, &Outcomes::default(), 3, 200);
        prop_assert!(close(e, oracle, 1e-9), "{e} vs {oracle}");
    }

    /// The unbiased stochastic shadow ray: over every outcome of the roulette on its hits,
    /// P(visible) = Π(1 − αᵢ) = `transmittance`, with decisions drawn early or late.
    #[test]
    fn stochastic_shadow_ray_expectation_is_the_transmittance((o, off, c) in stacks(12), late in any::<bool>()) {
        let (scene, ray) = stack(&o, &off, &c);
        let trace = TraceScene::new(&scene, settings()).unwrap();
        let h = hits(&scene, &ray, trace.settings());
        let product: f64 = h.iter().map(|&(_, a)| 1.0 - a).product();
        prop_assert!((trace.transmittance(&ray) - product).abs() < 1e-12);
        let visible = shadow_visibility(&trace, &ray, &h, late, Rule::Production);
        prop_assert!((visible - product).abs() < 1e-9, "{visible} vs {product}");
    }
}

/// P(the shadow ray is not blocked), enumerating the roulette of every hit in shadow slot 0.
fn shadow_visibility(trace: &TraceScene, ray: &Ray, hits: &[(u32, f64)], late: bool, rule: Rule) -> f64 {
    let slot = splat_core::lighting::shadow_slot(0, 0);
    let mut p_visible = 0.0;
    for mask in 0u32..(1 << hits.len()) {
        let mut outcomes = Outcomes { late, rule, ..Outcomes::new(trace.scene(), hits) };
        let mut p = 1.0;
        for (b, &(id, alpha)) in hits.iter().enumerate() {
            let accepted = mask >> b & 1 == 1;
            outcomes.accept.insert((id, slot), accepted);
            p *= if accepted { alpha } else { 1.0 - alpha };
        }
        if !trace.occluded(ray, &outcomes, slot) {
            p_visible += p;
        }
    }
    p_visible
}

/// The same enumerations reject wrong rules on the lit path: u ≤ 1 − α in the primary
/// roulette, u < opacity in the shadow roulette; and the surface look (lit once) is not the
/// expectation of the stochastic estimators, which is why both oracles exist.
#[test]
fn lit_enumerations_reject_wrong_rules_and_the_other_look() {
    let (scene, ray) = five_discs();
    let trace =
        TraceScene::new(&scene, settings()).unwrap().with_lighting(lit(Shadows::Exact, Look::Volumetric)).unwrap();
    let oracle = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
    let unshadowed = TraceScene::new(&scene, settings()).unwrap().with_lighting(lit(Shadows::None, Look::Volumetric));
    let unshadowed = unshadowed.unwrap().sample(&Method::Exact, &ray, &Outcomes::default()).color;
    assert!(!close(oracle, unshadowed, 1e-2), "the shadow rays cross the stack: {oracle} vs {unshadowed}");
    let h = hits(&scene, &ray, trace.settings());
    let wrong = expectation_with(&trace, &Method::Stochastic, &ray, &h, 1, false, Rule::Complement);
    assert!(!close(wrong, oracle, 1e-3), "u ≤ 1 − α passes lit: {wrong} vs {oracle}");
    let product: f64 = h.iter().map(|&(_, a)| 1.0 - a).product();
    let wrong = shadow_visibility(&trace, &ray, &h, false, Rule::Opacity);
    assert!((wrong - product).abs() > 1e-3, "u < opacity passes the shadow enumeration: {wrong} vs {product}");
    let surface =
        TraceScene::new(&scene, settings()).unwrap().with_lighting(lit(Shadows::Exact, Look::Surface)).unwrap();
    let surface = surface.sample(&Method::Exact, &ray, &Outcomes::default()).color;
    let e = expectation(&trace, &Method::Stochastic, &ray, &h, 1);
    assert!(close(e, oracle, 1e-9));
    assert!(!close(e, surface, 1e-3), "the surface look {surface} is not E[stochastic] {e}");
}

/// One flat, nearly opaque splat facing the camera under a directional light at angle θ from
/// its normal, no shadows: the lit pixel in closed form. With alpha α (the clamp) and base c:
/// surface look, Lit(α c) + (1 − α) bg = α (k_e + k_a + E k_d cos θ) c + E k_s cosⁿ(θ/2)
/// + (1 − α) bg; volumetric look, α Lit(c) + (1 − α) bg.
#[test]
fn one_flat_splat_under_a_directional_light_in_closed_form() {
    let c = Vec3::new(0.8, 0.5, 0.2);
    let disc = Particle::with_rgb(Vec3::ZERO, Vec3::new(1.0, 1.0, 1e-3), Quat::IDENTITY, 1.0, c);
    let scene = Scene::new(vec![disc], 0);
    let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
    let theta = 50f32.to_radians();
    let (ke, ka, kd, ks, n, e) = (0.1f64, 0.05f64, 0.7f64, 0.3f64, 12.0f32, 2.0f64);
    let material = Material {
        emissive: Vec3::splat(ke as f32),
        ambient: Vec3::splat(ka as f32),
        diffuse: Vec3::splat(kd as f32),
        specular: Vec3::splat(ks as f32),
        shininess: n,
    };
    let light = Light {
        kind: LightKind::Directional { direction: -Vec3::new(0.0, theta.sin(), theta.cos()) },
        color: Vec3::ONE,
        intensity: e as f32,
        radius: 0.0,
    };
    let bg = DVec3::new(0.1, 0.2, 0.3);
    let settings = RenderSettings { background: bg.as_vec3(), ..Default::default() };
    let alpha = f64::from(settings.kernel.alpha_clamp);
    let (cos, half) = (f64::from(theta.cos()), f64::from((theta / 2.0).cos()).powf(f64::from(n)));
    let c = c.as_dvec3();
    let surface = alpha * (ke + ka + e * kd * cos) * c + DVec3::splat(e * ks * half) + (1.0 - alpha) * bg;
    let volumetric = alpha * ((ke + ka + e * kd * cos) * c + DVec3::splat(e * ks * half)) + (1.0 - alpha) * bg;
    for (look, want) in [(Look::Surface, surface), (Look::Volumetric, volumetric)] {
        let lighting = Lighting { look, ..Lighting::single(material, vec![light], Shadows::None) };
        let trace = TraceScene::new(&scene, settings).unwrap().with_lighting(lighting).unwrap();
        let got = trace.sample(&Method::Exact, &ray, &Outcomes::default()).color;
        assert!(close(got, want, 1e-5), "{look:?}: {got} vs closed form {want}");
    }
}

/// vk_gaussian_splatting's sorted shadow ray, deterministic, against the transmittance along the
/// stack: with no early stop and k above the hit count it is Π(1 − αᵢ) (what `Exact` returns);
/// with k = 2 only the two nearest hits count; with threshold 0.99 any hit puts the point in
/// shadow; with colored = 1 each hit tints by its colour, (1 − α) + α c per channel. The shadow
/// ray starts `shadow_offset` along the light, so hits within it do not count.
#[test]
fn sorted_shadow_ray_by_hand() {
    let (scene, ray) = stack(&[0.6, 0.3, 0.8], &[(0.0, 0.0); 3], &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    let h = hits(&scene, &ray, &settings());
    assert_eq!(h.len(), 3);
    let mut by_depth: Vec<(f32, f64, Vec3)> = h
        .iter()
        .map(|&(id, a)| {
            let z = scene.particles[id as usize].mean.z;
            (z, a, Vec3::from([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]][id as usize]))
        })
        .collect();
    by_depth.sort_by(|a, b| a.0.total_cmp(&b.0));
    let light = Incident { l: Vec3::Z, distance: 100.0, irradiance: Vec3::ONE };
    let visibility = |shadows: Shadows, offset: f32| {
        let lighting = Lighting { shadow_offset: offset, ..lit(shadows, Look::Surface) };
        let trace = TraceScene::new(&scene, settings()).unwrap().with_lighting(lighting).unwrap();
        trace.visibility(ray.origin, &light, &Outcomes::default(), 0)
    };
    let product: f64 = by_depth.iter().map(|d| 1.0 - d.1).product();
    let close3 = |v: Vec3, w: Vec3| (v - w).abs().max_element() < 1e-6;
    assert!(close3(visibility(Shadows::Exact, 0.0), Vec3::splat(product as f32)));
    let sorted = |k, threshold, colored| Shadows::Sorted { k, threshold, colored };
    assert!(close3(visibility(sorted(8, 0.0, 0.0), 0.0), Vec3::splat(product as f32)));
    let two = ((1.0 - by_depth[0].1) * (1.0 - by_depth[1].1)) as f32;
    assert!(close3(visibility(sorted(2, 0.0, 0.0), 0.0), Vec3::splat(two)));
    assert_eq!(visibility(sorted(8, 0.99, 0.0), 0.0), Vec3::ZERO);
    let tinted = by_depth.iter().fold(Vec3::ONE, |t, &(_, a, c)| {
        let a = a as f32;
        t * (Vec3::splat(1.0 - a) + a * c)
    });
    assert!(close3(visibility(sorted(8, 0.0, 1.0), 0.0), tinted));
    // Past the first disc (z = 1 is 2 along the ray), only the other two count.
    let behind = ((1.0 - by_depth[1].1) * (1.0 - by_depth[2].1)) as f32;
    assert!(close3(visibility(Shadows::Exact, by_depth[0].0 + 1.25), Vec3::splat(behind)));
}

// ---------------------------------------------------------------------------------------------
// Meshes (splat_core::mesh): an opaque quad inside the stack clips the ray; every estimator's
// expectation is Eq. 3 over the discs in front of it plus their transmittance times its colour.

/// An emissive quad facing the ray at depth z, with colour `c`: its shaded colour is `c`.
fn quad_at(z: f32, c: Vec3) -> Meshes {
    let m = Affine3A::from_scale_rotation_translation(
        Vec3::splat(5.0),
        Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2),
        Vec3::new(0.0, 0.0, z),
    );
    let material = MeshMaterial { color: c, shading: Material::EMISSIVE, ..MeshMaterial::default() };
    Meshes::new(&[(TriangleMesh::plane().transformed(m), material)]).unwrap()
}

/// Eq. 3 by hand over the oracle's hits in front of `clip`, over `behind`.
fn composite_before(scene: &Scene, ray: &Ray, settings: &RenderSettings, clip: f32, behind: Vec3) -> DVec3 {
    let tracer = Oracle::new(scene, *settings).unwrap();
    let mut h: Vec<_> =
        (0..scene.particles.len() as u32).filter_map(|i| tracer.shade(i, ray)).filter(|h| h.t < clip).collect();
    splat_core::composite::sort_front_to_back(&mut h);
    let (mut c, mut t) = (DVec3::ZERO, 1.0f64);
    for hit in &h {
        c += t * f64::from(hit.alpha) * hit.color.as_dvec3();
        t *= 1.0 - f64::from(hit.alpha);
    }
    c + t * behind.as_dvec3()
}

/// With the quad between the third and fourth disc: `exact` is the hand composite in front of
/// it over its colour; the enumerated expectations of `stochastic`, `stochastic-n` (two slots)
/// and the stochastic pass meet it to 1e-9; ignoring the clip (every disc over the quad's
/// colour) is far from it, so the enumeration would catch a method that ignored the mesh.
#[test]
fn a_mesh_clips_every_estimator_to_eq_3_in_front_of_it() {
    let (scene, ray) = five_discs();
    let c_mesh = Vec3::new(0.9, 0.4, 0.1);
    // Discs sit at z = 1, 1.5, … 3; the quad at z = 2.2 leaves three in front (t = z + 1).
    let trace = TraceScene::new(&scene, settings()).unwrap().with_meshes(quad_at(2.2, c_mesh));
    let clip = 3.2;
    let oracle = composite_before(&scene, &ray, trace.settings(), clip, c_mesh);
    let exact = trace.sample(&Method::Exact, &ray, &Outcomes::default());
    assert!(close(exact.color, oracle, 1e-6), "{} vs {oracle}", exact.color);
    let ignoring_clip = composite_before(&scene, &ray, trace.settings(), f32::INFINITY, c_mesh);
    assert!(!close(ignoring_clip, oracle, 0.01), "the control must differ: {ignoring_clip} vs {oracle}");
    let h: Vec<_> = hits(&scene, &ray, trace.settings());
    let in_front: Vec<_> = {
        let tracer = Oracle::new(&scene, *trace.settings()).unwrap();
        h.iter().copied().filter(|&(id, _)| tracer.shade(id, &ray).unwrap().t < clip).collect()
    };
    assert_eq!(in_front.len(), 3);
    for (method, slots) in [(Method::Stochastic, 1), (Method::StochasticN { m: 1, n: 2 }, 2)] {
        let e = expectation(&trace, &method, &ray, &in_front, slots);
        assert!(close(e, exact.color, 1e-9), "{method:?}: {e} vs {}", exact.color);
    }
    for k in [1, 2] {
        let e = pass_expectation_before(&scene, &trace, &ray, k, Rule::Production, clip);
        assert!(close(e, exact.color, 1e-9), "pass k = {k}: {e} vs {}", exact.color);
        let pass = trace.stochastic_pass_expectation(&ray, &Outcomes::default(), k, 200);
        assert!(close(pass, exact.color, 1e-9), "pass expectation k = {k}: {pass}");
    }
    // Depth and normal of the first surface: the quad where the discs never reach the iso
    // threshold in front of it.
    let faint = TraceScene::new(&scene, settings()).unwrap().with_meshes(quad_at(0.5, c_mesh));
    let s = faint.sample(&Method::Exact, &ray, &Outcomes::default());
    assert_eq!(s.color, c_mesh.as_dvec3(), "a mesh in front hides every disc");
    assert!((s.depth.unwrap() - 1.5).abs() < 1e-5 && s.normal.abs_diff_eq(-Vec3::Z, 1e-6), "{s:?}");
}
