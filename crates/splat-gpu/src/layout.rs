//! Buffer layouts shared with `shaders/trace.wgsl`: `#[repr(C)]` + `bytemuck::Pod` structs
//! whose sizes and field offsets a test checks against the WGSL structs reflected by naga.

use crate::node::{GpuNode, bvh_nodes};
use crate::trace::MethodParams;
use bytemuck::{Pod, Zeroable};
use splat_core::Camera;
use splat_core::Scene;
use splat_core::camera::Lens;
use splat_core::camera_sampling::PixelFilter;
use splat_core::frame::Frames;
use splat_core::lighting::{LightKind, Lighting, Look, Material, Shadows};
use splat_core::mesh::Meshes;
use splat_core::particle::sh_coeff_count;
use splat_core::rng::RngScheme;
use splat_core::sh::ShStorage;
use splat_core::trace::TraceScene;

/// `Params::mode`: every frame of the dispatch in one invocation per pixel.
pub const MODE_FRAMES: u32 = 0;
/// `Params::mode`: one pass of one frame per dispatch, the ray's state kept in [`PassState`].
pub const MODE_PASS: u32 = 1;
/// `Params::mode`: whole frames whose camera segment is the rasterized first hit
/// ([`GpuFirstHit`], the hybrid pipeline).
pub const MODE_HYBRID: u32 = 2;
/// The hybrid pipeline's first hit from sorted splatting: Eq. 3 in front of the meshes, with
/// the iso-opacity pick (`Params::first_hit`, `RasterParams::first_hit`).
pub const FIRST_HIT_SORTED: u32 = 1;
/// The hybrid pipeline's first hit from StochasticSplats: the closest accepted fragment,
/// written opaque and lit as the pick in either look.
pub const FIRST_HIT_ACCEPTED: u32 = 2;
/// `RasterParams::first_hit` of the tile pass that counts each sample's fragments in front of
/// the meshes, for the hybrid's volumetric look with a sorted first hit.
pub const FIRST_HIT_COUNT: u32 = 3;
/// The hybrid pipeline's first hit from sorted splatting in the volumetric look: each sample's
/// fragments ([`GpuFragment`]) with their weights Tᵢ αᵢ, which the ray tracer lights one by one
/// with its shadow rays (`Params::first_hit`, `RasterParams::first_hit`).
pub const FIRST_HIT_FRAGMENTS: u32 = 4;
/// `Params::look` of [`Look::Surface`].
pub const LOOK_SURFACE: u32 = 0;
/// `Params::look` of [`Look::Volumetric`].
pub const LOOK_VOLUMETRIC: u32 = 1;
/// `Params::shadows` of [`Shadows::None`].
pub const SHADOWS_NONE: u32 = 0;
/// `Params::shadows` of [`Shadows::Sorted`].
pub const SHADOWS_SORTED: u32 = 1;
/// `Params::shadows` of [`Shadows::Stochastic`].
pub const SHADOWS_STOCHASTIC: u32 = 2;
/// `Params::shadows` of [`Shadows::Exact`].
pub const SHADOWS_EXACT: u32 = 3;
/// `Params::rng_scheme` of [`RngScheme::Hash`].
pub const RNG_HASH: u32 = 0;
/// `Params::rng_scheme` of [`RngScheme::Trig`].
pub const RNG_TRIG: u32 = 1;
/// `Params::hit_distance` of [`splat_core::HitDistance::Mean`].
pub const HIT_MEAN: u32 = 0;
/// `Params::hit_distance` of [`splat_core::HitDistance::Center`].
pub const HIT_CENTER: u32 = 1;
/// `Params::hit_distance` of [`splat_core::HitDistance::Icosahedron`].
pub const HIT_ICOSAHEDRON: u32 = 2;
/// [`PathParams::sampler`] of Owen-scrambled Sobol points.
pub const SAMPLER_SOBOL: u32 = 0;
/// [`PathParams::sampler`] of the counter-based hash.
pub const SAMPLER_HASH: u32 = 1;
/// [`PathParams::environment`] of a constant colour.
pub const ENVIRONMENT_CONSTANT: u32 = 0;
/// [`PathParams::environment`] of a horizon–zenith gradient.
pub const ENVIRONMENT_GRADIENT: u32 = 1;
/// [`GpuLight::kind`] of a point light.
pub const LIGHT_POINT: u32 = 0;
/// [`GpuLight::kind`] of a spot light.
pub const LIGHT_SPOT: u32 = 1;
/// [`GpuLight::kind`] of a directional light.
pub const LIGHT_DIRECTIONAL: u32 = 2;

/// One particle in BVH leaf order (WGSL `Particle`, 64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuParticle {
    /// Mean μ.
    pub mean: [f32; 3],
    /// Opacity.
    pub opacity: f32,
    /// Row 0 of the canonical transform M = S⁻¹ Rᵀ.
    pub row0: [f32; 3],
    /// Scene index (the id of the random decisions).
    pub id: u32,
    /// Row 1 of M.
    pub row1: [f32; 3],
    /// Visible extent in standard deviations ([`splat_core::KernelParams::visible_extent`]):
    /// the inradius of the icosahedron proxy.
    pub extent: f32,
    /// Row 2 of M.
    pub row2: [f32; 3],
    /// Padding.
    pub pad2: f32,
}

/// The state of one ray between the passes of pass-per-dispatch mode (WGSL `PassState`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PassState {
    /// Radiance integrated so far.
    pub radiance: [f32; 3],
    /// Transmittance so far.
    pub transmittance: f32,
    /// Distance of the last hit of the previous pass.
    pub after_t: f32,
    /// Particle id of that hit.
    pub after_id: u32,
    /// 1 done, 2 accepted (stochastic pass).
    pub flags: u32,
    /// Particle that set the iso-opacity depth (u32::MAX: none yet).
    pub picked: u32,
    /// Integrated normal Σ nᵢ αᵢ Tᵢ (lit renders).
    pub normal: [f32; 3],
    /// Iso-opacity depth.
    pub depth: f32,
}

/// The depth, unit normal and picked particle of frame 0 at one pixel (WGSL `Pick`, 32 bytes):
/// depth < 0 for none, picked `u32::MAX` for none.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuPick {
    /// Unit normal (zero where nothing was hit).
    pub normal: [f32; 3],
    /// Picked depth t.
    pub depth: f32,
    /// Scene index of the picked particle.
    pub picked: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
    /// Padding.
    pub pad2: u32,
}

/// The material of one splat set and its first particle id (WGSL `Material`, 64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    /// k_e.
    pub emissive: [f32; 3],
    /// First particle id of the set.
    pub first: u32,
    /// k_a.
    pub ambient: [f32; 3],
    /// Blinn–Phong exponent.
    pub shininess: f32,
    /// k_d.
    pub diffuse: [f32; 3],
    /// 1 when the material only emits.
    pub emissive_only: u32,
    /// k_s.
    pub specular: [f32; 3],
    /// Padding.
    pub pad: u32,
}

/// One light (WGSL `Light`, 64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    /// Position (point and spot).
    pub position: [f32; 3],
    /// 0 point, 1 spot, 2 directional.
    pub kind: u32,
    /// Unit direction (spot axis, directional travel).
    pub direction: [f32; 3],
    /// Emitter radius.
    pub radius: f32,
    /// Colour.
    pub color: [f32; 3],
    /// Intensity.
    pub intensity: f32,
    /// cos of the spot's inner half-angle.
    pub cos_inner: f32,
    /// cos of the spot's outer half-angle.
    pub cos_outer: f32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
}

