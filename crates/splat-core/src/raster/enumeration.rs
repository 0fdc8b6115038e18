//! Exact expectations of the stochastic raster methods on every pixel of a small scene, by
//! enumerating every outcome of a frame's decisions through [`Rasterizer::draw`]: each equals
//! sorted splatting with the same samples.
//!
//! The decisions are enumerated depth first: a [`Path`] scripts the choices of one outcome
//! and records the branch points it meets, so decisions that exist only on some paths (the
//! picks of Enderton's R samples, the surfaces of Laine–Karras) are enumerated where they
//! occur. Accept/reject decisions are scripted at their thresholds (u = α (1 − 10⁻⁶) accepts,
//! u = α rejects), Enderton's ξ at the first f32 that raises R, so every comparison runs one
//! rounding step from its boundary.

use super::*;
use crate::particle::Particle;
use glam::Quat;
use std::cell::{Cell, RefCell};
use std::collections::HashMap;

/// One outcome of a frame's decisions: the scripted choices, the branch points met, and the
/// probability of the path so far.
#[derive(Default)]
struct Path {
    choices: Vec<usize>,
    met: RefCell<Vec<usize>>,
    p: Cell<f64>,
}

impl Path {
    /// The choice at the next branch point among `probs` (choice 0 beyond the script).
    fn branch(&self, probs: &[f64]) -> usize {
        let mut met = self.met.borrow_mut();
        let choice = self.choices.get(met.len()).copied().unwrap_or(0);
        met.push(probs.len());
        self.p.set(self.p.get() * probs[choice]);
        choice
    }
}

/// Every path of `frame(path)`, depth first: Σ p(path) × sample(path), and the path count.
fn expectation(frame: impl Fn(&Path) -> DVec3) -> (DVec3, usize) {
    let (mut sum, mut paths) = (DVec3::ZERO, 0);
    let mut choices = Vec::new();
    loop {
        let path = Path { choices: choices.clone(), met: RefCell::default(), p: Cell::new(1.0) };
        let color = frame(&path);
        sum += path.p.get() * color;
        paths += 1;
        let met = path.met.into_inner();
        choices.resize(met.len(), 0);
        // The odometer: advance the deepest branch with a choice left, drop the ones below it.
        match (0..met.len()).rev().find(|&i| choices[i] + 1 < met[i]) {
            Some(i) => {
                choices.truncate(i + 1);
                choices[i] += 1;
            }
            None => return (sum, paths),
        }
    }
}

/// The decisions of one path for one pixel: `alpha` of each splat id at this pixel (from its
/// fragment, the value the method compares), `samples` per pixel.
struct Script<'a> {
    path: &'a Path,
    alpha: HashMap<u32, f32>,
    samples: usize,
    /// A mutant one rounding step off: roulette accepts when u ≤ α, Enderton's ξ is drawn
    /// one f32 below each threshold.
    mutant: bool,
}

impl Script<'_> {
    /// Accept (u just below α) with probability α, else reject (u = α).
    fn roulette(&self, alpha: f32) -> f32 {
        let a = f64::from(alpha);
        if self.path.branch(&[a, 1.0 - a]) == 0 { alpha * (1.0 - 1e-6) } else { alpha }
    }

    /// Enderton's ξ: R = ⌊α m + ξ⌋ steps up at ξ = b_m, the first f32 that raises it for m
    /// surviving samples. The b_m of m = 1 … S cut [0, 1) into intervals on which R is the
    /// same for every m; each interval is a branch (probability its length) scripted at its
    /// lower end, so that every step of R is taken exactly at its threshold.
    fn xi(&self, alpha: f32) -> f32 {
        let mut cuts: Vec<f32> = vec![0.0];
        for m in 1..=self.samples {
            let r = (alpha * m as f32).floor();
            let mut b = (1.0 - (alpha * m as f32 - r)).clamp(0.0, 1.0);
            while b > 0.0 && (alpha * m as f32 + b.next_down()).floor() > r {
                b = b.next_down();
            }
            while (alpha * m as f32 + b).floor() <= r && b < 1.0 {
                b = b.next_up();
            }
            if b < 1.0 {
                cuts.push(b);
            }
        }
        cuts.sort_by(f32::total_cmp);
        cuts.dedup();
        let ends: Vec<f64> = cuts.iter().skip(1).map(|&c| f64::from(c)).chain([1.0]).collect();
        let probs: Vec<f64> = cuts.iter().zip(&ends).map(|(&c, &e)| e - f64::from(c)).collect();
        let xi = cuts[self.path.branch(&probs)];
        if self.mutant { xi.next_down().max(0.0) } else { xi }
    }

    /// A pick of Enderton's partial Fisher–Yates: L = lcm(1 … S) equally likely values of u
    /// whose ⌊u K⌋ is uniform over K for every K ≤ S.
    fn pick(&self) -> f32 {
        let l = (1..=self.samples).fold(1, |l, k| l * k / gcd(l, k));
        let choice = self.path.branch(&vec![1.0 / l as f64; l]);
        (choice as f32 + 0.5) / l as f32
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

impl Decide for Script<'_> {
    fn needs_position(&self) -> bool {
        false
    }
    fn particle(&self, id: u32, slot: u32, _: Vec3) -> f32 {
        let alpha = self.alpha[&id];
        match slot {
            ENDERTON_XI_SLOT => self.xi(alpha),
            s if s > ENDERTON_XI_SLOT => self.pick(),
            _ => self.roulette(alpha),
        }
    }
    fn pass(&self, _: u32) -> f32 {
        unreachable!("no passes in rasterization")
    }
    fn accepts(&self, _: u32, u: f32, alpha: f32) -> bool {
        if self.mutant { u <= alpha } else { u < alpha }
    }
    /// Laine–Karras with independent uniform references: each test covers with probability
    /// α. (The production comparison α > reference is tested at its threshold below.)
    fn covers(&self, alpha: f32, _reference: f32) -> bool {
        let a = f64::from(alpha);
        self.path.branch(&[a, 1.0 - a]) == 0
    }
}

