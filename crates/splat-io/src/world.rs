//! World files: splat sets with transforms and materials, lights, shadows and a camera, in TOML
//! (docs/architecture.md, "Lighting"). A bare `.ply` or `.splat` is a world of one emissive set.
//!
//! ```toml
//! background = [0.02, 0.02, 0.03]
//! look = "surface"                 # sorted methods: "surface" (lit once) or "volumetric"
//! sh_storage = "f16"               # f32 (default) | f16 | u8: how the SH coefficients are stored
//!
//! [shadows]
//! kind = "stochastic"              # none | sorted | stochastic | exact
//! offset = 0.05                    # shadow-ray origin offset along the light (vk default 0.2)
//!
//! [camera]
//! eye = [0.0, 1.9, 3.6]
//! target = [0.0, 0.75, 0.0]
//! fov = 45                          # vertical, degrees; up = [0, 1, 0] unless given
//! width = 640
//! height = 480
//! aperture = 0.03                   # thin-lens radius, every pipeline (0 or absent: pinhole)
//! focus_distance = 3.5              # plane in focus (default: eye to target along the view)
//! pixel_filter = "box"              # center (default) | box: a point of the pixel per frame
//!
//! [environment]                     # where paths escape (path tracer; default: the background)
//! horizon = [0.6, 0.55, 0.5]        # or color = [r, g, b] for a constant environment
//! zenith = [0.25, 0.35, 0.6]
//! up = [0.0, 1.0, 0.0]
//!
//! [[splats]]
//! builtin = "demo"                  # or file = "bonsai.splat" (relative to this file)
//! translate = [0.0, 0.0, 0.0]
//! rotate = [0.0, 0.0, 0.0]          # degrees about x, then y, then z
//! scale = 1.0
//! sh_degree = 3                     # drop the SH bands above (baked lighting)
//! material = { emissive = 0.1, ambient = 0.1, diffuse = 0.8, specular = 0.3, shininess = 32 }
//!
//! [[lights]]
//! kind = "spot"                     # point | spot | directional
//! position = [1.5, 3.0, 1.5]
//! target = [0.0, 0.5, 0.0]          # or direction = [x, y, z]
//! inner = 20                        # spot half-angles, degrees
//! outer = 30
//! color = [1.0, 0.95, 0.9]          # a colour is [r, g, b] or one number
//! intensity = 12
//! radius = 0.05                     # soft shadows
//!
//! [[meshes]]                        # triangles beside the splats (splat_core::mesh)
//! shape = "sphere"                  # plane | cube | sphere, or file = "pedestal.obj" / ".gltf" / ".glb"
//! segments = 48                     # sphere tessellation (around; half as many rings)
//! translate = [0.8, 0.5, 0.6]
//! rotate = [0.0, 0.0, 0.0]
//! scale = 0.4                       # one number or [x, y, z]
//! color = [0.9, 0.9, 0.9]
//! material = { ambient = 0.1, diffuse = 0.9 }
//! transmission = 0.9                # glass: Fresnel mix of reflection and refraction
//! ior = 1.5
//! mirror = 0.0                      # perfect mirror share
//! mirror_tint = [1.0, 1.0, 1.0]     # its reflectance at normal incidence (Schlick's F₀)
//! roughness = 0.0                   # GGX roughness of mirror and glass (path tracer only)
//! specular_layer = false            # a dielectric specular layer over the base (path tracer only)
//! opacity = 1.0                     # α in (0, 1]: below 1 a transparent layer
//! ```
//!
//! A material table sets the colours it names and leaves the others at 0 (shininess 32); a set
//! without one is fully emissive, a mesh without one matte (ambient 0.1, diffuse 0.9). A glTF
//! file's triangles are a mesh for each of its materials, read as
//! [`crate::mesh::gltf_material`] maps them, each key of the entry overriding them (a `color`
//! keeps what a lit part emits, and retints a metal, whose tint is its base colour). Particle ids run over the sets in file order. `max_bounces`
//! (top level, default 3) limits mirror and glass bounces. `iso_threshold` and `raster_iso_threshold` (top level, default 0.7 each) are the
//! transmittance at which the ray tracers and splatting pick a pixel's surface
//! (vk_gaussian_splatting Lighting §1.1: two values, one per panel). What the file sets is the
//! render's default, which the front ends' flags override ([`WorldSpec::settings`]).

use crate::{Error, ErrorKind};
use glam::{EulerRot, Quat, Vec3};
use serde::Deserialize;
use splat_core::RenderSettings;
use splat_core::camera_sampling::{CameraSampling, PixelFilter, ThinLens};
use splat_core::lighting::{Light, LightKind, Lighting, Look, Material, Shadows, SplatSet};
use splat_core::mesh::{MeshMaterial, TriangleMesh};
use splat_core::particle::sh_coeff_count;
use splat_core::path::Environment;
use splat_core::sh::{Rotation, ShStorage};
use splat_core::trainer::Trained;
use splat_core::{Camera, Scene, ScreenFilter};
use std::path::{Path, PathBuf};

