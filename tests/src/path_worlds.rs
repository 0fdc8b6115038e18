//! Small worlds of the path tracer's tests (CPU and GPU): Gaussians with meshes, emitters and
//! lights.

use glam::Vec3;
use splat_core::lighting::{Light, LightKind, Lighting, Material, Shadows};
use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
use splat_core::{Camera, Scene};

fn quad(center: Vec3, normal: Vec3, half: f32) -> TriangleMesh {
    super::placed(TriangleMesh::plane(), half, normal, center)
}

fn sphere(center: Vec3, radius: f32) -> TriangleMesh {
    super::placed(TriangleMesh::sphere(32, 16), radius, Vec3::Y, center)
}

/// One of these worlds ready to trace: its Gaussians lit and among its meshes.
pub fn trace_scene(world: &(Scene, Camera, Meshes, Lighting)) -> splat_core::trace::TraceScene<'_> {
    trace_scene_with(world, splat_core::RenderSettings::default())
}

/// [`trace_scene`] with `settings` (a lens, say).
pub fn trace_scene_with(
    world: &(Scene, Camera, Meshes, Lighting),
    settings: splat_core::RenderSettings,
) -> splat_core::trace::TraceScene<'_> {
    let (scene, _, meshes, lighting) = world;
    splat_core::trace::TraceScene::new(scene, settings)
        .and_then(|t| t.with_lighting(lighting.clone()))
        .expect("a valid world")
        .with_meshes(meshes.clone())
}

/// A Lambertian material of albedo `color` (no ambient term).
pub fn lambert(color: Vec3) -> MeshMaterial {
    let shading = Material { ambient: Vec3::ZERO, diffuse: Vec3::ONE, ..Material::DIFFUSE };
    MeshMaterial { color, shading, ..MeshMaterial::default() }
}

/// An emitter of radiance `radiance`.
pub fn emitter(radiance: Vec3) -> MeshMaterial {
    MeshMaterial { color: radiance, shading: Material::EMISSIVE, ..MeshMaterial::default() }
}

/// Lit layers of Gaussians over a glossy floor, before a rough gold mirror that reflects them, under an
/// emissive panel, a point light and a sky: Gaussians on camera, mirror and shadow segments.
pub fn lit_world() -> (Scene, Camera, Meshes, Lighting) {
    let (scene, camera) = super::harness::fixture("layers", 24, 18);
    let meshes = Meshes::new(&[
        // Under a smooth dielectric layer (glTF's non-metal).
        (
            quad(Vec3::new(0.0, -0.8, 0.0), Vec3::Y, 4.0),
            MeshMaterial { specular_layer: true, ..lambert(Vec3::new(0.7, 0.65, 0.6)) },
        ),
        (
            quad(Vec3::new(0.0, 0.0, -1.4), Vec3::Z, 3.0),
            MeshMaterial {
                mirror: 0.8,
                roughness: 0.3,
                mirror_tint: Vec3::new(1.0, 0.78, 0.34),
                ..lambert(Vec3::splat(0.5))
            },
        ),
        (quad(Vec3::new(0.3, 2.0, 0.5), -Vec3::Y, 0.6), emitter(Vec3::new(6.0, 5.5, 5.0))),
    ])
    .unwrap();
    let material =
        Material { emissive: Vec3::splat(0.2), ambient: Vec3::ZERO, diffuse: Vec3::splat(0.8), ..Material::DIFFUSE };
    let light = Light {
        kind: LightKind::Point { position: Vec3::new(1.5, 1.5, 1.5) },
        color: Vec3::ONE,
        intensity: 2.0,
        radius: 0.0,
    };
    let lighting = Lighting { shadow_offset: 0.05, ..Lighting::single(material, vec![light], Shadows::Stochastic) };
    (scene, camera, meshes, lighting)
}

/// Emissive layers seen through a rough glass sphere and over a glossy floor.
pub fn glass_world() -> (Scene, Camera, Meshes, Lighting) {
    let (scene, camera) = super::harness::fixture("layers", 24, 18);
    // A rough mirror share beside a base under a rough dielectric layer.
    let floor = MeshMaterial { mirror: 0.4, roughness: 0.4, specular_layer: true, ..lambert(Vec3::new(0.6, 0.6, 0.7)) };
    let glass = MeshMaterial { transmission: 0.95, roughness: 0.25, ior: 1.5, ..MeshMaterial::default() };
    let meshes = Meshes::new(&[
        (quad(Vec3::new(0.0, -0.7, 0.0), Vec3::Y, 4.0), floor),
        (sphere(Vec3::new(0.25, -0.05, 1.3), 0.4), glass),
        (quad(Vec3::new(-1.0, 2.0, 1.0), -Vec3::Y, 0.8), emitter(Vec3::splat(4.0))),
    ])
    .unwrap();
    (scene, camera, meshes, Lighting::default())
}

/// Lit layers of Gaussians behind a transparent veil whose opacity ramps from 0.2 to 0.8 across
/// it (per-vertex opacities), over a floor, under a transparent emissive panel (opacity 0.6):
/// paths and emitter samples stop at transparent triangles by the path's decisions.
pub fn veiled_world() -> (Scene, Camera, Meshes, Lighting) {
    let (scene, camera, _, lighting) = lit_world();
    let mut veil = quad(Vec3::new(0.5, 0.1, 1.2), Vec3::Z, 0.5);
    veil.opacities = veil.positions.iter().map(|p| 0.2 + 0.6 * p.x).collect();
    let meshes = Meshes::new(&[
        (quad(Vec3::new(0.0, -0.8, 0.0), Vec3::Y, 4.0), lambert(Vec3::new(0.7, 0.65, 0.6))),
        (veil, lambert(Vec3::new(0.3, 0.5, 0.8))),
        (
            quad(Vec3::new(0.3, 2.0, 0.5), -Vec3::Y, 0.6),
            MeshMaterial { opacity: 0.6, ..emitter(Vec3::new(6.0, 5.5, 5.0)) },
        ),
    ])
    .unwrap();
    (scene, camera, meshes, lighting)
}