/// Everything one dispatch needs (WGSL `Params`, 240 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Params {
    /// World-to-camera rotation, row 0 (w unused).
    pub cam_row0: [f32; 4],
    /// Row 1.
    pub cam_row1: [f32; 4],
    /// Row 2 (the view direction).
    pub cam_row2: [f32; 4],
    /// Camera centre (w unused).
    pub cam_center: [f32; 4],
    /// fx, fy, cx, cy.
    pub intrinsics: [f32; 4],
    /// Background RGB (w unused).
    pub background: [f32; 4],
    /// Image width and height.
    pub size: [u32; 2],
    /// SH degree of the scene.
    pub sh_degree: u32,
    /// The method's code ([`splat_core::MethodId::code`], `METHOD_*` in WGSL).
    pub method: u32,
    /// Hits per pass.
    pub k: u32,
    /// Pass limit.
    pub max_passes: u32,
    /// Samples per traversal.
    pub n: u32,
    /// Traversals per frame.
    pub m: u32,
    /// Seed of the random stream.
    pub seed: u32,
    /// Frames in this dispatch.
    pub frames: u32,
    /// `RNG_HASH` or `RNG_TRIG`.
    pub rng_scheme: u32,
    /// `HIT_MEAN`, `HIT_CENTER` or `HIT_ICOSAHEDRON`.
    pub hit_distance: u32,
    /// Kernel degree.
    pub kernel_degree: u32,
    /// Cutoff in standard deviations.
    pub cutoff: f32,
    /// Alpha clamp.
    pub alpha_clamp: f32,
    /// Alpha cull.
    pub alpha_cull: f32,
    /// Ray start.
    pub t_min: f32,
    /// Ray end.
    pub t_max: f32,
    /// k-buffer early-out transmittance.
    pub min_transmittance: f32,
    /// Index of this dispatch's first frame.
    pub first_frame: u32,
    /// 0: whole frames per invocation; 1: one pass of frame `first_frame` per dispatch.
    pub mode: u32,
    /// The pass of pass-per-dispatch mode.
    pub pass_index: u32,
    /// [`splat_core::Frames::u_shift`], subtracted from every u (a test hook; 0 in renders).
    pub u_shift: f32,
    /// 1 when lighting is on ([`splat_core::lighting::Lighting::is_on`]).
    pub lit: u32,
    /// 0 surface, 1 volumetric.
    pub look: u32,
    /// 0 none, 1 sorted, 2 stochastic, 3 exact.
    pub shadows: u32,
    /// Hits of the sorted shadow pass.
    pub shadow_k: u32,
    /// Transmittance threshold of the sorted shadow.
    pub shadow_threshold: f32,
    /// Coloured-shadow strength.
    pub shadow_colored: f32,
    /// Shadow-ray origin offset.
    pub shadow_offset: f32,
    /// Lights in the light buffer (0: the headlight).
    pub light_count: u32,
    /// Sets in the material buffer.
    pub set_count: u32,
    /// Iso-opacity threshold on transmittance.
    pub iso_threshold: f32,
    /// Index in the node buffer of the mesh BVH's root (after the splats' nodes), `u32::MAX` without meshes.
    pub mesh_root: u32,
    /// Most mirror and glass bounces (`RenderSettings::max_bounces`).
    pub max_bounces: u32,
    /// The camera's lens (`LENS_*`: pinhole, perspective, fisheye, equirectangular).
    pub lens: u32,
    /// Its distortion ([`splat_core::camera::Distortion`]): a₁…a₄; b₁…b₃ and 0; p₁, p₂, s₁, s₂.
    pub distortion: [[f32; 4]; 3],
    /// `FILTER_CENTER` or `FILTER_BOX` ([`splat_core::camera_sampling::PixelFilter`]).
    pub pixel_filter: u32,
    /// The thin lens's radius (0: a pinhole).
    pub aperture: f32,
    /// Its distance in focus (1 without a lens).
    pub focus_distance: f32,
    /// How the running mean is stored ([`splat_core::frame::AccumulationFormat::code`]).
    pub accumulation: u32,
    /// Per-particle normal (`NORMAL_*` in `lighting.wgsl`).
    pub normal_mode: u32,
    /// In `MODE_HYBRID`, `FIRST_HIT_ACCEPTED` where the tile rasterizer wrote
    /// StochasticSplats' first hit (else it wrote sorted splatting's).
    pub first_hit: u32,
    /// In `MODE_HYBRID`, the rasterizer's samples per pixel S: S first hits a pixel.
    pub raster_samples: u32,
    /// [`splat_core::Frames::first`]: frame f of the render draws as frame `run_first + f` of
    /// the run (its key, its camera sample, the path tracer's sample index).
    pub run_first: u32,
}

/// The code of a normal mode in the kernels (`NORMAL_*` in `lighting.wgsl`).
pub fn normal_code(mode: splat_core::normal::NormalMode) -> u32 {
    match mode {
        splat_core::normal::NormalMode::MaxDensityPlane => 0,
        splat_core::normal::NormalMode::KernelEllipsoid => 1,
    }
}

/// [`Params::pixel_filter`] of [`splat_core::camera_sampling::PixelFilter::Center`].
pub const FILTER_CENTER: u32 = 0;
/// [`Params::pixel_filter`] of [`splat_core::camera_sampling::PixelFilter::Box`].
pub const FILTER_BOX: u32 = 1;

/// The hybrid pipeline's first hit of one sample of a pixel (WGSL `FirstHit`, 64 bytes), from
/// the rasterizer ([`crate::GpuRasterizer::first_hits`]): S of them a pixel, sample i of pixel p
/// at p S + i.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuFirstHit {
    /// The splats' radiance L in front of the meshes (unused with `FIRST_HIT_FRAGMENTS`: the
    /// ray tracer lights the fragments).
    pub radiance: [f32; 3],
    /// Their transmittance T.
    pub transmittance: f32,
    /// Integrated unit normal (zero where no fragment).
    pub normal: [f32; 3],
    /// Iso-opacity depth along the sample's ray (−1: none).
    pub depth: f32,
    /// The splat that set it (`u32::MAX`: none).
    pub picked: u32,
    /// Padding.
    pub pad0: u32,
    /// The sample's position in its pixel, in [0, 1)² (its camera ray's).
    pub offset: [f32; 2],
    /// With `FIRST_HIT_FRAGMENTS`, the sample's fragments: index of the first and count.
    pub fragments: [u32; 2],
    /// Padding.
    pub pad1: [u32; 2],
}

/// One fragment of a hybrid sample in the volumetric look (WGSL `Fragment`, 48 bytes): what the
/// ray tracer lights (`raster/mod.rs` `Rasterizer::color` through `lit_color`) and its weight in
/// the sample's composite.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuFragment {
    /// The splat's colour.
    pub color: [f32; 3],
    /// Its weight Tᵢ αᵢ in Eq. 3.
    pub weight: f32,
    /// The splat's unit normal along sample 0's ray.
    pub normal: [f32; 3],
    /// Its distance along the sample's ray.
    pub t: f32,
    /// The splat's particle id.
    pub id: u32,
    /// Padding.
    pub pad0: u32,
    /// Padding.
    pub pad1: u32,
    /// Padding.
    pub pad2: u32,
}

/// [`Params::mesh_root`] of a scene without meshes (WGSL `NONE`).
pub const NO_MESHES: u32 = u32::MAX;

