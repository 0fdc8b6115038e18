//! Small deterministic scenes, each with a camera: the built-in demo scene and the test
//! fixtures (`cargo xtask fixtures` writes them to `fixtures/`). World up is +y.

use crate::camera::Camera;
use crate::particle::{Particle, SH_MAX_COEFFS, Scene};
use crate::rng::SplitMix64;
use crate::sh::rgb_to_dc;
use glam::{Quat, Vec3, Vec4};

pub(crate) fn camera(eye: Vec3, target: Vec3, fov_y: f32, width: u32, height: u32) -> Camera {
    Camera::look_at(eye, target, Vec3::Y, fov_y, width, height).expect("built-in camera is valid")
}

/// A uniformly distributed random rotation (normalised Gaussian-like 4-vector by rejection).
fn random_rotation(rng: &mut SplitMix64) -> Quat {
    loop {
        let v = Vec4::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let len2 = v.length_squared();
        if len2 > 1e-4 && len2 <= 1.0 {
            return Quat::from_vec4(v / len2.sqrt());
        }
    }
}

/// A uniformly distributed point of the unit ball (by rejection from the cube).
pub(crate) fn point_in_unit_ball(rng: &mut SplitMix64) -> Vec3 {
    loop {
        let p = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        if p.length_squared() <= 1.0 {
            return p;
        }
    }
}

/// Colour of hue h ∈ [0, 1) at full saturation and value `v`.
pub(crate) fn hue(h: f32, v: f32) -> Vec3 {
    let k = |n: f32| {
        let k = (n + 6.0 * h) % 6.0;
        v * (1.0 - (k.min(4.0 - k).clamp(0.0, 1.0)))
    };
    Vec3::new(k(5.0), k(3.0), k(1.0))
}

/// Overlapping semi-transparent sheets of different colours and opacities, the analogue of the
/// Laine–Karras cloth: four large flat Gaussians, each tilted, partly covering the others.
pub fn layers() -> (Scene, Camera) {
    let sheets = [
        (Vec3::new(-0.25, 0.15, 0.6), 0.35, Vec3::new(0.9, 0.15, 0.1), 0.25),
        (Vec3::new(0.2, -0.1, 0.2), 0.5, Vec3::new(0.1, 0.8, 0.2), -0.2),
        (Vec3::new(-0.1, -0.2, -0.2), 0.65, Vec3::new(0.15, 0.3, 0.95), 0.15),
        (Vec3::new(0.15, 0.2, -0.6), 0.8, Vec3::new(0.95, 0.85, 0.2), -0.1),
    ];
    let particles = sheets
        .iter()
        .map(|&(mean, opacity, rgb, tilt)| {
            let rotation = Quat::from_rotation_y(tilt) * Quat::from_rotation_x(0.5 * tilt);
            Particle::with_rgb(mean, Vec3::new(0.7, 0.5, 0.01), rotation, opacity, rgb)
        })
        .collect();
    let scene = Scene::new(particles, 0);
    (scene, camera(Vec3::new(0.5, 0.35, 3.2), Vec3::ZERO, 40.0, 160, 120))
}

/// One row of flat, quad-like Gaussians with opacity rising linearly from 0 to 1.
pub fn ramp() -> (Scene, Camera) {
    let n = 12;
    let particles = (0..n)
        .map(|i| {
            let f = i as f32 / (n - 1) as f32;
            let mean = Vec3::new(-1.65 + 0.3 * i as f32, 0.0, 0.0);
            Particle::with_rgb(mean, Vec3::new(0.1, 0.25, 0.01), Quat::IDENTITY, f, Vec3::new(0.95, 0.9, 0.8))
        })
        .collect();
    let scene = Scene::new(particles, 0);
    (scene, camera(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 30.0, 192, 64))
}

/// A few thousand random particles in the unit ball with SH degree 3 colours.
pub fn cloud() -> (Scene, Camera) {
    let mut rng = SplitMix64::new(0x5EED_C10D);
    let particles = (0..3000)
        .map(|_| {
            let mean = point_in_unit_ball(&mut rng);
            let mut log_scale = || rng.range(0.015f32.ln(), 0.08f32.ln()).exp();
            let scale = Vec3::new(log_scale(), log_scale(), log_scale());
            let rotation = random_rotation(&mut rng);
            let opacity = rng.range(0.05, 0.95);
            let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
            sh[0] = rgb_to_dc(hue(rng.next_f32(), rng.range(0.5, 1.0)));
            for c in &mut sh[1..] {
                *c = Vec3::new(rng.range(-0.15, 0.15), rng.range(-0.15, 0.15), rng.range(-0.15, 0.15));
            }
            Particle { mean, scale, rotation, opacity, sh: sh.into() }
        })
        .collect();
    let scene = Scene::new(particles, 3);
    (scene, camera(Vec3::new(0.0, 0.6, 3.4), Vec3::ZERO, 40.0, 128, 96))
}

/// Kernel degree the [`plates`] and [`cloth`] scenes are meant for: exp(−4.5 (d/3)⁸) is flat
/// (≥ 0.98) out to 1.5σ, so each particle is a near-constant-alpha plate like the polygons of
/// Laine & Karras' test models.
pub const PLATE_KERNEL_DEGREE: u32 = 8;