/// A world as a file specifies it: the particles of every set in one id space, their lighting,
/// the meshes as triangles, and the camera, background, bounce limit, environment and lens when
/// the file gives them. A front end applies its options to it and builds what renders, a
/// [`splat_core::World`] (the meshes' BVH with it).
#[derive(Clone, Debug)]
pub struct WorldSpec {
    /// All sets' particles, set after set.
    pub scene: Scene,
    /// Materials per set, lights, shadows, look.
    pub lighting: Lighting,
    /// The file's camera, or the built-in scene's when the file has none and its first set is
    /// built in.
    pub camera: Option<Camera>,
    /// The file's background colour.
    pub background: Option<Vec3>,
    /// Meshes in world space with their materials.
    pub meshes: Vec<PlacedMesh>,
    /// The file's bounce limit.
    pub max_bounces: Option<u32>,
    /// The file's iso-opacity threshold of the ray tracers.
    pub iso_threshold: Option<f32>,
    /// The file's iso-opacity threshold of splatting.
    pub raster_iso_threshold: Option<f32>,
    /// The path tracer's environment (`[environment]`), if the file gives one.
    pub environment: Option<Environment>,
    /// The camera's thin lens (`aperture` and `focus_distance` in `[camera]`), if any.
    pub lens: Option<ThinLens>,
    /// Where the camera's rays pass through their pixels (`pixel_filter` in `[camera]`).
    pub pixel_filter: Option<PixelFilter>,
    /// How the SH coefficients are stored (`sh_storage`, top level).
    pub sh_storage: Option<ShStorage>,
    /// What the readers noted (a scene file's skipped records; glTF textures, vertex colours,
    /// extensions the mesh reader could not represent), for front ends to print.
    pub notes: Vec<String>,
}

impl WorldSpec {
    /// `base` with what the file sets: its background, bounce limit, iso thresholds, pixel
    /// filter and SH storage, over the kernel, near plane and background of the renderer its
    /// splats were trained through where their file or run says ([`Scene::trained`]).
    pub fn settings(&self, base: RenderSettings) -> RenderSettings {
        let base = self.scene.trained.map_or(base, |trained| trained.settings(base));
        RenderSettings {
            sh_storage: self.sh_storage.unwrap_or(base.sh_storage),
            sampling: CameraSampling { filter: self.pixel_filter.unwrap_or(base.sampling.filter), ..base.sampling },
            background: self.background.unwrap_or(base.background),
            max_bounces: self.max_bounces.unwrap_or(base.max_bounces),
            iso_threshold: self.iso_threshold.unwrap_or(base.iso_threshold),
            raster_iso_threshold: self.raster_iso_threshold.unwrap_or(base.raster_iso_threshold),
            ..base
        }
    }