/// One mesh triangle in the mesh BVH's leaf order (WGSL `Triangle`, 96 bytes):
/// [`splat_core::mesh::PreparedTriangle`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuTriangle {
    /// Vertex p₀.
    pub p0: [f32; 3],
    /// Index of its mesh (its material).
    pub mesh: u32,
    /// p₁ − p₀.
    pub e1: [f32; 3],
    /// Opacity α₀ at p₀.
    pub alpha0: f32,
    /// p₂ − p₀.
    pub e2: [f32; 3],
    /// Opacity α₁ at p₁.
    pub alpha1: f32,
    /// Vertex normal at p₀.
    pub n0: [f32; 3],
    /// Opacity α₂ at p₂.
    pub alpha2: f32,
    /// Vertex normal at p₁.
    pub n1: [f32; 3],
    /// Its place in the meshes' order (the id keying a transparent triangle's decisions).
    pub order: u32,
    /// Vertex normal at p₂.
    pub n2: [f32; 3],
    /// Padding.
    pub pad: u32,
}

/// One mesh's material (WGSL `MeshMaterial`, 112 bytes): [`splat_core::mesh::MeshMaterial`].
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMeshMaterial {
    /// Base colour c.
    pub color: [f32; 3],
    /// Mirror share.
    pub mirror: f32,
    /// Glass share.
    pub transmission: f32,
    /// Index of refraction.
    pub ior: f32,
    /// GGX roughness of the mirror and glass shares (the path tracer's).
    pub roughness: f32,
    /// 1 with the path tracer's dielectric specular layer over the local share, else 0.
    pub specular_layer: u32,
    /// The mirror share's reflectance at normal incidence (Schlick's F₀).
    pub mirror_tint: [f32; 3],
    /// Padding.
    pub pad2: u32,
    /// Emissive, ambient, diffuse and specular shares (`first` unused).
    pub shading: GpuMaterial,
}

/// The material buffer of a lighting: one entry per splat set.
pub fn materials(lighting: &Lighting) -> Vec<GpuMaterial> {
    lighting.sets.iter().map(|s| gpu_material(&s.material, s.first)).collect()
}

fn gpu_material(m: &Material, first: u32) -> GpuMaterial {
    GpuMaterial {
        emissive: m.emissive.to_array(),
        first,
        ambient: m.ambient.to_array(),
        shininess: m.shininess,
        diffuse: m.diffuse.to_array(),
        emissive_only: u32::from(m.is_emissive()),
        specular: m.specular.to_array(),
        pad: 0,
    }
}

/// Refuse transparent mesh materials (an opacity below 1) in `what`, which draws every
/// triangle as an opaque surface (the hybrid, sorted splatting and StochasticSplats): on the GPU
/// the ray tracer, the path tracer and the raster operations of Enderton and Laine–Karras draw
/// them.
pub fn check_opaque(meshes: &Meshes, what: &str) -> Result<(), crate::GpuError> {
    if meshes.has_transparent() {
        return Err(crate::GpuError::refused(
            format!("{what} draws no transparent mesh materials (an opacity below 1)"),
            &[crate::Remedy::RasterOperations, crate::Remedy::Cpu],
        ));
    }
    Ok(())
}

/// The triangles of the trace scene's meshes in their BVH's leaf order (one unused entry when
/// there are none: a binding cannot be empty).
pub fn triangles(meshes: &Meshes) -> Vec<GpuTriangle> {
    non_empty(meshes.triangles().iter().map(gpu_triangle).collect())
}

/// The triangles in the order the meshes list them (entry `order` is the triangle of that
/// place): how the raster operations find a transparent triangle from the id it wrote.
pub fn triangles_in_order(meshes: &Meshes) -> Vec<GpuTriangle> {
    let mut v = vec![GpuTriangle::default(); meshes.triangles().len()];
    for t in meshes.triangles() {
        v[t.order as usize] = gpu_triangle(t);
    }
    non_empty(v)
}

fn gpu_triangle(t: &splat_core::mesh::PreparedTriangle) -> GpuTriangle {
    let [n0, n1, n2] = t.normals.map(|n| n.to_array());
    let [alpha0, alpha1, alpha2] = t.alphas;
    GpuTriangle {
        p0: t.p0.to_array(),
        mesh: t.mesh,
        e1: t.e1.to_array(),
        alpha0,
        e2: t.e2.to_array(),
        alpha1,
        n0,
        alpha2,
        n1,
        order: t.order,
        n2,
        pad: 0,
    }
}

/// `v`, or one unused entry where it is empty (a binding cannot be empty).
pub(crate) fn non_empty<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

/// The material of each mesh (one unused entry when there are none).
pub fn mesh_materials(meshes: &Meshes) -> Vec<GpuMeshMaterial> {
    non_empty(
        meshes
            .materials()
            .iter()
            .map(|m| GpuMeshMaterial {
                color: m.color.to_array(),
                mirror: m.mirror,
                mirror_tint: m.mirror_tint.to_array(),
                transmission: m.transmission,
                ior: m.ior,
                roughness: m.roughness,
                specular_layer: u32::from(m.specular_layer),
                shading: gpu_material(&m.shading, 0),
                ..GpuMeshMaterial::default()
            })
            .collect(),
    )
}

/// The light buffer of a lighting (one unused entry when it has none: a binding cannot be
/// empty). Cone cosines are computed here as the core computes them.
pub fn lights(lighting: &Lighting) -> Vec<GpuLight> {
    non_empty(
        lighting
            .lights
            .iter()
            .map(|l| {
                let base = GpuLight {
                    color: l.color.to_array(),
                    intensity: l.intensity,
                    radius: l.radius,
                    ..GpuLight::default()
                };
                match l.kind {
                    LightKind::Point { position } => {
                        GpuLight { position: position.to_array(), kind: LIGHT_POINT, ..base }
                    }
                    LightKind::Spot { position, direction, inner_deg, outer_deg } => GpuLight {
                        position: position.to_array(),
                        kind: LIGHT_SPOT,
                        direction: direction.to_array(),
                        cos_inner: inner_deg.to_radians().cos(),
                        cos_outer: outer_deg.to_radians().cos(),
                        ..base
                    },
                    LightKind::Directional { direction } => {
                        GpuLight { kind: LIGHT_DIRECTIONAL, direction: direction.to_array(), ..base }
                    }
                }
            })
            .collect(),
    )
}

/// The particles `range` of a scene in leaf order: the array, or one part of it made without the
/// others.
pub fn particles(trace: &TraceScene, range: std::ops::Range<u64>) -> Vec<GpuParticle> {
    let kernel = trace.settings().kernel;
    let range = range.start as usize..range.end as usize;
    trace.leaf_particles()[range.clone()]
        .iter()
        .zip(&trace.leaf_ids()[range])
        .map(|(p, &id)| {
            let rows = [p.canonical.row(0), p.canonical.row(1), p.canonical.row(2)];
            GpuParticle {
                mean: p.mean.to_array(),
                opacity: p.opacity,
                row0: rows[0].to_array(),
                id,
                row1: rows[1].to_array(),
                extent: kernel.visible_extent(p.opacity),
                row2: rows[2].to_array(),
                pad2: 0.0,
            }
        })
        .collect()
}

/// The wide BVH nodes of a scene: the splats' (their root at 0), then the meshes' (at
/// [`mesh_root`]).
pub fn nodes(trace: &TraceScene) -> Vec<GpuNode> {
    let mut v = bvh_nodes(trace.bvh(), 0);
    if !trace.meshes().is_empty() {
        v.extend(bvh_nodes(trace.meshes().bvh(), v.len() as u32));
    }
    v
}

/// Where [`nodes`] puts the mesh BVH's root: after the splat BVH's nodes, or [`NO_MESHES`].
pub fn mesh_root(trace: &TraceScene) -> u32 {
    if trace.meshes().is_empty() { NO_MESHES } else { trace.bvh().len() as u32 }
}