/// The analogue of Laine & Karras' motor (Figure 9): 40 white, flat, round plates of constant
/// opacity 0.3 in a random clutter, each shaded grey by a two-sided diffuse term |n·l| from a
/// fixed light. Render with kernel degree [`PLATE_KERNEL_DEGREE`].
pub fn plates() -> (Scene, Camera) {
    let mut rng = SplitMix64::new(0x9A7E5);
    let light = Vec3::new(0.4, 0.8, 0.45).normalize();
    let particles = (0..40)
        .map(|_| {
            let mean = Vec3::new(rng.range(-0.9, 0.9), rng.range(-0.65, 0.65), rng.range(-0.8, 0.8));
            let rotation = Quat::from_rotation_y(rng.range(-0.9, 0.9)) * Quat::from_rotation_x(rng.range(-0.9, 0.9));
            let radius = rng.range(0.12, 0.22);
            let normal = rotation * Vec3::Z;
            let grey = 0.15 + 0.8 * normal.dot(light).abs();
            Particle::with_rgb(mean, Vec3::new(radius, radius, 0.004), rotation, 0.3, Vec3::splat(grey))
        })
        .collect();
    let scene = Scene::new(particles, 0);
    (scene, camera(Vec3::new(0.0, 0.3, 3.6), Vec3::ZERO, 40.0, 200, 150))
}

/// The analogue of Laine & Karras' cloth (Figure 10): a coloured sheet of opacity 0.4 folded
/// like an accordion and seen obliquely, so that the eye looks through several folds and sees
/// both sides of the sheet. Each panel is three flat patches in a stripe of hues, the back
/// faces darker. Render with kernel degree [`PLATE_KERNEL_DEGREE`].
pub fn cloth() -> (Scene, Camera) {
    let folds = 8;
    let mut particles = Vec::new();
    for i in 0..folds {
        // Alternating ±55° panels along x: a zigzag seen from the side.
        let angle = if i % 2 == 0 { 0.95f32 } else { -0.95 };
        let rotation = Quat::from_rotation_y(angle);
        let x = -0.95 + 0.27 * i as f32;
        for j in 0..3 {
            let mean = Vec3::new(x, -0.5 + 0.5 * j as f32, 0.0);
            let shade = if i % 2 == 0 { 0.95 } else { 0.6 };
            let rgb = hue((0.13 * i as f32 + 0.31 * j as f32) % 1.0, shade);
            particles.push(Particle::with_rgb(mean, Vec3::new(0.11, 0.17, 0.004), rotation, 0.4, rgb));
        }
    }
    let scene = Scene::new(particles, 0);
    (scene, camera(Vec3::new(1.2, 0.4, 3.2), Vec3::new(0.0, 0.0, 0.0), 38.0, 200, 150))
}

/// The built-in demo scene: a rainbow trefoil knot of soft Gaussians floating over a
/// translucent checkered floor, with three large glassy bubbles. 640 × 480 camera.
pub fn demo() -> (Scene, Camera) {
    let mut rng = SplitMix64::new(0xDE30);
    let mut particles = Vec::new();
    // Trefoil knot.
    let knot = 1600;
    for i in 0..knot {
        let s = i as f32 / knot as f32 * std::f32::consts::TAU;
        let p = Vec3::new(s.sin() + 2.0 * (2.0 * s).sin(), s.cos() - 2.0 * (2.0 * s).cos(), -(3.0 * s).sin());
        let jitter = Vec3::new(rng.range(-0.08, 0.08), rng.range(-0.08, 0.08), rng.range(-0.08, 0.08));
        let mean = 0.35 * p + jitter + Vec3::new(0.0, 1.05, 0.0);
        let scale = Vec3::new(rng.range(0.03, 0.07), rng.range(0.03, 0.07), rng.range(0.03, 0.07));
        let rgb = hue((i as f32 / knot as f32 + 0.05 * rng.next_f32()) % 1.0, 0.95);
        particles.push(Particle::with_rgb(mean, scale, random_rotation(&mut rng), rng.range(0.35, 0.9), rgb));
    }
    // Checkered floor of flat tiles.
    for iz in -7..=7 {
        for ix in -7..=7 {
            let dark = (ix + iz) % 2 == 0;
            let rgb = if dark { Vec3::new(0.25, 0.27, 0.32) } else { Vec3::splat(0.85) };
            let mean = Vec3::new(0.22 * ix as f32, 0.0, 0.22 * iz as f32);
            let flat = Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
            particles.push(Particle::with_rgb(mean, Vec3::new(0.11, 0.11, 0.006), flat, 0.8, rgb));
        }
    }
    // Glassy bubbles.
    for (center, rgb) in [
        (Vec3::new(-1.1, 0.35, 0.6), Vec3::new(0.6, 0.8, 1.0)),
        (Vec3::new(1.15, 0.3, 0.45), Vec3::new(1.0, 0.7, 0.5)),
        (Vec3::new(0.0, 0.45, -1.0), Vec3::new(0.7, 1.0, 0.7)),
    ] {
        particles.push(Particle::with_rgb(center, Vec3::splat(0.14), Quat::IDENTITY, 0.3, rgb));
    }
    let scene = Scene::new(particles, 0);
    (scene, camera(Vec3::new(0.0, 1.9, 3.6), Vec3::new(0.0, 0.75, 0.0), 45.0, 640, 480))
}

/// A named scene generator, for the CLI and xtask.
pub fn by_name(name: &str) -> Option<(Scene, Camera)> {
    match name {
        "demo" => Some(demo()),
        "layers" => Some(layers()),
        "ramp" => Some(ramp()),
        "cloud" => Some(cloud()),
        "plates" => Some(plates()),
        "cloth" => Some(cloth()),
        _ => None,
    }
}

/// Names accepted by [`by_name`].
pub const NAMES: [&str; 6] = ["demo", "layers", "ramp", "cloud", "plates", "cloth"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_scene_is_valid_and_deterministic() {
        for name in NAMES {
            let (a, cam) = by_name(name).unwrap();
            let (b, _) = by_name(name).unwrap();
            assert_eq!(a, b, "{name} is not deterministic");
            cam.validate().unwrap();
            for p in &a.particles {
                p.validate().unwrap();
            }
        }
    }
}