    /// A world of one emissive set: how a bare `.ply` or `.splat` renders.
    pub fn of(scene: Scene) -> Self {
        Self {
            scene,
            lighting: Lighting::default(),
            camera: None,
            background: None,
            meshes: Vec::new(),
            max_bounces: None,
            iso_threshold: None,
            raster_iso_threshold: None,
            environment: None,
            lens: None,
            pixel_filter: None,
            sh_storage: None,
            notes: Vec::new(),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldFile {
    background: Option<[f32; 3]>,
    look: Option<LookName>,
    shadows: Option<ShadowsFile>,
    camera: Option<CameraFile>,
    #[serde(default)]
    splats: Vec<SplatsFile>,
    #[serde(default)]
    lights: Vec<LightFile>,
    #[serde(default)]
    meshes: Vec<MeshFile>,
    max_bounces: Option<u32>,
    iso_threshold: Option<f32>,
    raster_iso_threshold: Option<f32>,
    sh_storage: Option<String>,
    environment: Option<EnvironmentFile>,
}

/// The environment a path escapes to: a constant colour, or a gradient from the horizon to the
/// zenith.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnvironmentFile {
    color: Option<Colour>,
    horizon: Option<Colour>,
    zenith: Option<Colour>,
    up: Option<[f32; 3]>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum ShapeName {
    Plane,
    Cube,
    Sphere,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshFile {
    shape: Option<ShapeName>,
    file: Option<PathBuf>,
    segments: Option<u32>,
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<Colour>,
    color: Option<Colour>,
    material: Option<MaterialFile>,
    mirror: Option<f32>,
    mirror_tint: Option<Colour>,
    transmission: Option<f32>,
    ior: Option<f32>,
    roughness: Option<f32>,
    specular_layer: Option<bool>,
    opacity: Option<f32>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum LookName {
    Surface,
    Volumetric,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum ShadowKind {
    None,
    Sorted,
    Stochastic,
    Exact,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShadowsFile {
    kind: ShadowKind,
    offset: Option<f32>,
    k: Option<usize>,
    threshold: Option<f32>,
    colored: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    eye: [f32; 3],
    target: [f32; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
    width: Option<u32>,
    height: Option<u32>,
    aperture: Option<f32>,
    focus_distance: Option<f32>,
    pixel_filter: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SplatsFile {
    file: Option<PathBuf>,
    builtin: Option<String>,
    translate: Option<[f32; 3]>,
    rotate: Option<[f32; 3]>,
    scale: Option<f32>,
    sh_degree: Option<u8>,
    material: Option<MaterialFile>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(untagged)]
enum Colour {
    Grey(f32),
    Rgb([f32; 3]),
}

impl Colour {
    fn rgb(self) -> Vec3 {
        match self {
            Colour::Grey(g) => Vec3::splat(g),
            Colour::Rgb(c) => Vec3::from(c),
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MaterialFile {
    emissive: Option<Colour>,
    ambient: Option<Colour>,
    diffuse: Option<Colour>,
    specular: Option<Colour>,
    shininess: Option<f32>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum LightKindName {
    Point,
    Spot,
    Directional,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightFile {
    kind: LightKindName,
    position: Option<[f32; 3]>,
    direction: Option<[f32; 3]>,
    target: Option<[f32; 3]>,
    inner: Option<f32>,
    outer: Option<f32>,
    color: Option<Colour>,
    intensity: Option<f32>,
    radius: Option<f32>,
}

/// Whether `path` names a world file (extension `.toml`, any case) rather than a scene file.
pub fn is_world_file(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"))
}

/// What a front end opens ([`open_world`]).
#[derive(Clone, Debug)]
pub struct Opened {
    /// The world: a world file's, a scene file's as one emissive set, or the demo's.
    pub world: WorldSpec,
    /// Its name for titles and messages: the file name, or `demo`.
    pub name: String,
    /// `.ply` vertex properties the reader skipped as unknown (see [`crate::ReadOptions`]).
    pub skipped_properties: Vec<String>,
    /// The reader's notes ([`crate::SceneRead::notes`]).
    pub notes: Vec<String>,
}

/// Open what the user named: a world file (`.toml`), a scene file (`.ply`, compressed `.ply`,
/// `.splat`, `.spz`) as a world of one emissive set, or, for `None`, the built-in demo with
/// its camera. A world with neither splats nor meshes is refused ([`ErrorKind::Empty`]), so
/// that no front end opens a window or starts a render on nothing.
pub fn open_world(path: Option<&Path>, options: crate::ReadOptions) -> Result<Opened, Error> {
    let Some(path) = path else {
        let (scene, camera) = splat_core::scenes::demo();
        let world = WorldSpec { camera: Some(camera), ..WorldSpec::of(scene) };
        return Ok(Opened { world, name: "demo".into(), skipped_properties: Vec::new(), notes: Vec::new() });
    };
    let (world, skipped_properties) = if is_world_file(path) {
        (read_world_as(path, options.screen_filter)?, Vec::new())
    } else if matches!(crate::extension(path).as_deref(), Some("glb" | "gltf")) {
        (read_gltf_world(path, options)?, Vec::new())
    } else {
        let read = crate::read_scene_with(path, options)?;
        (WorldSpec { notes: read.notes, ..WorldSpec::of(read.scene) }, read.skipped_properties)
    };
    let notes = world.notes.clone();
    if world.scene.particles.is_empty() && world.meshes.is_empty() {
        return Err(Error::new(path, ErrorKind::Empty));
    }
    let name = crate::file_name(path);
    Ok(Opened { world, name, skipped_properties, notes })
}

/// A glTF file as a world: its `KHR_gaussian_splatting` splats ([`crate::gltf_splats`]) and
/// its triangles, a mesh for each material ([`crate::mesh::parse_gltf`], which skips the
/// splats; primitives without a material are matte), either of which may be absent.
fn read_gltf_world(path: &Path, options: crate::ReadOptions) -> Result<WorldSpec, Error> {
    let bytes = crate::read_file(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut scene = crate::gltf_splats::splats_in(&bytes, base).map_err(|kind| Error::new(path, kind))?;
    if let Some(filter) = options.screen_filter {
        scene.screen_filter = filter;
    }
    let read = crate::mesh::parse_gltf(&bytes, base).map_err(|m| Error::new(path, ErrorKind::Mesh(m)))?;
    let mut world = WorldSpec::of(scene);
    for part in read.parts.into_iter().filter(|p| !p.mesh.triangles.is_empty()) {
        part.mesh.validate().map_err(|m| Error::new(path, ErrorKind::Mesh(m)))?;
        world.meshes.push((part.mesh, part.material.unwrap_or_default()));
    }
    world.notes = read.notes;
    Ok(world)
}

/// Read a world file (`.toml`); set files are resolved relative to its folder.
pub fn read_world(path: &Path) -> Result<WorldSpec, Error> {
    read_world_as(path, None)
}

/// Read a world file whose splats render through `screen_filter`, whatever their files say
/// (`None`: the filter their files name, which must agree).
fn read_world_as(path: &Path, screen_filter: Option<ScreenFilter>) -> Result<WorldSpec, Error> {
    let text = String::from_utf8(crate::read_file(path)?)
        .map_err(|e| Error::new(path, ErrorKind::World(format!("not UTF-8 text: {e}"))))?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse_world(&text, base, screen_filter).map_err(|message| Error::new(path, ErrorKind::World(message)))
}

/// A file a world entry names that could not be read: the entry's key and file as the world
/// file spells them, then the reader's error (which names the resolved path).
/// A missing file under `target/assets/` is the repository's pinned capture, which the fixture
/// worlds name: the message says how to fetch it.
fn named_file(file: &Path, error: Error) -> String {
    let missing = matches!(&error.kind, ErrorKind::Io(e) if e.kind() == std::io::ErrorKind::NotFound);
    let asset = missing
        && file.components().any(|c| c.as_os_str() == "assets")
        && file.components().any(|c| c.as_os_str() == "target");
    let hint =
        if asset { " (`cargo xtask assets` fetches the repository's real capture into target/assets)" } else { "" };
    format!("file = {:?} cannot be read: {error}{hint}", file.display().to_string())
}

/// Parse world-file text; set files are resolved relative to `base`; `screen_filter` as in
/// [`read_world_as`].
fn parse_world(text: &str, base: &Path, screen_filter: Option<ScreenFilter>) -> Result<WorldSpec, String> {
    let file: WorldFile = toml::from_str(text).map_err(|e| e.to_string())?;
    if file.splats.is_empty() {
        return Err("no [[splats]] set: a world needs at least one".to_string());
    }
    let mut scene = Scene::default();
    let mut sets = Vec::new();
    let mut camera = None;
    let mut notes = Vec::new();
    let mut first_trained = None;
    for (i, set) in file.splats.iter().enumerate() {
        if let Some(d) = set.sh_degree.filter(|&d| d > 3) {
            return Err(format!("splats[{i}]: sh_degree {d} is above 3"));
        }
        let (mut particles, builtin_camera) = load_set(set, base).map_err(|m| format!("splats[{i}]: {m}"))?;
        if i == 0 {
            camera = builtin_camera;
            scene.screen_filter = screen_filter.unwrap_or(particles.screen_filter);
        } else if screen_filter.is_none() && particles.screen_filter != scene.screen_filter {
            return Err(format!(
                "splats[{i}] was trained with {} but splats[0] with {}: a world's splats render through one \
                 screen-space filter (choose one for all of them, or render the sets apart)",
                particles.screen_filter.describe(),
                scene.screen_filter.describe()
            ));
        }
        if i == 0 {
            (scene.trained, first_trained) = (particles.trained, particles.trained);
        } else if particles.trained != first_trained && scene.trained == first_trained {
            let said = |trained: Option<Trained>| {
                trained.map_or("names no renderer".into(), |t| format!("was trained through {}", t.describe()))
            };
            notes.push(format!(
                "splats[{i}] {} but splats[0] {}: a world's splats render with one kernel, near plane and \
                 background, the defaults where no preset, kernel or background is chosen",
                said(particles.trained),
                said(first_trained)
            ));
            scene.trained = None;
        }
        if let Some(d) = set.sh_degree {
            truncate_sh(&mut particles, d);
        }
        transform(&mut particles, set).map_err(|m| format!("splats[{i}]: {m}"))?;
        let material = set.material.as_ref().map_or(Material::EMISSIVE, material);
        if !particles.particles.is_empty() {
            sets.push(SplatSet { first: scene.particles.len() as u32, material });
        }
        scene.sh_degree = scene.sh_degree.max(particles.sh_degree);
        scene.particles.append(&mut particles.particles);
    }
    if sets.is_empty() {
        sets.push(SplatSet { first: 0, material: Material::EMISSIVE });
    }
    let lights = file
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| light(l).map_err(|m| format!("lights[{i}]: {m}")))
        .collect::<Result<_, _>>()?;
    let (shadows, shadow_offset) = shadows(file.shadows.as_ref());
    let look = match file.look {
        Some(LookName::Volumetric) => Look::Volumetric,
        _ => Look::Surface,
    };
    let lighting = Lighting { sets, lights, shadows, shadow_offset, look };
    lighting.validate(scene.particles.len())?;
    if let Some(c) = &file.camera {
        camera = Some(camera_from(c)?);
    }
    let background = file.background.map(Vec3::from);
    if background.is_some_and(|b| !b.is_finite()) {
        return Err("background is not finite".to_string());
    }
    let mut meshes = Vec::new();
    for (i, m) in file.meshes.iter().enumerate() {
        let (parts, read_notes) = load_mesh(m, base).map_err(|e| format!("meshes[{i}]: {e}"))?;
        meshes.extend(parts);
        notes.extend(read_notes.into_iter().map(|n| format!("meshes[{i}]: {n}")));
    }
    if let Some(b) = file.max_bounces.filter(|&b| b > splat_core::settings::MAX_BOUNCES) {
        return Err(format!("max_bounces {b} is above {}", splat_core::settings::MAX_BOUNCES));
    }
    for (key, value) in [("iso_threshold", file.iso_threshold), ("raster_iso_threshold", file.raster_iso_threshold)] {
        if let Some(v) = value.filter(|v| !(0.0..=1.0).contains(v)) {
            return Err(format!("{key} {v} is outside [0, 1] (a transmittance)"));
        }
    }
    let environment = file.environment.as_ref().map(environment).transpose()?;
    let lens = file.camera.as_ref().and_then(|c| lens(c, camera.as_ref())).transpose()?;
    let pixel_filter = file.camera.as_ref().and_then(|c| c.pixel_filter.as_deref());
    let pixel_filter = pixel_filter.map(|n| by_name(&PixelFilter::ALL, PixelFilter::name, "camera: pixel_filter", n));
    let sh_storage = file.sh_storage.as_deref().map(|n| by_name(&ShStorage::ALL, ShStorage::name, "sh_storage", n));
    Ok(WorldSpec {
        scene,
        lighting,
        camera,
        background,
        meshes,
        max_bounces: file.max_bounces,
        iso_threshold: file.iso_threshold,
        raster_iso_threshold: file.raster_iso_threshold,
        environment,
        lens,
        pixel_filter: pixel_filter.transpose()?,
        sh_storage: sh_storage.transpose()?,
        notes,
    })
}

/// A mesh in world space with its material.
pub type PlacedMesh = (TriangleMesh, MeshMaterial);

/// One mesh entry in world space: a part for each material of its file, each with the file's
/// material (or the matte default) under the keys the entry sets; and the reader's notes.
fn load_mesh(m: &MeshFile, base: &Path) -> Result<(Vec<PlacedMesh>, Vec<String>), String> {
    let shape =
        |mesh| crate::mesh::MeshRead { parts: vec![crate::mesh::MeshPart { mesh, material: None }], notes: Vec::new() };
    let read = match (&m.file, m.shape) {
        (Some(file), None) => crate::mesh::read_mesh(&base.join(file)).map_err(|e| named_file(file, e))?,
        (None, Some(ShapeName::Plane)) => shape(TriangleMesh::plane()),
        (None, Some(ShapeName::Cube)) => shape(TriangleMesh::cube()),
        (None, Some(ShapeName::Sphere)) => {
            let segments = m.segments.unwrap_or(48);
            if !(3..=4096).contains(&segments) {
                return Err(format!("segments {segments} is outside 3..=4096"));
            }
            shape(TriangleMesh::sphere(segments, segments / 2))
        }
        _ => return Err("give exactly one of shape = \"plane|cube|sphere\" or file = \"…\"".to_string()),
    };
    let (t, r) = translate_rotate(m.translate, m.rotate)?;
    let s = m.scale.map_or(Vec3::ONE, Colour::rgb);
    if !(s.is_finite() && s.min_element() > 0.0) {
        return Err(format!("scale {s} must be finite and positive"));
    }
    let placed = glam::Affine3A::from_scale_rotation_translation(s, r, t);
    let mut parts = Vec::with_capacity(read.parts.len());
    for part in read.parts {
        let file = part.material.unwrap_or_default();
        let mut material = MeshMaterial {
            color: m.color.map_or(file.color, Colour::rgb),
            shading: m.material.as_ref().map_or(file.shading, material),
            mirror: m.mirror.unwrap_or(file.mirror),
            mirror_tint: m.mirror_tint.map_or(file.mirror_tint, Colour::rgb),
            transmission: m.transmission.unwrap_or(file.transmission),
            ior: m.ior.unwrap_or(file.ior),
            roughness: m.roughness.unwrap_or(file.roughness),
            specular_layer: m.specular_layer.unwrap_or(file.specular_layer),
            opacity: m.opacity.unwrap_or(file.opacity),
        };
        // A glTF metal's tint is its base colour: a new colour retints it too.
        if m.color.is_some() && m.mirror_tint.is_none() && file.mirror > 0.0 && file.mirror_tint == file.color {
            material.mirror_tint = material.color.min(Vec3::ONE);
        }
        // A colour over a file's lit material changes what the surface reflects, not what it
        // emits (glTF's emissiveFactor is no share of the base colour): k_e is read again under
        // the new colour. An unlit part's colour is its emission, and a material table's k_e
        // is a share of the entry's colour by this file's own convention.
        if m.color.is_some() && m.material.is_none() && file.shading != Material::EMISSIVE {
            (material.color, material.shading.emissive) =
                crate::mesh::emitting(file.shading.emissive * file.color, material.color);
        }
        material.validate()?;
        parts.push((part.mesh.transformed(placed), material));
    }
    Ok((parts, read.notes))
}

/// The particles of one set and, for a built-in scene, its camera.
fn load_set(set: &SplatsFile, base: &Path) -> Result<(Scene, Option<Camera>), String> {
    match (&set.file, &set.builtin) {
        (Some(file), None) => Ok((crate::read_scene(&base.join(file)).map_err(|e| named_file(file, e))?, None)),
        (None, Some(name)) => {
            let (scene, camera) = splat_core::scenes::by_name(name)
                .ok_or_else(|| format!("no built-in scene '{name}' (demo, layers, ramp, cloud, plates, cloth)"))?;
            Ok((scene, Some(camera)))
        }
        _ => Err("give exactly one of file = \"…\" or builtin = \"…\"".to_string()),
    }
}

/// Zero the SH coefficients above `degree` and lower the scene's degree to it (the seed's way of
/// removing some baked lighting before relighting).
pub fn truncate_sh(scene: &mut Scene, degree: u8) {
    if degree >= scene.sh_degree {
        return;
    }
    let keep = sh_coeff_count(degree);
    for p in &mut scene.particles {
        p.sh.truncate(keep);
    }
    scene.sh_degree = degree;
}

/// A world entry's `translate` and `rotate` (degrees about x, then y, then z) as a translation
/// and a rotation, both finite.
fn translate_rotate(translate: Option<[f32; 3]>, rotate: Option<[f32; 3]>) -> Result<(Vec3, Quat), String> {
    let t = Vec3::from(translate.unwrap_or([0.0; 3]));
    let [rx, ry, rz] = rotate.unwrap_or([0.0; 3]).map(f32::to_radians);
    if !(t.is_finite() && rx.is_finite() && ry.is_finite() && rz.is_finite()) {
        return Err("translate and rotate must be finite".into());
    }
    Ok((t, Quat::from_euler(EulerRot::ZYX, rz, ry, rx)))
}

/// Apply the set's similarity transform x ↦ s R x + t to means, rotations, scales and SH.
fn transform(scene: &mut Scene, set: &SplatsFile) -> Result<(), String> {
    let (t, r) = translate_rotate(set.translate, set.rotate)?;
    let s = set.scale.unwrap_or(1.0);
    if !(s.is_finite() && s > 0.0) {
        return Err(format!("scale {s} must be finite and positive"));
    }
    let rotate_sh = (r != Quat::IDENTITY && scene.sh_degree > 0).then(|| Rotation::new(r));
    for p in &mut scene.particles {
        p.mean = s * (r * p.mean) + t;
        p.rotation = (r * p.rotation).normalize();
        p.scale *= s;
        if let Some(rot) = &rotate_sh {
            p.sh = rot.apply(&p.sh.to_array()).into();
        }
    }
    Ok(())
}

fn material(m: &MaterialFile) -> Material {
    let c = |c: Option<Colour>| c.map_or(Vec3::ZERO, Colour::rgb);
    Material {
        emissive: c(m.emissive),
        ambient: c(m.ambient),
        diffuse: c(m.diffuse),
        specular: c(m.specular),
        shininess: m.shininess.unwrap_or(32.0),
    }
}

fn light(l: &LightFile) -> Result<Light, String> {
    let position = || l.position.map(Vec3::from).ok_or("needs a position");
    let direction = |from: Option<Vec3>| -> Result<Vec3, String> {
        let d = match (l.direction, l.target, from) {
            (Some(d), None, _) => Vec3::from(d),
            (None, Some(target), Some(p)) => Vec3::from(target) - p,
            (None, Some(target), None) => -Vec3::from(target),
            _ => return Err("needs one of direction = [x, y, z] or target = [x, y, z]".into()),
        };
        d.try_normalize().ok_or_else(|| format!("direction {d} has no length"))
    };
    let kind = match l.kind {
        LightKindName::Point => LightKind::Point { position: position()? },
        LightKindName::Spot => {
            let p = position()?;
            LightKind::Spot {
                position: p,
                direction: direction(Some(p))?,
                inner_deg: l.inner.unwrap_or(20.0),
                outer_deg: l.outer.unwrap_or(30.0),
            }
        }
        LightKindName::Directional => LightKind::Directional { direction: direction(None)? },
    };
    let light = Light {
        kind,
        color: l.color.map_or(Vec3::ONE, Colour::rgb),
        intensity: l.intensity.unwrap_or(1.0),
        radius: l.radius.unwrap_or(0.0),
    };
    light.validate()?;
    Ok(light)
}

fn shadows(s: Option<&ShadowsFile>) -> (Shadows, f32) {
    let offset = s.and_then(|s| s.offset).unwrap_or(splat_core::lighting::DEFAULT_SHADOW_OFFSET);
    let Some(s) = s else { return (Shadows::None, offset) };
    let kind = match s.kind {
        ShadowKind::None => Shadows::None,
        ShadowKind::Stochastic => Shadows::Stochastic,
        ShadowKind::Exact => Shadows::Exact,
        ShadowKind::Sorted => Shadows::Sorted {
            k: s.k.unwrap_or(splat_core::lighting::DEFAULT_SHADOW_K),
            threshold: s.threshold.unwrap_or(splat_core::lighting::DEFAULT_SHADOW_THRESHOLD),
            colored: s.colored.unwrap_or(0.0),
        },
    };
    (kind, offset)
}

fn environment(e: &EnvironmentFile) -> Result<Environment, String> {
    let env = match (e.color, e.horizon, e.zenith) {
        (Some(c), None, None) => Environment::Constant(c.rgb()),
        (None, Some(h), Some(z)) => {
            let up = Vec3::from(e.up.unwrap_or([0.0, 1.0, 0.0]));
            let up = up.try_normalize().ok_or("environment: up must be a non-zero finite vector")?;
            Environment::Gradient { horizon: h.rgb(), zenith: z.rgb(), up }
        }
        _ => return Err("environment: give either color, or horizon and zenith".into()),
    };
    let ok = |c: Vec3| c.is_finite() && c.min_element() >= 0.0;
    match env {
        Environment::Constant(c) if !ok(c) => Err(format!("environment colour {c} must be finite and non-negative")),
        Environment::Gradient { horizon, zenith, .. } if !ok(horizon) || !ok(zenith) => {
            Err("environment colours must be finite and non-negative".into())
        }
        env => Ok(env),
    }
}

/// The thin lens of `[camera]`: `aperture` (lens radius) with `focus_distance` (by default the
/// distance from the eye to the target).
fn lens(c: &CameraFile, camera: Option<&Camera>) -> Option<Result<ThinLens, String>> {
    let aperture = c.aperture?;
    let focus_distance = c.focus_distance.unwrap_or_else(|| {
        let target = Vec3::from(c.target);
        camera.map_or(1.0, |cam| (target - cam.center()).dot(cam.forward()))
    });
    let ok = aperture.is_finite() && aperture >= 0.0 && focus_distance.is_finite() && focus_distance > 0.0;
    Some(if ok {
        Ok(ThinLens { aperture, focus_distance })
    } else {
        Err(format!("camera: aperture {aperture} must be ≥ 0 and focus_distance {focus_distance} > 0"))
    })
}

/// The choice among `all` that `key` names by `name`, as the command line names them.
fn by_name<T: Copy>(all: &[T], name_of: fn(T) -> &'static str, key: &str, name: &str) -> Result<T, String> {
    all.iter().copied().find(|&t| name_of(t) == name).ok_or_else(|| {
        let names: Vec<&str> = all.iter().map(|&t| name_of(t)).collect();
        format!("{key} \"{name}\" is not one of {}", names.join(", "))
    })
}

fn camera_from(c: &CameraFile) -> Result<Camera, String> {
    let up = Vec3::from(c.up.unwrap_or([0.0, 1.0, 0.0]));
    Camera::look_at(
        Vec3::from(c.eye),
        Vec3::from(c.target),
        up,
        c.fov.unwrap_or(splat_core::camera::DEFAULT_FOV_Y),
        c.width.unwrap_or(640),
        c.height.unwrap_or(480),
    )
    .map_err(|e| format!("camera: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<WorldSpec, String> {
        parse_world(text, Path::new("."), None)
    }

    #[test]
    fn two_sets_share_one_id_space_with_their_materials() {
        let w = parse(
            r#"
            [[splats]]
            builtin = "layers"
            [[splats]]
            builtin = "layers"
            translate = [0, 0, 5]
            material = { diffuse = [0.5, 0.6, 0.7], shininess = 8 }
            [[lights]]
            kind = "directional"
            direction = [0, -1, 0]
            "#,
        )
        .unwrap();
        let n = splat_core::scenes::layers().0.particles.len();
        assert_eq!(w.scene.particles.len(), 2 * n);
        assert_eq!(*w.lighting.material(0), Material::EMISSIVE);
        assert_eq!(w.lighting.material(n as u32).diffuse, Vec3::new(0.5, 0.6, 0.7));
        assert_eq!(w.lighting.material(n as u32).emissive, Vec3::ZERO);
        assert_eq!(w.scene.particles[n].mean.z, w.scene.particles[0].mean.z + 5.0);
        assert!(w.lighting.is_on());
        assert!(w.camera.is_some(), "the first built-in set's camera");
    }

    #[test]
    fn environment_lens_and_pixel_filter_are_read() {
        let w = parse(
            "[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 1]\naperture = 0.1\npixel_filter = \"box\"\n\
             [environment]\nhorizon = [1, 0.5, 0]\nzenith = 0.2\n[[splats]]\nbuiltin = \"demo\"",
        )
        .unwrap();
        assert_eq!(w.settings(RenderSettings::default()).sampling.filter, PixelFilter::Box);
        let plain = parse("[[splats]]\nbuiltin = \"demo\"").unwrap();
        assert_eq!(plain.settings(RenderSettings::default()).sampling.filter, PixelFilter::Center);
        assert_eq!(plain.settings(RenderSettings::default()).sh_storage, ShStorage::F32);
        let u8 = parse("sh_storage = \"u8\"\n[[splats]]\nbuiltin = \"demo\"").unwrap();
        assert_eq!(u8.settings(RenderSettings::default()).sh_storage, ShStorage::U8);
        let lens = w.lens.unwrap();
        assert_eq!(lens.aperture, 0.1);
        assert!((lens.focus_distance - 4.0).abs() < 1e-5, "eye to target: {}", lens.focus_distance);
        assert_eq!(
            w.environment,
            Some(Environment::Gradient { horizon: Vec3::new(1.0, 0.5, 0.0), zenith: Vec3::splat(0.2), up: Vec3::Y })
        );
    }

    #[test]
    fn open_world_names_the_demo_and_refuses_an_empty_file() {
        let demo = open_world(None, crate::ReadOptions::default()).unwrap();
        assert_eq!(demo.name, "demo");
        assert!(demo.world.camera.is_some() && !demo.world.scene.particles.is_empty());
        let empty = std::env::temp_dir().join(format!("splat-io-empty-{}.splat", std::process::id()));
        std::fs::write(&empty, []).unwrap();
        let err = open_world(Some(&empty), crate::ReadOptions::default()).unwrap_err();
        std::fs::remove_file(&empty).unwrap();
        assert!(matches!(err.kind, ErrorKind::Empty), "{err}");
        assert!(err.to_string().contains("no splats and no meshes"), "{err}");
    }

    #[test]
    fn bad_worlds_name_the_problem() {
        let cases = [
            ("", "no [[splats]]"),
            ("[[splats]]\nbuiltin = \"nope\"", "no built-in scene 'nope'"),
            ("[[splats]]\nbuiltin = \"demo\"\nfile = \"x.ply\"", "exactly one of"),
            ("[[splats]]\nbuiltin = \"demo\"\nscale = 0", "scale 0"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[lights]]\nkind = \"spot\"\nposition = [0,1,0]", "direction"),
            (
                "[[splats]]\nbuiltin = \"demo\"\n[[lights]]\nkind = \"point\"\nposition = [0,1,0]\nintensity = -1",
                "intensity",
            ),
            ("[[splats]]\nbuiltin = \"demo\"\nmaterial = { diffuse = -0.5 }", "non-negative"),
            ("[[splats]]\nbuiltin = \"demo\"\ncolour = 1", "unknown field"),
            ("[[splats]]\nbuiltin = \"demo\"\nsh_degree = 7", "above 3"),
            (
                "[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 1]\npixel_filter = \"gauss\"\n[[splats]]\nbuiltin = \"demo\"",
                "pixel_filter \"gauss\" is not one of center, box",
            ),
            ("sh_storage = \"f8\"\n[[splats]]\nbuiltin = \"demo\"", "sh_storage \"f8\" is not one of f32, f16, u8"),
            ("[[splats]]\nbuiltin = \"demo\"\n[shadows]\nkind = \"sorted\"\nk = 0", "shadow k"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nscale = 1", "meshes[0]: give exactly one of"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"cube\"\nmirror = 2", "meshes[0]: mirror 2"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"cube\"\nscale = [1, 0, 1]", "scale"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"sphere\"\nsegments = 1", "segments 1"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"cone\"", "unknown variant"),
            ("max_bounces = 99\n[[splats]]\nbuiltin = \"demo\"", "max_bounces 99"),
            ("raster_iso_threshold = 1.5\n[[splats]]\nbuiltin = \"demo\"", "raster_iso_threshold 1.5 is outside"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"cube\"\nroughness = 2", "roughness 2"),
            ("[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nshape = \"cube\"\nopacity = 0", "opacity 0"),
            ("[environment]\ncolor = 1\nhorizon = 1\n[[splats]]\nbuiltin = \"demo\"", "either color, or horizon"),
            ("[environment]\ncolor = -1\n[[splats]]\nbuiltin = \"demo\"", "environment colour"),
            ("[environment]\nhorizon = 1\nzenith = 1\nup = [0, 0, 0]\n[[splats]]\nbuiltin = \"demo\"", "up must be"),
            (
                "[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\naperture = -0.1\n[[splats]]\nbuiltin = \"demo\"",
                "aperture -0.1",
            ),
        ];
        for (text, want) in cases {
            let err = parse(text).err().unwrap_or_else(|| panic!("accepted: {text}"));
            assert!(err.contains(want), "{text:?}: {err}");
        }
    }

    #[test]
    fn sh_degree_cut_zeroes_the_upper_bands() {
        let mut scene = Scene::new(vec![splat_core::scenes::layers().0.particles[0].clone()], 3);
        scene.particles[0].sh = [Vec3::ONE; 16].into();
        truncate_sh(&mut scene, 1);
        assert_eq!(scene.sh_degree, 1);
        assert_eq!(scene.particles[0].sh[3], Vec3::ONE);
        assert_eq!(scene.particles[0].sh[4], Vec3::ZERO);
    }
}