/// SH coefficients of a scene: (degree + 1)² a particle.
pub fn sh_len(scene: &Scene) -> usize {
    scene.particles.len() * sh_coeff_count(scene.sh_degree)
}

/// The words of SH coefficients `range` of the array in scene order, (degree + 1)² RGB(pad)
/// entries a particle (coefficient i is particle i / (degree + 1)²'s coefficient
/// i mod (degree + 1)²), as `storage` holds them: RGB and a zero pad in f32 (four words), the
/// halves of R, G | B, 0 in f16 (two words, as WGSL's `unpack2x16float` reads them: the lower
/// half first), three bytes and a DC flag in u8 (one word). The whole array, or one part of it
/// made without the others.
pub fn sh_range(scene: &Scene, storage: ShStorage, range: std::ops::Range<u64>) -> Vec<u32> {
    let per = sh_coeff_count(scene.sh_degree) as u64;
    let coefficient = |i: u64| (scene.particles[(i / per) as usize].sh[(i % per) as usize], (i % per) as usize);
    let coefficients = range.map(coefficient);
    let half = |x: f32| u32::from(half::f16::from_f32(x).to_bits());
    match storage {
        ShStorage::F32 => coefficients.flat_map(|(c, _)| [c.x, c.y, c.z, 0.0].map(f32::to_bits)).collect(),
        ShStorage::F16 => coefficients.flat_map(|(c, _)| [half(c.x) | half(c.y) << 16, half(c.z)]).collect(),
        // The three channels, then 1 for the DC term (the decode's scale): one word.
        ShStorage::U8 => coefficients
            .map(|(c, k)| {
                let [r, g, b] = splat_core::sh::u8_quantize(c, k);
                u32::from_le_bytes([r, g, b, u8::from(k == 0)])
            })
            .collect(),
    }
}

/// Words (u32) of one SH coefficient as `storage` holds it: four in f32, two in f16, one in u8.
pub fn sh_words(storage: ShStorage) -> usize {
    match storage {
        ShStorage::F32 => 4,
        ShStorage::F16 => 2,
        ShStorage::U8 => 1,
    }
}

/// The SH array of a module as `storage` holds it, part 0 at `binding`, and the WGSL that reads
/// coefficient i of it as RGB + pad, `sh_at(i)`: the array's own accessor in f32; in f16 and u8
/// a decode of the words its accessor (`sh_half_at`, `sh_byte_at`) reads.
pub(crate) fn sh_array(storage: ShStorage, binding: u32) -> (crate::split::SplitArray, &'static str) {
    use crate::split::SplitArray;
    match storage {
        ShStorage::F32 => (SplitArray::of::<[f32; 4]>("SH", "sh", "sh_at", "vec4<f32>", binding), ""),
        ShStorage::F16 => (SplitArray::of::<[u32; 2]>("SH", "sh", "sh_half_at", "vec2<u32>", binding), SH_HALF_DECODE),
        ShStorage::U8 => (SplitArray::of::<u32>("SH", "sh", "sh_byte_at", "u32", binding), &SH_BYTE_DECODE),
    }
}