/// Five splats of different opacities and colours overlapping on a 6 × 6 image: pixels see
/// zero to five fragments, with partial sample coverage at the edges.
fn small_scene() -> (Scene, Camera) {
    let particles = (0..5)
        .map(|i| {
            let f = i as f32;
            let mean = Vec3::new(0.25 * (f - 2.0), 0.15 * (2.0 - f) * (f - 1.0), 0.2 * f);
            let rgb = Vec3::new(0.1 + 0.2 * f, 0.9 - 0.17 * f, (i % 2) as f32);
            let rotation = Quat::from_rotation_z(0.4 * f);
            Particle::with_rgb(mean, Vec3::new(0.45, 0.3, 0.2), rotation, 0.25 + 0.15 * f, rgb)
        })
        .collect();
    let camera = Camera::look_at(Vec3::new(0.0, 0.0, 6.0), Vec3::ZERO, Vec3::Y, 14.0, 6, 6).unwrap();
    (Scene::new(particles, 0), camera)
}

/// E[frame] of `method` at every pixel equals sorted splatting to `tol`, on `samples` samples
/// per pixel; returns the number of paths enumerated and the most fragments in a pixel.
fn check(method: RasterMethod, samples: u32, tol: f64) -> (usize, usize) {
    let (paths, most, worst) = enumerate(method, samples, false, None);
    assert!(worst < tol, "{method:?} S={samples}: E[frame] differs from sorted splatting by {worst}");
    (paths, most)
}

/// The largest difference from sorted splatting over the pixels, with the paths and the most
/// fragments a pixel.
fn enumerate(method: RasterMethod, samples: u32, mutant: bool, lighting: Option<Lighting>) -> (usize, usize, f64) {
    let (scene, camera) = small_scene();
    let raster = RasterSettings { samples, ..RasterSettings::default() };
    let mut r = Rasterizer::new(&scene, &camera, RenderSettings::default(), raster).unwrap();
    if let Some(lighting) = lighting {
        r = r.with_lighting(lighting).unwrap();
    }
    let (mut paths, mut most, mut worst) = (0, 0, 0.0f64);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let px = r.pixel(x, y);
            let frags = r.fragments(&px);
            most = most.max(frags.len());
            let alpha: HashMap<u32, f32> = frags.iter().map(|f| (r.id(f), f.alpha)).collect();
            let no_decisions = Script { path: &Path::default(), alpha: HashMap::new(), samples: 0, mutant };
            let want = r.draw(&RasterMethod::Sorted { blend: Blend::Under }, &px, &frags, &no_decisions, 0).color;
            let (got, n) = expectation(|path| {
                let script = Script { path, alpha: alpha.clone(), samples: samples as usize, mutant };
                r.draw(&method, &px, &frags, &script, 0).color
            });
            paths += n;
            worst = worst.max((got - want).abs().max_element());
        }
    }
    (paths, most, worst)
}

#[test]
fn stochastic_splat_expectation_is_sorted_splatting_on_every_pixel() {
    for samples in [1, 2] {
        let (paths, most) = check(RasterMethod::StochasticSplat, samples, 1e-9);
        assert!(most >= 4 && paths > 100, "{paths} paths, at most {most} fragments a pixel");
    }
}

