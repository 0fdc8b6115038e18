//! The test scenes of Laine & Karras 2011 rebuilt from transparent triangles (generated here,
//! no third-party models): Figure 1's strips, a motor-like model of layered white parts
//! (Figure 9, α = 0.3), a folded, striped cloth (Figure 10, α = 0.4, triangles in random order
//! as Figure 6 draws them), Figure 3b's eight stacked surfaces (α = 0.1) and Figure 8's smoke of
//! billboards (α = 0.05). Each is a [`MeshScene`]: no splats, the meshes, a camera and the
//! lighting of the paper's images (diffuse white under a light, or emissive white on black).

use crate::camera::Camera;
use crate::lighting::{Lighting, Material};
use crate::mesh::{MeshMaterial, Meshes, TriangleMesh};
use crate::particle::Scene;
use crate::rng::SplitMix64;
use crate::scenes::{camera, point_in_unit_ball};
use glam::{Affine3A, Quat, Vec3};

/// Subdivision of the motor's and the cloth's surfaces at [`by_name`]: triangles of about a sixth
/// of a pixel at 160 × 120 (5.2 M on the motor, 7.1 M on the cloth), so that a surface reaches a pixel in many fragments of a few samples
/// each (the paper's detailed models; how the gain depends on it is measured by
/// `splat stratify --detail`).
pub const DETAIL: u32 = 32;

/// A world of transparent triangles and its camera.
pub struct MeshScene {
    /// The splats: none.
    pub scene: Scene,
    /// The triangles.
    pub meshes: Meshes,
    /// The camera of the paper's view.
    pub camera: Camera,
    /// The lights of the diffuse models (emissive scenes need none).
    pub lighting: Lighting,
}

/// Names of the scenes, for [`by_name`].
pub const NAMES: [&str; 5] = ["figure-1", "motor", "cloth", "stack", "smoke"];

/// The scene called `name` ([`NAMES`]).
pub fn by_name(name: &str) -> Option<MeshScene> {
    by_name_at(name, DETAIL)
}

/// The scene called `name` with the motor and the cloth subdivided `detail` times as finely as
/// at detail 1 (the other scenes have no subdivision).
pub fn by_name_at(name: &str, detail: u32) -> Option<MeshScene> {
    Some(match name {
        "figure-1" => figure_1(),
        "motor" => motor(detail),
        "cloth" => cloth(detail),
        "stack" => stack(),
        "smoke" => smoke(),
        _ => return None,
    })
}

fn build(meshes: &[(TriangleMesh, MeshMaterial)], camera: Camera, lighting: Lighting) -> MeshScene {
    let meshes = Meshes::new(meshes).expect("built-in meshes are valid");
    MeshScene { scene: Scene::new(Vec::new(), 0), meshes, camera, lighting }
}

/// A surface of colour `color` and opacity `opacity`: emissive (the paper's white on black) or
/// matte.
fn material(color: Vec3, opacity: f32, emissive: bool) -> MeshMaterial {
    let shading = if emissive { Material::EMISSIVE } else { Material::DIFFUSE };
    MeshMaterial { color, shading, opacity, ..MeshMaterial::default() }
}

/// An `nu` × `nv` grid of quads (two triangles each) over the parameter square, placed by `f`.
fn grid(nu: u32, nv: u32, f: impl Fn(f32, f32) -> Vec3) -> TriangleMesh {
    let mut mesh = TriangleMesh::default();
    for j in 0..=nv {
        for i in 0..=nu {
            mesh.positions.push(f(i as f32 / nu as f32, j as f32 / nv as f32));
        }
    }
    let row = nu + 1;
    for j in 0..nv {
        for i in 0..nu {
            let a = j * row + i;
            mesh.triangles.extend([[a, a + 1, a + row + 1], [a, a + row + 1, a + row]]);
        }
    }
    mesh
}

/// The triangles of `mesh` in an order shuffled by `rng` (Fisher–Yates).
fn shuffled(mut mesh: TriangleMesh, rng: &mut SplitMix64) -> TriangleMesh {
    for i in (1..mesh.triangles.len()).rev() {
        let j = (rng.next_f32() * (i + 1) as f32) as usize;
        mesh.triangles.swap(i, j.min(i));
    }
    mesh
}