/// `sh_at` of the u8 SH ([`ShStorage::U8`]): three channels q and a DC flag a word, decoded as
/// `splat_core::sh::u8_decode` does, (2q − 255) times the scale `u8_scale` (its f32 bits
/// written here), one rounding, so the GPU reads the CPU's floats.
static SH_BYTE_DECODE: std::sync::LazyLock<String> = std::sync::LazyLock::new(|| {
    let [dc, rest] = [0, 1].map(|k| splat_core::sh::u8_scale(k).to_bits());
    format!(
        "
fn sh_at(i: u32) -> vec4<f32> {{
    let w = sh_byte_at(i);
    let q = vec3<f32>(f32(w & 0xffu), f32((w >> 8u) & 0xffu), f32((w >> 16u) & 0xffu));
    let scale = select(bitcast<f32>({rest:#x}u), bitcast<f32>({dc:#x}u), (w >> 24u) != 0u);
    return vec4<f32>((2.0 * q - 255.0) * scale, 0.0);
}}
"
    )
});

/// `sh_at` of the f16 SH ([`ShStorage::F16`]): RGB + pad, two halves a word, the lower first,
/// decoded exactly (WGSL's `unpack2x16float` written out: naga wants a capability for it,
/// `SHADER_FLOAT16_IN_FLOAT32`, that not every adapter has).
const SH_HALF_DECODE: &str = "
// IEEE binary16 bits (the low 16 of h) as the f32 of the same value.
fn half_to_f32(h: u32) -> f32 {
    let magnitude = h & 0x7fffu;
    let exponent = magnitude >> 10u;
    var v: f32;
    if (exponent == 0u) {
        v = ldexp(f32(magnitude), -24); // zero and subnormals: m 2^-24
    } else if (exponent == 31u) {
        v = bitcast<f32>(0x7f800000u | ((magnitude & 0x3ffu) << 13u));
    } else {
        v = bitcast<f32>((magnitude << 13u) + 0x38000000u); // the exponent rebiased by 127 - 15
    }
    return select(v, -v, (h & 0x8000u) != 0u);
}
fn sh_at(i: u32) -> vec4<f32> {
    let w = sh_half_at(i);
    return vec4<f32>(half_to_f32(w.x), half_to_f32(w.x >> 16u), half_to_f32(w.y), half_to_f32(w.y >> 16u));
}
";
/// The uniforms of one dispatch: `chunk` frames starting at `first_frame`.
pub fn params(
    trace: &TraceScene,
    camera: &Camera,
    method: &MethodParams,
    frames: &Frames,
    first_frame: u32,
    chunk: u32,
) -> Params {
    let s = trace.settings();
    let r = camera.rotation;
    let row = |i: usize| {
        let v = r.row(i);
        [v.x, v.y, v.z, 0.0]
    };
    let c = camera.center();
    let MethodParams { id, k, max_passes, min_transmittance, n, m, .. } = *method;
    Params {
        cam_row0: row(0),
        cam_row1: row(1),
        cam_row2: row(2),
        cam_center: [c.x, c.y, c.z, 0.0],
        intrinsics: [camera.fx, camera.fy, camera.cx, camera.cy],
        background: [s.background.x, s.background.y, s.background.z, 0.0],
        size: [camera.width, camera.height],
        sh_degree: u32::from(trace.scene().sh_degree),
        method: id.code(),
        k,
        max_passes,
        n,
        m,
        seed: frames.seed,
        frames: chunk,
        rng_scheme: match frames.rng {
            RngScheme::Hash => RNG_HASH,
            RngScheme::Trig => RNG_TRIG,
        },
        hit_distance: match s.hit_distance {
            splat_core::HitDistance::Mean => HIT_MEAN,
            splat_core::HitDistance::Center => HIT_CENTER,
            splat_core::HitDistance::Icosahedron => HIT_ICOSAHEDRON,
        },
        kernel_degree: s.kernel.degree,
        cutoff: s.kernel.cutoff,
        alpha_clamp: s.kernel.alpha_clamp,
        alpha_cull: s.kernel.alpha_cull,
        t_min: s.t_min,
        t_max: s.t_max,
        min_transmittance,
        first_frame,
        mode: MODE_FRAMES,
        pass_index: 0,
        u_shift: frames.u_shift,
        lens: lens_code(&camera.lens),
        distortion: distortion(&camera.lens),
        pixel_filter: match s.sampling.filter {
            PixelFilter::Center => FILTER_CENTER,
            PixelFilter::Box => FILTER_BOX,
        },
        aperture: s.sampling.aperture(),
        focus_distance: s.sampling.lens.map_or(1.0, |l| l.focus_distance),
        accumulation: frames.accumulation.code(),
        normal_mode: normal_code(s.normal_mode),
        run_first: frames.first,
        ..lighting_params(trace)
    }
}

/// The code of a lens in the kernels (`LENS_*`).
pub fn lens_code(lens: &Lens) -> u32 {
    match lens {
        Lens::Pinhole => 0,
        Lens::Perspective(_) => 1,
        Lens::Fisheye(_) => 2,
        Lens::Equirectangular => 3,
    }
}

/// [`Params::distortion`] of a lens (zero without one).
pub(crate) fn distortion(lens: &Lens) -> [[f32; 4]; 3] {
    let d = lens.distortion().copied().unwrap_or_default();
    let [b1, b2, b3] = d.rational;
    let ([p1, p2], [s1, s2]) = (d.tangential, d.prism);
    [d.radial, [b1, b2, b3, 0.0], [p1, p2, s1, s2]]
}

/// The lighting fields of [`Params`] (the rest zero).
fn lighting_params(trace: &TraceScene) -> Params {
    let l = trace.lighting();
    let (shadows, shadow_k, shadow_threshold, shadow_colored) = match l.shadows {
        Shadows::None => (SHADOWS_NONE, 1, 0.0, 0.0),
        Shadows::Sorted { k, threshold, colored } => (SHADOWS_SORTED, k as u32, threshold, colored),
        Shadows::Stochastic => (SHADOWS_STOCHASTIC, 1, 0.0, 0.0),
        Shadows::Exact => (SHADOWS_EXACT, 1, 0.0, 0.0),
    };
    Params {
        lit: u32::from(l.is_on()),
        look: match l.look {
            Look::Surface => LOOK_SURFACE,
            Look::Volumetric => LOOK_VOLUMETRIC,
        },
        shadows,
        shadow_k,
        shadow_threshold,
        shadow_colored,
        shadow_offset: l.shadow_offset,
        light_count: l.lights.len() as u32,
        set_count: l.sets.len() as u32,
        iso_threshold: trace.settings().iso_threshold,
        mesh_root: mesh_root(trace),
        max_bounces: trace.settings().max_bounces,
        ..Params::default()
    }
}

/// `splat_core::path::PathSettings` as `shaders/path.wgsl` reads it (80 bytes; the lens is
/// [`Params`]'s, as the settings' is the path tracer's).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PathParams {
    /// Most bounces off meshes.
    pub max_depth: u32,
    /// Bounces before Russian roulette.
    pub roulette_depth: u32,
    /// The estimator's method code (`METHOD_*`, [`splat_core::MethodId::code`]).
    pub estimator: u32,
    /// Instantiations of stochastic-n.
    pub n: u32,
    /// `SAMPLER_SOBOL` or `SAMPLER_HASH`.
    pub sampler: u32,
    /// `ENVIRONMENT_CONSTANT` or `ENVIRONMENT_GRADIENT`.
    pub environment: u32,
    /// Emissive triangles.
    pub emitters: u32,
    /// Padding.
    pub pad0: u32,
    /// Constant colour or horizon.
    pub env_a: [f32; 4],
    /// Zenith.
    pub env_b: [f32; 4],
    /// Up.
    pub env_up: [f32; 4],
}

/// The kernel's parameters of `settings` with `emitters` emissive triangles; `None` for an
/// estimator the kernel does not run (depth sampling, the CPU's control only).
pub fn path_params(settings: &splat_core::path::PathSettings, emitters: u32) -> Option<PathParams> {
    use splat_core::path::sampler::SamplerKind;
    use splat_core::path::{Environment, GaussianEstimator};
    let n = match settings.gaussians {
        GaussianEstimator::Stochastic | GaussianEstimator::Exact => 1,
        GaussianEstimator::StochasticN { n } => n,
        GaussianEstimator::DepthSampling { .. } => return None,
    };
    let estimator = settings.gaussians.id().code();
    let v4 = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
    let (environment, env_a, env_b, env_up) = match settings.environment {
        Environment::Constant(c) => (ENVIRONMENT_CONSTANT, v4(c), [0.0; 4], [0.0; 4]),
        Environment::Gradient { horizon, zenith, up } => (ENVIRONMENT_GRADIENT, v4(horizon), v4(zenith), v4(up)),
    };
    Some(PathParams {
        max_depth: settings.max_depth,
        roulette_depth: settings.roulette_depth,
        estimator,
        n,
        sampler: match settings.sampler {
            SamplerKind::Sobol => SAMPLER_SOBOL,
            SamplerKind::Hash => SAMPLER_HASH,
        },
        environment,
        emitters,
        pad0: 0,
        env_a,
        env_b,
        env_up,
    })
}

/// Test helpers shared by every module with WGSL: naga's validation and its layout of a WGSL
/// struct, and [`assert_mirrors`] to compare that layout with a Rust mirror.
#[cfg(test)]
pub(crate) mod wgsl_check {
    /// Parse and validate `source` with no optional capability (so no subgroup operations).
    pub(crate) fn validate(name: &str, source: &str) {
        validate_with(name, source, naga::valid::Capabilities::empty());
    }

    /// Parse and validate `source` with only the optional `capabilities`.
    pub(crate) fn validate_with(name: &str, source: &str, capabilities: naga::valid::Capabilities) {
        parse_and_validate(name, source, capabilities);
    }

    fn parse_and_validate(
        name: &str,
        source: &str,
        capabilities: naga::valid::Capabilities,
    ) -> (naga::Module, naga::valid::ModuleInfo) {
        let module =
            naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        (module, info)
    }

    /// What naga needs to validate a module whose split arrays' parts are binding arrays
    /// ([`crate::split::PartBindings::Array`]): the capabilities of the device features the
    /// context asks for them.
    pub(crate) const BINDING_ARRAYS: naga::valid::Capabilities =
        naga::valid::Capabilities::STORAGE_BUFFER_BINDING_ARRAY
            .union(naga::valid::Capabilities::STORAGE_BUFFER_BINDING_ARRAY_NON_UNIFORM_INDEXING);

    /// The storage buffers each entry point of `source` uses (what an automatic layout binds
    /// in its stage), by name.
    pub(crate) fn storage_buffers_used(name: &str, source: &str) -> Vec<(String, u32)> {
        let (module, info) = parse_and_validate(name, source, naga::valid::Capabilities::all());
        module
            .entry_points
            .iter()
            .enumerate()
            .map(|(i, entry_point)| {
                let used = module
                    .global_variables
                    .iter()
                    .filter(|(handle, var)| {
                        matches!(var.space, naga::AddressSpace::Storage { .. })
                            && !info.get_entry_point(i)[*handle].is_empty()
                    })
                    .count();
                (entry_point.name.clone(), used as u32)
            })
            .collect()
    }

    /// Check a bind group layout written in Rust against the bindings the shader declares, as
    /// naga reflects them (all in group 0): each binding has an entry of its kind (read-only or
    /// read-write storage, a texture multisampled or not; never a uniform buffer,
    /// [`crate::context::params_entry`]), visible to every stage whose entry point uses it, a
    /// minimum size, where the layout gives one, at least the WGSL type's; and each entry is a
    /// binding of the shader. wgpu finds the same mistakes only when it creates the
    /// pipeline, on an adapter.
    pub(crate) fn check_layout(
        name: &str,
        source: &str,
        capabilities: naga::valid::Capabilities,
        entries: &[wgpu::BindGroupLayoutEntry],
    ) {
        check_layouts(name, source, capabilities, &[entries]);
    }

    /// [`check_layout`] of a module in several bind groups, `groups[g]` the entries of group g
    /// (a split array's binding arrays are in their own, `crate::split::ARRAY_GROUP`).
    pub(crate) fn check_layouts(
        name: &str,
        source: &str,
        capabilities: naga::valid::Capabilities,
        groups: &[&[wgpu::BindGroupLayoutEntry]],
    ) {
        use naga::{AddressSpace, ImageClass, ShaderStage, StorageAccess, TypeInner};
        use wgpu::{BindingType, BufferBindingType};
        let (module, info) = parse_and_validate(name, source, capabilities);
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let mut declared = Vec::new();
        for (handle, var) in module.global_variables.iter() {
            let Some(binding) = &var.binding else { continue };
            let label = format!(
                "{name}: group {} binding {} ({})",
                binding.group,
                binding.binding,
                var.name.as_deref().unwrap_or("?")
            );
            let entries = groups.get(binding.group as usize).unwrap_or_else(|| panic!("{label}: no such group"));
            declared.push((binding.group, binding.binding));
            let entry = entries
                .iter()
                .find(|e| e.binding == binding.binding)
                .unwrap_or_else(|| panic!("{label} has no entry in the layout"));
            // A binding array (a split array's parts, crate::split) is an entry of its count.
            let (ty, count) = match module.types[var.ty].inner {
                TypeInner::BindingArray { base, size: naga::ArraySize::Constant(n) } => (base, Some(n)),
                _ => (var.ty, None),
            };
            assert_eq!(entry.count, count, "{label}: the layout's count of buffers in the binding");
            match (var.space, entry.ty) {
                (AddressSpace::Uniform, _) => {
                    panic!(
                        "{label} is a uniform buffer: parameters are read-only storage (context::params_entry says why)"
                    )
                }
                (
                    AddressSpace::Storage { access },
                    BindingType::Buffer { ty: BufferBindingType::Storage { read_only }, min_binding_size, .. },
                ) => {
                    let shader = if access.contains(StorageAccess::STORE) { "read_write" } else { "read" };
                    assert_eq!(read_only, !access.contains(StorageAccess::STORE), "{label}: the shader's is {shader}");
                    if let Some(min) = min_binding_size {
                        let size = u64::from(layouter[ty].size);
                        assert!(
                            min.get() >= size,
                            "{label}: the layout's minimum size {min} is below the WGSL type's {size}"
                        );
                    }
                }
                (AddressSpace::Handle, BindingType::Texture { multisampled, .. }) => match module.types[var.ty].inner {
                    TypeInner::Image {
                        class: ImageClass::Sampled { multi, .. } | ImageClass::Depth { multi }, ..
                    } => {
                        assert_eq!(multisampled, multi, "{label}: multisampled");
                    }
                    ref other => panic!("{label}: the layout has a texture, the shader {other:?}"),
                },
                (space, ty) => panic!("{label}: the shader declares {space:?}, the layout {ty:?}"),
            }
            for (i, entry_point) in module.entry_points.iter().enumerate() {
                if info.get_entry_point(i)[handle].is_empty() {
                    continue;
                }
                let stage = match entry_point.stage {
                    ShaderStage::Vertex => wgpu::ShaderStages::VERTEX,
                    ShaderStage::Fragment => wgpu::ShaderStages::FRAGMENT,
                    ShaderStage::Compute => wgpu::ShaderStages::COMPUTE,
                    other => panic!("{name}: no stage {other:?} in this crate"),
                };
                assert!(
                    entry.visibility.contains(stage),
                    "{label}: {} ({:?}) uses it, the layout hides it from that stage",
                    entry_point.name,
                    entry_point.stage
                );
            }
        }
        for (group, entries) in groups.iter().enumerate() {
            for entry in *entries {
                assert!(
                    declared.contains(&(group as u32, entry.binding)),
                    "{name}: the layout's entry {} of group {group} is no binding of the shader",
                    entry.binding
                );
            }
        }
    }

    /// Size and (member name, offset) list of the WGSL struct `name` of `source`, as naga lays
    /// it out.
    pub(crate) fn struct_layout(source: &str, name: &str) -> (usize, Vec<(String, usize)>) {
        let module = naga::front::wgsl::parse_str(source).expect("parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (_, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect(name);
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
        (*span as usize, members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect())
    }

    /// The value of the WGSL constant `name` of `source` as naga parses it: a u32, i32 or f32
    /// literal, or an array of them, as f64 (one comparison serves every type).
    pub(crate) fn constant(source: &str, name: &str) -> Vec<f64> {
        let module = naga::front::wgsl::parse_str(source).expect("parses");
        let (_, c) = module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(name)).expect(name);
        values(&module, c.init, name)
    }

    fn values(module: &naga::Module, expr: naga::Handle<naga::Expression>, name: &str) -> Vec<f64> {
        match &module.global_expressions[expr] {
            naga::Expression::Literal(naga::Literal::U32(v)) => vec![f64::from(*v)],
            naga::Expression::Literal(naga::Literal::I32(v)) => vec![f64::from(*v)],
            naga::Expression::Literal(naga::Literal::F32(v)) => vec![f64::from(*v)],
            naga::Expression::Compose { components, .. } => {
                components.iter().flat_map(|&c| values(module, c, name)).collect()
            }
            other => panic!("{name} is not a literal or an array of literals: {other:?}"),
        }
    }

    /// Each WGSL constant equals its Rust twin: `assert_constants!(SOURCE, [NAME = value, …])`.
    macro_rules! assert_constants {
        ($source:expr, [$($name:literal = $value:expr),* $(,)?]) => {{
            $(
                let wgsl = $crate::layout::wgsl_check::constant($source, $name);
                assert_eq!(wgsl, vec![$value as f64], "WGSL {} = {wgsl:?}, Rust {}", $name, stringify!($value));
            )*
        }};
    }
    pub(crate) use assert_constants;

    /// The Rust struct has the size and field offsets naga computes for the WGSL struct of the
    /// same role, so the two cannot drift apart.
    macro_rules! assert_mirrors {
        ($source:expr, $rust:ty, $wgsl:literal, [$($field:ident),*]) => {{
            let (size, members) = $crate::layout::wgsl_check::struct_layout($source, $wgsl);
            assert_eq!(std::mem::size_of::<$rust>(), size, "size of {}", $wgsl);
            let rust = vec![$((stringify!($field).to_string(), std::mem::offset_of!($rust, $field))),*];
            assert_eq!(rust, members, "fields of {}", $wgsl);
        }};
    }
    pub(crate) use assert_mirrors;
}

#[cfg(test)]
mod tests {
    use super::wgsl_check::{assert_constants, assert_mirrors, constant, validate};
    use super::*;
    use splat_core::camera::Distortion;

    /// A part of the SH array made alone ([`sh_range`], as the tracer uploads it) is those
    /// coefficients of the whole array, in every storage: ranges that start and end inside a
    /// particle's coefficients, the empty one and the whole.
    #[test]
    fn sh_parts_are_slices_of_the_whole_array() {
        let particle = |i: usize| {
            let sh: [glam::Vec3; 16] = std::array::from_fn(|k| glam::Vec3::new(0.1 * k as f32, -0.03 * i as f32, 0.2));
            splat_core::Particle::new(glam::Vec3::ZERO, glam::Vec3::ONE, glam::Quat::IDENTITY, 0.5, sh).unwrap()
        };
        let scene = Scene::new((0..5).map(particle).collect(), 2);
        assert_eq!(sh_len(&scene), 45);
        for storage in [ShStorage::F32, ShStorage::F16, ShStorage::U8] {
            let (whole, w) = (sh_range(&scene, storage, 0..45), sh_words(storage));
            assert_eq!(whole.len(), 45 * w);
            for (a, b) in [(0, 45), (0, 0), (7, 20), (20, 45), (44, 45)] {
                assert_eq!(
                    sh_range(&scene, storage, a..b),
                    whole[a as usize * w..b as usize * w],
                    "{storage:?} {a}..{b}"
                );
            }
        }
    }

    /// The kernels that draw every triangle opaque refuse a transparent mesh before any upload,
    /// naming the raster operations and the CPU as the remedies; opaque meshes pass; the ray
    /// tracer and the raster operations take transparent ones (and the path tracer, which
    /// `gpu_paths_are_the_cpu_paths` renders with them).
    #[test]
    fn transparent_meshes_are_refused() {
        use splat_core::mesh::{MeshMaterial, Meshes, TriangleMesh};
        let mesh =
            |opacity| Meshes::new(&[(TriangleMesh::plane(), MeshMaterial { opacity, ..MeshMaterial::default() })]);
        assert!(check_opaque(&mesh(1.0).unwrap(), "the GPU hybrid").is_ok());
        let refused = check_opaque(&mesh(0.5).unwrap(), "the GPU hybrid").unwrap_err().to_string();
        assert!(refused.contains("the GPU hybrid draws no transparent") && refused.contains("CPU"), "{refused}");
        assert!(refused.contains("Enderton or stratified"), "{refused}");
        // Which pipelines draw them: the ray tracer and the raster operations, not the hybrid or
        // sorted splatting.
        use splat_core::raster::{RasterMethod, RasterSettings};
        use splat_core::{Algorithm, trace::Method};
        let half = mesh(0.5).unwrap();
        let raster = |m| Algorithm::Raster(m, RasterSettings::default());
        for drawn in [Algorithm::Trace(Method::Exact), raster(RasterMethod::Enderton)] {
            assert!(crate::supports_meshes(&drawn, &half).is_ok(), "{drawn:?}");
        }
        let hybrid = Algorithm::Hybrid(RasterMethod::StochasticSplat, RasterSettings::default(), Method::Exact);
        for refused in [raster(RasterMethod::StochasticSplat), hybrid] {
            assert!(crate::supports_meshes(&refused, &half).is_err(), "{refused:?}");
        }
    }

    /// Size and every field offset of each Rust struct equal those naga computes for the WGSL
    /// struct of the same role, so the two cannot drift apart.
    #[test]
    fn rust_structs_mirror_the_wgsl_structs() {
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuParticle,
            "Particle",
            [mean, opacity, row0, id, row1, extent, row2, pad2]
        );
        assert_mirrors!(&crate::TRACE_WGSL, GpuNode, "Node", [origin, planes_xy, planes_z, child]);
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuFirstHit,
            "FirstHit",
            [radiance, transmittance, normal, depth, picked, pad0, offset, fragments, pad1]
        );
        assert_mirrors!(&crate::TRACE_WGSL, GpuFragment, "Fragment", [color, weight, normal, t, id, pad0, pad1, pad2]);
        assert_mirrors!(
            &crate::TRACE_WGSL,
            PassState,
            "PassState",
            [radiance, transmittance, after_t, after_id, flags, picked, normal, depth]
        );
        assert_mirrors!(&crate::TRACE_WGSL, GpuPick, "Pick", [normal, depth, picked, pad0, pad1, pad2]);
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuMaterial,
            "Material",
            [emissive, first, ambient, shininess, diffuse, emissive_only, specular, pad]
        );
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuLight,
            "Light",
            [position, kind, direction, radius, color, intensity, cos_inner, cos_outer, pad0, pad1]
        );
        assert_mirrors!(
            &crate::TRACE_WGSL,
            Params,
            "Params",
            [
                cam_row0,
                cam_row1,
                cam_row2,
                cam_center,
                intrinsics,
                background,
                size,
                sh_degree,
                method,
                k,
                max_passes,
                n,
                m,
                seed,
                frames,
                rng_scheme,
                hit_distance,
                kernel_degree,
                cutoff,
                alpha_clamp,
                alpha_cull,
                t_min,
                t_max,
                min_transmittance,
                first_frame,
                mode,
                pass_index,
                u_shift,
                lit,
                look,
                shadows,
                shadow_k,
                shadow_threshold,
                shadow_colored,
                shadow_offset,
                light_count,
                set_count,
                iso_threshold,
                mesh_root,
                max_bounces,
                lens,
                distortion,
                pixel_filter,
                aperture,
                focus_distance,
                accumulation,
                normal_mode,
                first_hit,
                raster_samples,
                run_first
            ]
        );
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuTriangle,
            "Triangle",
            [p0, mesh, e1, alpha0, e2, alpha1, n0, alpha2, n1, order, n2, pad]
        );
        assert_mirrors!(
            &crate::TRACE_WGSL,
            GpuMeshMaterial,
            "MeshMaterial",
            [color, mirror, transmission, ior, roughness, specular_layer, mirror_tint, pad2, shading]
        );
        assert_mirrors!(
            &crate::TRACE_WGSL,
            PathParams,
            "PathParams",
            [max_depth, roulette_depth, estimator, n, sampler, environment, emitters, pad0, env_a, env_b, env_up]
        );
    }

    /// The kernel's layout matches its WGSL whole and split: every part of a split array is a
    /// binding of the module and an entry of the layout.
    #[test]
    fn trace_layout_matches_the_shader() {
        use crate::split::Split;
        let whole = crate::TraceSplit::WHOLE;
        let split = crate::TraceSplit {
            particles: Split { parts: 3, shift: 4 },
            nodes: Split { parts: 2, shift: 6 },
            sh: Split { parts: 5, shift: 7 },
            sh_storage: splat_core::sh::ShStorage::F32,
            parts: crate::split::PartBindings::Each,
        };
        let half = crate::TraceSplit { sh_storage: splat_core::sh::ShStorage::F16, ..split };
        let arrayed = crate::TraceSplit { parts: crate::split::PartBindings::Array, ..half };
        for split in [whole, split, half, arrayed] {
            let entries = crate::trace::TracePipeline::layout_entries(&split);
            let arrays = crate::trace::TracePipeline::array_entries(&split);
            let source = split.wgsl();
            let arrayed = split.parts == crate::split::PartBindings::Array;
            let capabilities = if arrayed { wgsl_check::BINDING_ARRAYS } else { naga::valid::Capabilities::empty() };
            wgsl_check::check_layouts("trace", &source, capabilities, &[&entries, &arrays]);
        }
        assert_eq!(crate::trace::TracePipeline::layout_entries(&split).len(), 18 + 2 + 1 + 4);
        // In binding arrays: group 0 the kernel's own, group 1 one binding array an array, of its
        // parts after the first.
        assert_eq!(crate::trace::TracePipeline::layout_entries(&arrayed).len(), 18);
        let arrays = crate::trace::TracePipeline::array_entries(&arrayed);
        let counts: Vec<_> = arrays.iter().map(|e| e.count.map(|c| c.get())).collect();
        assert_eq!(counts, [Some(2), Some(1), Some(4)]);
    }

    /// Every constant the kernel shares with the core has the core's value: the method
    /// identities, the fixed array sizes, the reserved decision ids and the SH constants.
    #[test]
    fn trace_constants_equal_their_rust_twins() {
        use splat_core::{bvh, rng, sh, trace};
        // A METHOD_* constant for every method of the catalogue the kernel runs, and no other.
        let module = naga::front::wgsl::parse_str(&crate::TRACE_WGSL).expect("parses");
        let mut wgsl: Vec<String> = module
            .constants
            .iter()
            .filter_map(|(_, c)| c.name.clone())
            .filter(|name| name.starts_with("METHOD_"))
            .collect();
        let mut catalogue = Vec::new();
        for id in splat_core::MethodId::of(splat_core::catalogue::Family::Trace).filter(|m| m.entry().gpu) {
            let name = id.wgsl_constant();
            assert_eq!(constant(&crate::TRACE_WGSL, &name), vec![f64::from(id.code())], "{name}");
            catalogue.push(name);
        }
        wgsl.sort();
        catalogue.sort();
        assert_eq!(wgsl, catalogue, "the kernel's METHOD_* constants and the catalogue's GPU ray-tracing methods");
        assert_constants!(
            &crate::TRACE_WGSL,
            [
                "MAX_HITS" = trace::MAX_HITS,
                "WIDE_STACK" = bvh::WIDE_STACK,
                "LEAF" = bvh::LEAF,
                "COUNT_SHIFT" = bvh::COUNT_SHIFT,
                "ROOT" = bvh::ROOT,
                "PASS_ID" = rng::PASS_ID,
                "OFFSET_ID" = rng::OFFSET_ID,
                "LOOP_BUDGET" = crate::LOOP_BUDGET,
                "MODE_FRAMES" = MODE_FRAMES,
                "MODE_PASS" = MODE_PASS,
                "MODE_HYBRID" = MODE_HYBRID,
                "LIGHT_ID" = rng::LIGHT_ID,
                "LOOK_SURFACE" = LOOK_SURFACE,
                "LOOK_VOLUMETRIC" = LOOK_VOLUMETRIC,
                "SHADOWS_NONE" = SHADOWS_NONE,
                "SHADOWS_SORTED" = SHADOWS_SORTED,
                "SHADOWS_STOCHASTIC" = SHADOWS_STOCHASTIC,
                "SHADOWS_EXACT" = SHADOWS_EXACT,
                "LIGHT_POINT" = LIGHT_POINT,
                "LIGHT_SPOT" = LIGHT_SPOT,
                "LIGHT_DIRECTIONAL" = LIGHT_DIRECTIONAL,
                "SH_C0" = sh::SH_C0,
                "SH_C1" = sh::SH_C1,
                "NONE" = NO_MESHES,
                "EDGE_SLACK" = splat_core::mesh::EDGE_SLACK,
                "SURFACE_OFFSET" = splat_core::trace::SURFACE_OFFSET,
                "BOUNCE_SHIFT" = splat_core::trace::BOUNCE_SHIFT,
                "SHADOW_BOUNCE_SHIFT" = splat_core::trace::SHADOW_BOUNCE_SHIFT,
                "LAYER_PASS_SHIFT" = splat_core::trace::LAYER_PASS_SHIFT,
                "MAX_BOUNCES" = splat_core::settings::MAX_BOUNCES,
                "PATH_DIM_ID" = splat_core::path::sampler::PATH_DIM_ID,
                "LIGHT_STREAM" = splat_core::path::sampler::LIGHT_STREAM,
                "DIMS_PER_BOUNCE" = splat_core::path::sampler::Dim::PER_BOUNCE,
                "SOBOL_DIMENSIONS" = splat_core::path::sampler::SOBOL_DIMENSIONS,
                "MIN_ROUGHNESS" = splat_core::path::bsdf::MIN_ROUGHNESS,
                "RNG_HASH" = RNG_HASH,
                "RNG_TRIG" = RNG_TRIG,
                "HIT_MEAN" = HIT_MEAN,
                "LENS_PINHOLE" = lens_code(&Lens::Pinhole),
                "LENS_PERSPECTIVE" = lens_code(&Lens::Perspective(Distortion::default())),
                "LENS_FISHEYE" = lens_code(&Lens::Fisheye(Distortion::default())),
                "LENS_EQUIRECTANGULAR" = lens_code(&Lens::Equirectangular),
                "UNDISTORT_STEPS" = splat_core::lens::UNDISTORT_STEPS,
                "UNDISTORT_TOLERANCE_F32" = splat_core::lens::UNDISTORT_TOLERANCE_F32,
                "HIT_CENTER" = HIT_CENTER,
                "HIT_ICOSAHEDRON" = HIT_ICOSAHEDRON,
                "CENTER_VIEW_COS_MIN" = splat_core::hit::CENTER_VIEW_COS_MIN,
                "DEGENERATE_NORMAL" = splat_core::composite::DEGENERATE_NORMAL as f32,
                "NORMAL_PLANE" = normal_code(splat_core::normal::NormalMode::MaxDensityPlane),
                "NORMAL_ELLIPSOID" = normal_code(splat_core::normal::NormalMode::KernelEllipsoid),
                "SAMPLER_SOBOL" = SAMPLER_SOBOL,
                "FILTER_CENTER" = FILTER_CENTER,
                "FILTER_BOX" = FILTER_BOX,
                "FIRST_HIT_ACCEPTED" = FIRST_HIT_ACCEPTED,
                "FIRST_HIT_FRAGMENTS" = FIRST_HIT_FRAGMENTS,
                "FRAME_SOBOL_SALT" = splat_core::camera_sampling::FRAME_SOBOL_SALT,
                "ACCUMULATION_F32" = splat_core::frame::AccumulationFormat::F32.code(),
                "ACCUMULATION_F16" = splat_core::frame::AccumulationFormat::F16.code(),
                "ACCUMULATION_UNORM8" = splat_core::frame::AccumulationFormat::Unorm8.code(),
                "SAMPLER_HASH" = SAMPLER_HASH,
                "ENVIRONMENT_CONSTANT" = ENVIRONMENT_CONSTANT,
                "ENVIRONMENT_GRADIENT" = ENVIRONMENT_GRADIENT,
            ]
        );
        let f64s = |v: &[f32]| v.iter().map(|&c| f64::from(c)).collect::<Vec<_>>();
        assert_eq!(constant(&crate::TRACE_WGSL, "SH_C2"), f64s(&sh::SH_C2), "SH_C2");
        assert_eq!(constant(&crate::TRACE_WGSL, "SH_C3"), f64s(&sh::SH_C3), "SH_C3");
    }

    /// The kernel is valid WGSL for naga's validator (a shader error fails `cargo test`).
    #[test]
    fn trace_wgsl_validates() {
        validate("trace", &crate::TRACE_WGSL);
    }

    /// docs/architecture.md's table of shaders and their CPU twins names every shader file:
    /// a new shader (or a split one) cannot go undocumented.
    #[test]
    fn every_shader_has_a_row_in_the_twin_table() {
        let crate_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let doc = std::fs::read_to_string(crate_dir.join("../../docs/architecture.md")).expect("the design document");
        let table: Vec<&str> = doc.lines().filter(|l| l.starts_with("| `")).collect();
        let mut missing = Vec::new();
        for entry in std::fs::read_dir(crate_dir.join("shaders")).expect("the shaders") {
            let name = entry.expect("a shader").file_name().to_string_lossy().into_owned();
            if name.ends_with(".wgsl") && !table.iter().any(|row| row.contains(&format!("`{name}`"))) {
                missing.push(name);
            }
        }
        assert!(missing.is_empty(), "shaders without a row in docs/architecture.md's twin table: {missing:?}");
    }
}