/// Enderton et al.'s R = ⌊α m + ξ⌋ writes on random surviving samples. ξ's branch
/// probabilities are differences of f32 thresholds, exact to about 1e-7.
#[test]
fn enderton_expectation_is_sorted_splatting_on_every_pixel() {
    for samples in [1, 2] {
        check(RasterMethod::Enderton, samples, 1e-6);
    }
}

/// Laine–Karras's surfaces, sequences and depth tests, with the reference values replaced by
/// independent uniform ones: the drawing logic is unbiased.
#[test]
fn stratified_expectation_is_sorted_splatting_on_every_pixel() {
    for samples in [1, 2] {
        check(RasterMethod::Stratified { scramble: true }, samples, 1e-9);
    }
}

/// The production comparisons at their thresholds: u = α rejects, the f32 below accepts; a
/// reference equal to α does not cover, one just below does; and the enumeration rejects a
/// rule that accepts at the threshold (u ≤ α is biased by the probability of u = α, zero for a
/// continuous u, but the scripted u sits exactly there).
#[test]
fn the_comparisons_are_strict_at_their_thresholds() {
    let rng = RayRng::new(0, 0, 0, RngScheme::Hash);
    for alpha in [0.01f32, 0.3, 0.5, 0.99] {
        assert!(!rng.accepts(0, alpha, alpha) && rng.accepts(0, alpha.next_down(), alpha));
        assert!(!rng.covers(alpha, alpha) && rng.covers(alpha, alpha.next_down()));
    }
}

/// The enumeration sees a rule one rounding step off: accepting at u = α, or ξ one f32 below
/// the value that raises R.
#[test]
fn rules_one_rounding_step_off_are_rejected() {
    let (_, _, worst) = enumerate(RasterMethod::StochasticSplat, 1, true, None);
    assert!(worst > 1e-2, "u ≤ α passes: {worst}");
    let (_, _, worst) = enumerate(RasterMethod::Enderton, 2, true, None);
    assert!(worst > 1e-2, "ξ one step low passes: {worst}");
}

/// A material with every term, lit by a directional and a point light, in the volumetric look
/// (each fragment lit at its own depth and normal, then blended: the stochastic methods'
/// expectation).
fn volumetric_lighting() -> Lighting {
    use crate::lighting::{Light, LightKind, Look, Material, Shadows};
    let material = Material {
        emissive: Vec3::splat(0.1),
        ambient: Vec3::splat(0.05),
        diffuse: Vec3::new(0.8, 0.7, 0.9),
        specular: Vec3::splat(0.4),
        shininess: 12.0,
    };
    let lights = vec![
        Light {
            kind: LightKind::Directional { direction: Vec3::new(0.3, -0.4, -1.0).normalize() },
            color: Vec3::ONE,
            intensity: 1.5,
            radius: 0.0,
        },
        Light {
            kind: LightKind::Point { position: Vec3::new(0.5, 0.8, 3.0) },
            color: Vec3::X,
            intensity: 6.0,
            radius: 0.0,
        },
    ];
    Lighting { look: Look::Volumetric, ..Lighting::single(material, lights, Shadows::None) }
}

/// Lit, each written sample is shaded at its own fragment (vk_gaussian_splatting Lighting §1.2,
/// §2.2), so the expectation of every stochastic raster method is lit sorted splatting in the
/// volumetric look, on every pixel; the mutant rule is still caught, and lighting moves the
/// image (the comparison is not of two unlit images).
#[test]
fn lit_stochastic_raster_expectations_are_volumetric_sorted_splatting() {
    for samples in [1, 2] {
        for (method, tol) in [
            (RasterMethod::StochasticSplat, 1e-9),
            (RasterMethod::Enderton, 1e-6),
            (RasterMethod::Stratified { scramble: true }, 1e-9),
        ] {
            let (_, _, worst) = enumerate(method, samples, false, Some(volumetric_lighting()));
            assert!(worst < tol, "lit {method:?} S={samples}: E[frame] differs from sorted splatting by {worst}");
        }
    }
    let (_, _, worst) = enumerate(RasterMethod::StochasticSplat, 1, true, Some(volumetric_lighting()));
    assert!(worst > 1e-2, "u ≤ α passes lit: {worst}");
    let (scene, camera) = small_scene();
    let r = Rasterizer::new(&scene, &camera, RenderSettings::default(), RasterSettings::default()).unwrap();
    let sorted = RasterMethod::Sorted { blend: Blend::Under };
    let unlit = render_raster(&r, &sorted, &Frames::default(), &|_| {}).unwrap();
    let lit =
        render_raster(&r.with_lighting(volumetric_lighting()).unwrap(), &sorted, &Frames::default(), &|_| {}).unwrap();
    assert!(crate::stats::rmse(unlit.mean.data(), lit.mean.data()) > 0.05);
}