/// Figure 1: white on black, three bands: a quad whose opacity ramps from 0 to 1 left to right,
/// a quad of α = 0.61, and a band of α = 0.75 drawn as five quads whose slanted shared edges
/// cross the pixels.
pub fn figure_1() -> MeshScene {
    let white = |opacity| material(Vec3::ONE, opacity, true);
    let quad = |x0: f32, x1: f32, x2: f32, x3: f32, y0: f32, y1: f32| TriangleMesh {
        positions: vec![Vec3::new(x0, y0, 0.0), Vec3::new(x1, y0, 0.0), Vec3::new(x2, y1, 0.0), Vec3::new(x3, y1, 0.0)],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        ..TriangleMesh::default()
    };
    let mut ramp = quad(-1.5, 1.5, 1.5, -1.5, 0.35, 0.85);
    ramp.opacities = vec![0.0, 1.0, 1.0, 0.0];
    let mut meshes = vec![(ramp, white(1.0)), (quad(-1.5, 1.5, 1.5, -1.5, -0.25, 0.25), white(0.61))];
    // Five pieces of one band, their shared edges slanted so that they cut through pixels.
    let cuts = [-1.5, -0.93, -0.31, 0.27, 0.88, 1.5];
    for w in cuts.windows(2) {
        let slant = |x: f32| if x.abs() < 1.4 { 0.11 } else { 0.0 };
        meshes.push((quad(w[0], w[1], w[1] + slant(w[1]), w[0] + slant(w[0]), -0.85, -0.35), white(0.75)));
    }
    build(&meshes, camera(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 36.0, 240, 144), Lighting::default())
}

/// An open cylinder of radius `r` from `a` to `b`, `around` × `along` quads.
fn tube(a: Vec3, b: Vec3, r: f32, around: u32, along: u32) -> TriangleMesh {
    let axis = b - a;
    let (u, v) = axis.normalize().any_orthonormal_pair();
    grid(around, along, |s, t| {
        let phi = std::f32::consts::TAU * s;
        a + t * axis + r * (phi.cos() * u + phi.sin() * v)
    })
}

/// A torus of radii `big` and `small` around axis `axis` at `centre`, 32 `detail` × 12 `detail` quads.
fn torus(centre: Vec3, axis: Vec3, big: f32, small: f32, detail: u32) -> TriangleMesh {
    let (u, v) = axis.normalize().any_orthonormal_pair();
    grid(32 * detail, 12 * detail, |s, t| {
        let (phi, theta) = (std::f32::consts::TAU * s, std::f32::consts::TAU * t);
        let radial = phi.cos() * u + phi.sin() * v;
        centre + (big + small * theta.cos()) * radial + small * theta.sin() * axis.normalize()
    })
}

/// A box of half extents `half` at `centre`, each face a `n` × `n` grid.
fn boxed(centre: Vec3, half: Vec3, n: u32) -> TriangleMesh {
    let mut mesh = TriangleMesh::default();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let normal = Vec3::AXES[axis] * sign;
            let (a, b) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3] * sign);
            let face = grid(n, n, |s, t| centre + half * (normal + (2.0 * s - 1.0) * a + (2.0 * t - 1.0) * b));
            let base = mesh.positions.len() as u32;
            mesh.positions.extend(face.positions);
            mesh.triangles.extend(face.triangles.iter().map(|t| t.map(|v| v + base)));
        }
    }
    mesh
}

/// A motor-like model (Figure 9's setting: white untextured parts, diffuse shading under a
/// headlight, α = 0.3), its curved parts `detail` times finer than at detail 1:
/// a block with four cylinders through it, a crankshaft, two pulleys and a housing, so that a
/// ray crosses up to a few dozen surfaces.
pub fn motor(detail: u32) -> MeshScene {
    let white = material(Vec3::ONE, 0.3, false);
    let mut parts = vec![boxed(Vec3::ZERO, Vec3::new(0.9, 0.35, 0.35), 6 * detail)];
    for i in 0..4 {
        let x = -0.6 + 0.4 * i as f32;
        parts.push(tube(Vec3::new(x, -0.2, 0.0), Vec3::new(x, 0.75, 0.0), 0.14, 20 * detail, 6 * detail));
        parts.push(TriangleMesh::sphere(16 * detail, 8 * detail).transformed(
            Affine3A::from_translation(Vec3::new(x, 0.75, 0.0)) * Affine3A::from_scale(Vec3::splat(0.14)),
        ));
    }
    parts.push(tube(Vec3::new(-1.3, -0.45, 0.0), Vec3::new(1.3, -0.45, 0.0), 0.09, 16 * detail, 12 * detail));
    for x in [-1.15, 1.15] {
        parts.push(torus(Vec3::new(x, -0.45, 0.0), Vec3::X, 0.38, 0.07, detail));
    }
    parts.push(TriangleMesh::sphere(28 * detail, 14 * detail).transformed(Affine3A::from_scale_rotation_translation(
        Vec3::new(1.2, 0.55, 0.6),
        Quat::IDENTITY,
        Vec3::new(0.0, -0.2, 0.0),
    )));
    let meshes: Vec<_> = parts.into_iter().map(|m| (m, white)).collect();
    build(&meshes, camera(Vec3::new(1.3, 1.0, 2.0), Vec3::new(0.0, -0.05, 0.0), 42.0, 160, 120), Lighting::default())
}

/// A striped cloth (Figure 10's setting, α = 0.4, diffuse under a headlight), subdivided `detail`
/// times: three curtains with deep folds, one
/// behind the other and seen at an angle, so that the folds and the curtains overlap; each
/// stripe is a mesh of its own colour, the stripes and each stripe's triangles in random order
/// (Figure 6 draws the cloth's triangles in random order).
pub fn cloth(detail: u32) -> MeshScene {
    let mut rng = SplitMix64::new(0x10_C1_07);
    let mut meshes = Vec::new();
    let stripes = 6;
    for (c, &(z, phase)) in [(0.5f32, 0.0f32), (0.0, 1.3), (-0.5, 2.1)].iter().enumerate() {
        for s in 0..stripes {
            let (u0, u1) = (s as f32 / stripes as f32, (s + 1) as f32 / stripes as f32);
            let curtain = grid(12 * detail, 16 * detail, |a, b| {
                let u = u0 + a * (u1 - u0);
                let x = -1.2 + 2.4 * u;
                Vec3::new(x, -0.9 + 1.8 * b, z + 0.3 * (9.0 * x + phase).sin() + 0.1 * b * (3.0 * x).cos())
            });
            let hue = ((c * stripes + s) as f32 * 0.37).fract();
            let color = crate::scenes::hue(hue, 0.95) * 0.8 + Vec3::splat(0.2);
            meshes.push((shuffled(curtain, &mut rng), material(color, 0.4, false)));
        }
    }
    // The stripes in random order too, so that near and far folds come first alike.
    for i in (1..meshes.len()).rev() {
        meshes.swap(i, ((rng.next_f32() * (i + 1) as f32) as usize).min(i));
    }
    build(&meshes, camera(Vec3::new(2.2, 0.4, 1.6), Vec3::ZERO, 42.0, 160, 120), Lighting::default())
}

/// Figure 3b's setting: eight white surfaces of α = 0.1 stacked in front of each other on black.
pub fn stack() -> MeshScene {
    let white = material(Vec3::ONE, 0.1, true);
    let meshes: Vec<_> = (0..8)
        .map(|i| {
            let z = -0.1 * i as f32;
            let m = TriangleMesh::plane().transformed(
                Affine3A::from_translation(Vec3::new(0.0, 0.0, z))
                    * Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2)
                    * Affine3A::from_scale(Vec3::splat(2.0)),
            );
            (m, white)
        })
        .collect();
    build(&meshes, camera(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 30.0, 96, 96), Lighting::default())
}

/// Figure 8's setting: a cloud of smoke, 64 camera-facing billboards of α = 0.05 at the centre
/// fading to 0 at the rim (the opacity texture sampled at a 6 × 6 grid of vertices), grey on
/// black, for 16 samples per pixel.
pub fn smoke() -> MeshScene {
    let mut rng = SplitMix64::new(0x5_30_CE);
    let eye = Vec3::new(0.0, 0.0, 3.2);
    let mut meshes = Vec::new();
    for _ in 0..64 {
        let centre = 0.8 * point_in_unit_ball(&mut rng);
        let size = rng.range(0.3, 0.7);
        let (u, v) = (eye - centre).normalize().any_orthonormal_pair();
        let mut puff = grid(6, 6, |s, t| centre + size * ((2.0 * s - 1.0) * u + (2.0 * t - 1.0) * v));
        puff.opacities = (0..=6)
            .flat_map(|j| (0..=6).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (s, t) = (i as f32 / 3.0 - 1.0, j as f32 / 3.0 - 1.0);
                (1.0 - (s * s + t * t)).max(0.0)
            })
            .collect();
        let grey = rng.range(0.6, 1.0);
        meshes.push((puff, material(Vec3::splat(grey), 0.05, true)));
    }
    build(&meshes, camera(eye, Vec3::ZERO, 45.0, 128, 128), Lighting::default())
}
