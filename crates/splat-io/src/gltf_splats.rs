//! glTF 2.0 Gaussian splats: the Khronos `KHR_gaussian_splatting` extension, read from `.glb`
//! and `.gltf` (buffers in the binary chunk, in `data:` URIs or in files beside it) and written
//! as either.
//!
//! The extension stores each Gaussian as a point of a `POINTS` mesh primitive: `POSITION`, and
//! `KHR_gaussian_splatting:ROTATION` (a unit quaternion in glTF's x, y, z, w order),
//! `:SCALE` (linear standard deviations, not `.ply`'s logarithms), `:OPACITY` (after the
//! sigmoid, not `.ply`'s logit) and `:SH_DEGREE_l_COEF_n` (RGB of SH coefficient (l, m = n − l),
//! bands up to 3, each complete or absent). Three differences from `.ply` cause silent errors
//! when missed, and this module handles each:
//!
//! - **Axes.** glTF is +Y up. The ecosystem's convention (PlayCanvas splat-transform, whose GLB
//!   writer is the reference tested here) stores `.ply`-convention data turned by a half turn
//!   about z: (x, y, z) ↦ (−x, −y, z), the quaternion premultiplied by that turn and each SH
//!   coefficient (l, m) multiplied by (−1)^m. The reader turns the data back into the project's
//!   (the `.ply`'s) axes; the writer turns them out again.
//! - **Activations**: linear scale and opacity are stored as such.
//! - **Node transforms** place the splats (the extension's Σ = M C Cᵀ Mᵀ): translation, rotation
//!   and uniform scale are applied to means, rotations and scales, and the rotation to the SH
//!   coefficients ([`splat_core::sh::Rotation`], as the specification asks). A non-uniform
//!   scale or a reflection has no splat equivalent: those are refused with the node named.
//!
//! Primitives without the extension (triangles beside the splats) are left to the mesh reader
//! ([`crate::mesh::parse_gltf`]), which skips the splat primitives, so one `.glb` can hold the
//! splats and the meshes of a world. Compressed splats (`KHR_gaussian_splatting_compression_spz_2`,
//! `EXT_meshopt_compression`) and sparse accessors are refused by name.

use crate::placement::Placement;
use crate::{Error, ErrorKind, read_file};
use glam::{Mat4, Quat, Vec3};
use serde_json::{Map, Value, json};
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::sh::SH_C0;
use splat_core::{Particle, Scene};
use std::path::Path;

/// The extension's name, and the prefix of its attributes.
pub const EXTENSION: &str = "KHR_gaussian_splatting";
/// "glTF", little-endian: the GLB magic.
const GLB_MAGIC: u32 = 0x4654_6C67;
/// GLB chunk types.
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
/// glTF `componentType`s.
const BYTE: u64 = 5120;
const UNSIGNED_BYTE: u64 = 5121;
const SHORT: u64 = 5122;
const UNSIGNED_SHORT: u64 = 5123;
const UNSIGNED_INT: u64 = 5125;
const FLOAT: u64 = 5126;
/// Mesh primitive mode `POINTS`.
const POINTS: u64 = 0;
/// bufferView target `ARRAY_BUFFER`.
const ARRAY_BUFFER: u64 = 34962;
/// Extensions a reader may be required to know: the splats' own, and quantised attributes.
const KNOWN_REQUIRED: [&str; 2] = [EXTENSION, "KHR_mesh_quantization"];
/// Most nodes visited (a cyclic hierarchy would never end).
const MAX_NODES: usize = 1 << 20;

fn gltf_error(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Gltf(message.into())
}

fn is_splat_primitive(primitive: &Value) -> bool {
    primitive["extensions"].get(EXTENSION).is_some()
}

/// Read the splats of a `.glb` or `.gltf` file.
pub fn read_gltf_splats(path: &Path) -> Result<Scene, Error> {
    let bytes = read_file(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse_gltf_splats(&bytes, base).map_err(|kind| Error::new(path, kind))
}

/// Parse the splats of a glTF document (`.glb` or `.gltf` bytes; external buffers relative to
/// `base`), in the project's (`.ply`) axes; a document without any is refused.
pub fn parse_gltf_splats(bytes: &[u8], base: &Path) -> Result<Scene, ErrorKind> {
    let scene = splats_in(bytes, base)?;
    if scene.particles.is_empty() {
        return Err(gltf_error(format!("no mesh primitive of the default scene carries {EXTENSION}")));
    }
    Ok(scene)
}

/// The splats of a glTF document as [`parse_gltf_splats`] reads them, none where it has no
/// `KHR_gaussian_splatting` primitive (a world of meshes only, [`crate::world`]).
pub(crate) fn splats_in(bytes: &[u8], base: &Path) -> Result<Scene, ErrorKind> {
    let (json, bin) = split_container(bytes).map_err(gltf_error)?;
    check_required(&json).map_err(gltf_error)?;
    let buffers = load_buffers(&json, bin, base).map_err(gltf_error)?;
    let mut particles = Vec::new();
    let mut sh_degree = 0u8;
    for (node, world) in placed_meshes(&json).map_err(gltf_error)? {
        let mesh = &json["meshes"][node.mesh];
        let primitives = mesh["primitives"].as_array().map_or(&[][..], Vec::as_slice);
        for (p, primitive) in primitives.iter().enumerate().filter(|(_, p)| is_splat_primitive(p)) {
            let at = format!("mesh {} primitive {p}", node.mesh);
            let placement = Placement::of(world).map_err(|m| gltf_error(format!("node {}: {m}", node.index)))?;
            if placement.mirror {
                let message = "its transform mirrors (negative determinant), which the extension leaves undefined";
                return Err(gltf_error(format!("node {}: {message}", node.index)));
            }
            let (splats, degree) = read_primitive(&json, &buffers, primitive, &at, &placement, particles.len())?;
            sh_degree = sh_degree.max(degree);
            particles.extend(splats);
        }
    }
    Ok(Scene::new(particles, sh_degree))
}

/// The JSON document and the GLB binary chunk, if any.
fn split_container(bytes: &[u8]) -> Result<(Value, Option<&[u8]>), String> {
    let word = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if word(0) != Some(GLB_MAGIC) {
        let json = serde_json::from_slice(bytes).map_err(|e| format!("not a .glb and not glTF JSON: {e}"))?;
        return Ok((json, None));
    }
    let (version, length) = (word(4).ok_or("GLB header is truncated")?, word(8).ok_or("GLB header is truncated")?);
    if version != 2 {
        return Err(format!("GLB version {version}, expected 2"));
    }
    if length as usize > bytes.len() {
        return Err(format!("GLB header declares {length} bytes but the file holds {}", bytes.len()));
    }
    let bytes = &bytes[..length as usize];
    let chunk = |at: usize| -> Result<Option<(u32, &[u8])>, String> {
        if at >= bytes.len() {
            return Ok(None);
        }
        let (len, kind) =
            (word(at).ok_or("GLB chunk header is truncated")?, word(at + 4).ok_or("GLB chunk header is truncated")?);
        let data = bytes.get(at + 8..at + 8 + len as usize).ok_or_else(|| {
            format!("GLB chunk at byte {at} declares {len} bytes but the file ends first (truncated)")
        })?;
        Ok(Some((kind, data)))
    };
    let Some((CHUNK_JSON, text)) = chunk(12)? else {
        return Err("the GLB's first chunk is not its JSON".into());
    };
    let json = serde_json::from_slice(text).map_err(|e| format!("GLB JSON chunk: {e}"))?;
    let next = 12 + 8 + text.len();
    let bin = match chunk(next)? {
        Some((CHUNK_BIN, data)) => Some(data),
        _ => None,
    };
    Ok((json, bin))
}

/// Refuse a document that requires an extension this reader does not know.
fn check_required(json: &Value) -> Result<(), String> {
    let required = json["extensionsRequired"].as_array().map_or(&[][..], Vec::as_slice);
    let unknown: Vec<&str> =
        required.iter().filter_map(Value::as_str).filter(|e| !KNOWN_REQUIRED.contains(e)).collect();
    if unknown.is_empty() {
        return Ok(());
    }
    Err(format!(
        "the file requires {} , which this reader does not decode (it reads {} data uncompressed); convert it with a tool that does",
        unknown.join(", "),
        EXTENSION
    ))
}

/// Every buffer's bytes: the GLB binary chunk (a buffer without `uri`), a `data:` URI or a file
/// relative to `base`, each at least as long as it declares.
fn load_buffers(json: &Value, bin: Option<&[u8]>, base: &Path) -> Result<Vec<Vec<u8>>, String> {
    let list = json["buffers"].as_array().map_or(&[][..], Vec::as_slice);
    list.iter()
        .enumerate()
        .map(|(i, b)| {
            let data = match b["uri"].as_str() {
                Some(uri) => crate::mesh::buffer_from_uri(uri, base)?,
                None => bin.ok_or(format!("buffer {i} has no uri and the file has no binary chunk"))?.to_vec(),
            };
            let declared = b["byteLength"].as_u64().ok_or(format!("buffer {i} has no byteLength"))?;
            if (data.len() as u64) < declared {
                return Err(format!("buffer {i} holds {} bytes, fewer than the {declared} it declares", data.len()));
            }
            Ok(data)
        })
        .collect()
}

/// A node that instantiates a mesh.
struct MeshNode {
    index: usize,
    mesh: usize,
}

/// The nodes of the default scene (else scene 0, else every root node) that instantiate a
/// mesh, with their global transforms.
fn placed_meshes(json: &Value) -> Result<Vec<(MeshNode, Mat4)>, String> {
    let nodes = json["nodes"].as_array().map_or(&[][..], Vec::as_slice);
    let index = |v: &Value, what: &str, len: usize| -> Result<usize, String> {
        let i = v.as_u64().ok_or(format!("{what} is not an index"))? as usize;
        if i >= len {
            return Err(format!("{what} {i} does not exist ({len} of them)"));
        }
        Ok(i)
    };
    let scene = json["scene"].as_u64().unwrap_or(0) as usize;
    let roots: Vec<usize> = match json["scenes"].get(scene) {
        Some(s) => s["nodes"]
            .as_array()
            .map_or(&[][..], Vec::as_slice)
            .iter()
            .map(|n| index(n, "scene node", nodes.len()))
            .collect::<Result<_, _>>()?,
        None => {
            let children: Vec<u64> = nodes
                .iter()
                .flat_map(|n| n["children"].as_array().into_iter().flatten().filter_map(Value::as_u64))
                .collect();
            (0..nodes.len()).filter(|i| !children.contains(&(*i as u64))).collect()
        }
    };
    let meshes = json["meshes"].as_array().map_or(0, Vec::len);
    let mut stack: Vec<(usize, Mat4)> = roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut out = Vec::new();
    let mut visited = 0;
    while let Some((n, parent)) = stack.pop() {
        visited += 1;
        if visited > MAX_NODES {
            return Err("the node hierarchy is cyclic or too deep".into());
        }
        let node = &nodes[n];
        let world = parent * node_transform(node).map_err(|m| format!("node {n}: {m}"))?;
        if !node["mesh"].is_null() {
            out.push((MeshNode { index: n, mesh: index(&node["mesh"], "node mesh", meshes)? }, world));
        }
        for child in node["children"].as_array().map_or(&[][..], Vec::as_slice) {
            stack.push((index(child, "child node", nodes.len())?, world));
        }
    }
    Ok(out)
}

/// A node's local transform: `matrix` (column-major), else translation · rotation · scale.
fn node_transform(node: &Value) -> Result<Mat4, String> {
    let floats = |key: &str, len: usize| -> Result<Option<Vec<f32>>, String> {
        match node[key].as_array() {
            None => Ok(None),
            Some(a) if a.len() == len => a
                .iter()
                .map(|v| v.as_f64().map(|f| f as f32).ok_or(format!("{key} holds a non-number")))
                .collect::<Result<Vec<_>, _>>()
                .map(Some),
            Some(a) => Err(format!("{key} has {} numbers, expected {len}", a.len())),
        }
    };
    if let Some(m) = floats("matrix", 16)? {
        return Ok(Mat4::from_cols_slice(&m));
    }
    let t = floats("translation", 3)?.map_or(Vec3::ZERO, |v| Vec3::from_slice(&v));
    let r = floats("rotation", 4)?.map_or(Quat::IDENTITY, |v| Quat::from_slice(&v));
    let s = floats("scale", 3)?.map_or(Vec3::ONE, |v| Vec3::from_slice(&v));
    Ok(Mat4::from_scale_rotation_translation(s, r, t))
}

/// One attribute's elements in a buffer.
struct Accessor<'a> {
    data: &'a [u8],
    stride: usize,
    component: u64,
    normalized: bool,
    count: usize,
}

impl Accessor<'_> {
    /// Component `c` of element `i`, with glTF's normalisation of integer components.
    fn get(&self, i: usize, c: usize) -> f32 {
        let size = component_size(self.component);
        let at = i * self.stride + c * size;
        let b = &self.data[at..at + size];
        let norm = self.normalized;
        match self.component {
            BYTE if norm => (f32::from(b[0] as i8) / 127.0).max(-1.0),
            BYTE => f32::from(b[0] as i8),
            UNSIGNED_BYTE if norm => f32::from(b[0]) / 255.0,
            UNSIGNED_BYTE => f32::from(b[0]),
            SHORT if norm => (f32::from(i16::from_le_bytes([b[0], b[1]])) / 32767.0).max(-1.0),
            SHORT => f32::from(i16::from_le_bytes([b[0], b[1]])),
            UNSIGNED_SHORT if norm => f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
            UNSIGNED_SHORT => f32::from(u16::from_le_bytes([b[0], b[1]])),
            UNSIGNED_INT => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
            _ => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        }
    }

    fn vec3(&self, i: usize) -> Vec3 {
        Vec3::new(self.get(i, 0), self.get(i, 1), self.get(i, 2))
    }
}

fn component_size(component: u64) -> usize {
    match component {
        BYTE | UNSIGNED_BYTE => 1,
        SHORT | UNSIGNED_SHORT => 2,
        _ => 4,
    }
}

/// The accessor of attribute `name` of `primitive`, of glTF type `kind` (`VEC3`, …), its
/// elements checked to lie inside its buffer view and buffer.
fn accessor<'a>(
    json: &Value,
    buffers: &'a [Vec<u8>],
    primitive: &Value,
    name: &str,
    kind: &str,
) -> Result<Option<Accessor<'a>>, String> {
    let Some(index) = primitive["attributes"].get(name) else { return Ok(None) };
    let i = index.as_u64().ok_or(format!("attribute {name} is not an accessor index"))? as usize;
    let a = json["accessors"].get(i).ok_or(format!("attribute {name} names accessor {i}, which does not exist"))?;
    let found = a["type"].as_str().unwrap_or("?");
    if found != kind {
        return Err(format!("attribute {name} (accessor {i}) is {found}, expected {kind}"));
    }
    if !a["sparse"].is_null() {
        return Err(format!("attribute {name} (accessor {i}) is sparse, which this reader does not decode"));
    }
    let component = a["componentType"].as_u64().ok_or(format!("accessor {i} has no componentType"))?;
    if ![BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT, UNSIGNED_INT, FLOAT].contains(&component) {
        return Err(format!("accessor {i} has componentType {component}, not a glTF one"));
    }
    let count = a["count"].as_u64().ok_or(format!("accessor {i} has no count"))? as usize;
    let width = match kind {
        "SCALAR" => 1,
        "VEC3" => 3,
        _ => 4,
    };
    let view_index =
        a["bufferView"].as_u64().ok_or(format!("accessor {i} has no bufferView (all zeros): not a splat attribute"))?
            as usize;
    let view = json["bufferViews"]
        .get(view_index)
        .ok_or(format!("accessor {i} names bufferView {view_index}, which does not exist"))?;
    let buffer = view["buffer"]
        .as_u64()
        .and_then(|b| buffers.get(b as usize))
        .ok_or(format!("bufferView {view_index} names no loaded buffer"))?;
    let element = width * component_size(component);
    let stride = view["byteStride"].as_u64().map_or(element, |s| s as usize);
    let view_start = view["byteOffset"].as_u64().unwrap_or(0) as usize;
    let view_len = view["byteLength"].as_u64().ok_or(format!("bufferView {view_index} has no byteLength"))? as usize;
    let start = view_start + a["byteOffset"].as_u64().unwrap_or(0) as usize;
    let needed = if count == 0 {
        0
    } else {
        stride.checked_mul(count - 1).and_then(|n| n.checked_add(element)).ok_or("accessor size overflows")?
    };
    let view_end = view_start.checked_add(view_len).ok_or("bufferView size overflows")?;
    if stride < element || start.checked_add(needed).is_none_or(|end| end > view_end || end > buffer.len()) {
        return Err(format!(
            "attribute {name} (accessor {i}): {count} elements of {element} bytes, stride {stride}, from byte {start} do not fit bufferView {view_index} ({view_len} bytes at {view_start}) in its buffer of {} bytes",
            buffer.len()
        ));
    }
    Ok(Some(Accessor {
        data: &buffer[start..start + needed],
        stride,
        component,
        normalized: a["normalized"].as_bool().unwrap_or(false),
        count,
    }))
}

/// The SH attribute of coefficient `k` (0..16): degree l, index n = k − l².
fn sh_attribute(k: usize) -> String {
    let l = (k as f32).sqrt() as usize;
    format!("{EXTENSION}:SH_DEGREE_{l}_COEF_{}", k - l * l)
}

/// (−1)^m of coefficient k (l, m = n − l): its sign under the half turn about z.
fn half_turn_sign(k: usize) -> f32 {
    let l = (k as f32).sqrt() as i32;
    let m = k as i32 - l * l - l;
    if m.rem_euclid(2) == 0 { 1.0 } else { -1.0 }
}

/// The half turn about z between glTF's and the `.ply`'s axes (its own inverse).
fn half_turn(p: &mut Particle) {
    p.mean = Vec3::new(-p.mean.x, -p.mean.y, p.mean.z);
    // (0, 0, 1, 0) ⊗ q, exactly.
    let q = p.rotation;
    p.rotation = Quat::from_xyzw(-q.y, q.x, q.w, -q.z);
    if let splat_core::Sh::Bands(all) = &mut p.sh {
        for (k, c) in all.iter_mut().enumerate().skip(1) {
            *c *= half_turn_sign(k);
        }
    }
}

/// The splats of one primitive (`at` names it; `first` is the index of its first splat in the
/// scene, for messages) placed by `placement`, in the `.ply`'s axes, and their SH degree.
fn read_primitive(
    json: &Value,
    buffers: &[Vec<u8>],
    primitive: &Value,
    at: &str,
    placement: &Placement,
    first: usize,
) -> Result<(Vec<Particle>, u8), ErrorKind> {
    let ext = &primitive["extensions"][EXTENSION];
    let field = |key: &str, default: &str| ext[key].as_str().unwrap_or(default).to_string();
    let (kernel, color_space, projection) =
        (field("kernel", "?"), field("colorSpace", "?"), field("projection", "perspective"));
    if kernel != "ellipse" {
        return Err(gltf_error(format!(
            "{at}: kernel '{kernel}' is not the extension's 'ellipse', the only one rendered here"
        )));
    }
    if color_space != "srgb_rec709_display" {
        return Err(gltf_error(format!(
            "{at}: colour space '{color_space}': the renderer composites display-referred sRGB (srgb_rec709_display) like 3DGS, and would show other colours wrongly"
        )));
    }
    if projection != "perspective" {
        return Err(gltf_error(format!("{at}: projection '{projection}' is not 'perspective'")));
    }
    if primitive["mode"].as_u64().unwrap_or(4) != POINTS {
        return Err(gltf_error(format!("{at}: a splat primitive's mode must be POINTS (0)")));
    }
    let get = |name: &str, kind: &str| {
        accessor(json, buffers, primitive, name, kind).map_err(|m| gltf_error(format!("{at}: {m}")))
    };
    let need = |name: &str, kind: &str| -> Result<Accessor, ErrorKind> {
        get(name, kind)?.ok_or_else(|| gltf_error(format!("{at}: the required attribute {name} is missing")))
    };
    let position = need("POSITION", "VEC3")?;
    let rotation = need(&format!("{EXTENSION}:ROTATION"), "VEC4")?;
    let scale = need(&format!("{EXTENSION}:SCALE"), "VEC3")?;
    let opacity = need(&format!("{EXTENSION}:OPACITY"), "SCALAR")?;
    let mut sh = vec![need(&sh_attribute(0), "VEC3")?];
    let mut degree = 0u8;
    for l in 1..=3u8 {
        let band: Vec<Option<Accessor>> = (sh_coeff_count(l - 1)..sh_coeff_count(l))
            .map(|k| get(&sh_attribute(k), "VEC3"))
            .collect::<Result<_, _>>()?;
        match band.iter().filter(|a| a.is_some()).count() {
            0 => break,
            n if n < band.len() => {
                return Err(gltf_error(format!(
                    "{at}: SH degree {l} has {n} of its {} coefficients (a degree is complete or absent)",
                    band.len()
                )));
            }
            _ => {
                sh.extend(band.into_iter().flatten());
                degree = l;
            }
        }
    }
    let count = position.count;
    for (name, a) in [("ROTATION", &rotation), ("SCALE", &scale), ("OPACITY", &opacity)]
        .into_iter()
        .chain(sh.iter().map(|a| ("SH", a)))
    {
        if a.count != count {
            return Err(gltf_error(format!("{at}: {name} holds {} elements, POSITION {count}", a.count)));
        }
    }
    let mut particles = Vec::with_capacity(count);
    for i in 0..count {
        let mut coeffs = [Vec3::ZERO; SH_MAX_COEFFS];
        for (c, a) in coeffs.iter_mut().zip(&sh) {
            *c = a.vec3(i);
        }
        let q = Quat::from_xyzw(rotation.get(i, 0), rotation.get(i, 1), rotation.get(i, 2), rotation.get(i, 3));
        let (mean, scale, q, coeffs) = placement.place(position.vec3(i), scale.vec3(i), q, coeffs);
        let mut p = Particle::new(mean, scale, q, opacity.get(i, 0), coeffs)
            .map_err(|error| ErrorKind::Particle { index: (first + i) as u64, error })?;
        half_turn(&mut p);
        particles.push(p);
    }
    Ok((particles, degree))
}

/// How the writer stores the buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GltfContainer {
    /// Binary `.glb`: the JSON and the buffer in one file.
    Glb,
    /// `.gltf` JSON with the buffer in a base64 `data:` URI.
    Embedded,
}

/// Write `scene` as glTF with `KHR_gaussian_splatting` (`.glb`, or `.gltf` by extension).
pub fn write_gltf_splats(path: &Path, scene: &Scene) -> Result<(), Error> {
    let is_gltf = crate::extension(path).as_deref() == Some("gltf");
    let container = if is_gltf { GltfContainer::Embedded } else { GltfContainer::Glb };
    let bytes = encode_gltf_splats(scene, container).map_err(|kind| Error::new(path, kind))?;
    std::fs::write(path, bytes).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}

/// The attributes' data, in writing order: (semantic, glTF type, component type, normalized,
/// bytes, min and max for POSITION).
struct Segment {
    name: String,
    kind: &'static str,
    component: u64,
    normalized: bool,
    data: Vec<u8>,
    bounds: Option<(Vec3, Vec3)>,
}

/// The bytes of `scene` as glTF with `KHR_gaussian_splatting` in `container`: one point
/// primitive in the extension's axes, every attribute in f32 (lossless), and the `COLOR_0`
/// fallback the specification suggests for viewers without the extension (8-bit, the DC
/// colour and the opacity).
pub fn encode_gltf_splats(scene: &Scene, container: GltfContainer) -> Result<Vec<u8>, ErrorKind> {
    if scene.particles.is_empty() {
        return Err(gltf_error("the scene has no splats to write"));
    }
    let turned: Vec<Particle> = scene
        .particles
        .iter()
        .map(|p| {
            let mut p = p.clone();
            half_turn(&mut p);
            p
        })
        .collect();
    let floats = |f: &dyn Fn(&Particle) -> Vec<f32>| -> Vec<u8> {
        turned.iter().flat_map(f).flat_map(f32::to_le_bytes).collect()
    };
    let (lo, hi) =
        turned.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p.mean), hi.max(p.mean)));
    let float =
        |name: String, kind, data| Segment { name, kind, component: FLOAT, normalized: false, data, bounds: None };
    let unit = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    let mut segments = vec![
        Segment { bounds: Some((lo, hi)), ..float("POSITION".into(), "VEC3", floats(&|p| p.mean.to_array().to_vec())) },
        Segment {
            name: "COLOR_0".into(),
            kind: "VEC4",
            component: UNSIGNED_BYTE,
            normalized: true,
            data: turned
                .iter()
                .flat_map(|p| {
                    let c = p.sh[0] * SH_C0 + Vec3::splat(0.5);
                    [unit(c.x), unit(c.y), unit(c.z), unit(p.opacity)]
                })
                .collect(),
            bounds: None,
        },
        float(format!("{EXTENSION}:ROTATION"), "VEC4", floats(&|p| p.rotation.to_array().to_vec())),
        float(format!("{EXTENSION}:SCALE"), "VEC3", floats(&|p| p.scale.to_array().to_vec())),
        float(format!("{EXTENSION}:OPACITY"), "SCALAR", floats(&|p| vec![p.opacity])),
    ];
    for k in 0..sh_coeff_count(scene.sh_degree.min(3)) {
        segments.push(float(sh_attribute(k), "VEC3", floats(&|p| p.sh[k].to_array().to_vec())));
    }
    let mut bin = Vec::new();
    let (mut views, mut accessors, mut attributes) = (Vec::new(), Vec::new(), Map::new());
    for (i, s) in segments.iter().enumerate() {
        views.push(json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": s.data.len(), "target": ARRAY_BUFFER }));
        bin.extend_from_slice(&s.data);
        bin.resize(bin.len().next_multiple_of(4), 0);
        let mut a = json!({ "bufferView": i, "componentType": s.component, "count": turned.len(), "type": s.kind });
        if s.normalized {
            a["normalized"] = json!(true);
        }
        if let Some((lo, hi)) = s.bounds {
            a["min"] = json!(lo.to_array());
            a["max"] = json!(hi.to_array());
        }
        accessors.push(a);
        attributes.insert(s.name.clone(), json!(i));
    }
    let mut buffer = json!({ "byteLength": bin.len() });
    if container == GltfContainer::Embedded {
        buffer["uri"] = json!(format!("data:application/octet-stream;base64,{}", base64_encode(&bin)));
    }
    let document = json!({
        "asset": { "version": "2.0", "generator": concat!("splat-io ", env!("CARGO_PKG_VERSION")) },
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{
            "attributes": attributes,
            "mode": POINTS,
            "extensions": { EXTENSION: {
                "kernel": "ellipse",
                "colorSpace": "srgb_rec709_display",
                "sortingMethod": "cameraDistance",
                "projection": "perspective"
            } }
        }] }],
        "buffers": [buffer],
        "bufferViews": views,
        "accessors": accessors,
    });
    let text = serde_json::to_vec(&document).map_err(ErrorKind::Json)?;
    if container == GltfContainer::Embedded {
        return Ok(text);
    }
    let json_len = text.len().next_multiple_of(4);
    let total = 12 + 8 + json_len + 8 + bin.len();
    let total32 = u32::try_from(total).map_err(|_| gltf_error(format!("{total} bytes exceed a GLB's 4 GiB")))?;
    let mut out = Vec::with_capacity(total);
    for word in [GLB_MAGIC, 2, total32, json_len as u32, CHUNK_JSON] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&text);
    out.resize(12 + 8 + json_len, b' ');
    for word in [bin.len() as u32, CHUNK_BIN] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Standard base64 (RFC 4648 §4) with padding.
fn base64_encode(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            out.push(if i <= chunk.len() { DIGITS[(n >> shift & 63) as usize] as char } else { '=' });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::rng::SplitMix64;

    fn scene(degree: u8) -> Scene {
        let mut rng = SplitMix64::new(4);
        let mut r = || rng.next_f32();
        let particles = (0..20)
            .map(|_| {
                let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
                for c in &mut sh[..sh_coeff_count(degree)] {
                    *c = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5);
                }
                let q = Quat::from_xyzw(r() - 0.5, r() - 0.5, r() - 0.5, r() - 0.5);
                let mean = Vec3::new(r(), r(), r()) * 4.0 - 2.0;
                Particle::new(mean, Vec3::new(r(), r(), r()) * 0.1 + 0.01, q, r(), sh).unwrap()
            })
            .collect();
        Scene::new(particles, degree)
    }

    fn same(a: &Scene, b: &Scene) {
        assert_eq!(a.sh_degree, b.sh_degree);
        for (p, q) in a.particles.iter().zip(&b.particles) {
            assert!((p.mean - q.mean).abs().max_element() < 1e-6, "{:?} {:?}", p.mean, q.mean);
            assert!((p.scale - q.scale).abs().max_element() < 1e-7);
            assert!(p.rotation.dot(q.rotation).abs() > 1.0 - 1e-6);
            assert_eq!(p.opacity, q.opacity);
            for k in 0..SH_MAX_COEFFS {
                assert_eq!(p.sh[k], q.sh[k], "coefficient {k}");
            }
        }
    }

    #[test]
    fn glb_and_gltf_round_trip_losslessly() {
        for degree in [0, 1, 3] {
            let s = scene(degree);
            for container in [GltfContainer::Glb, GltfContainer::Embedded] {
                let bytes = encode_gltf_splats(&s, container).unwrap();
                same(&s, &parse_gltf_splats(&bytes, Path::new(".")).unwrap());
            }
        }
    }

    #[test]
    fn the_half_turn_is_its_own_inverse_and_flips_odd_orders() {
        let signs: Vec<f32> = (1..16).map(half_turn_sign).collect();
        // Bands 1–3 in the 3DGS order (y, z, x; …): (−1)^m for m = −l … l.
        assert_eq!(signs, [-1., 1., -1., 1., -1., 1., -1., 1., -1., 1., -1., 1., -1., 1., -1.]);
        let mut p = scene(3).particles[3].clone();
        let before = p.clone();
        half_turn(&mut p);
        assert_eq!(p.mean, Vec3::new(-before.mean.x, -before.mean.y, before.mean.z));
        let turned = Quat::from_rotation_z(std::f32::consts::PI) * before.rotation;
        assert!(p.rotation.dot(turned).abs() > 1.0 - 1e-6);
        half_turn(&mut p);
        assert_eq!(p.mean, before.mean);
        assert_eq!(p.rotation.to_array().map(|c| c.abs()), before.rotation.to_array().map(|c| c.abs()));
    }

    #[test]
    fn nodes_place_the_splats_and_what_they_cannot_take_is_refused() {
        let s = scene(0);
        let bytes = encode_gltf_splats(&s, GltfContainer::Embedded).unwrap();
        let mut doc: Value = serde_json::from_slice(&bytes).unwrap();
        let turn = Quat::from_rotation_y(0.7);
        doc["nodes"] = json!([{ "children": [1], "translation": [1.0, 2.0, 3.0] }, { "mesh": 0, "rotation": turn.to_array(), "scale": [2.0, 2.0, 2.0] }]);
        doc["scenes"] = json!([{ "nodes": [0] }]);
        let placed = parse_gltf_splats(&serde_json::to_vec(&doc).unwrap(), Path::new(".")).unwrap();
        let m = Mat4::from_scale_rotation_translation(Vec3::splat(2.0), turn, Vec3::new(1.0, 2.0, 3.0));
        for (p, q) in s.particles.iter().zip(&placed.particles) {
            // In glTF axes the node acts on the turned splat.
            let mut g = p.clone();
            half_turn(&mut g);
            let mut expected =
                Particle { mean: m.transform_point3(g.mean), scale: 2.0 * g.scale, rotation: turn * g.rotation, ..g };
            half_turn(&mut expected);
            assert!((expected.mean - q.mean).abs().max_element() < 1e-5);
            assert!((expected.scale - q.scale).abs().max_element() < 1e-6);
            assert!(expected.rotation.dot(q.rotation).abs() > 1.0 - 1e-5);
        }
        // The SH turn with the node: the colour seen along d is the original's along the
        // direction that the node turned into d (H the half turn between the axes).
        let sh3 = scene(3);
        let mut doc3: Value =
            serde_json::from_slice(&encode_gltf_splats(&sh3, GltfContainer::Embedded).unwrap()).unwrap();
        doc3["nodes"] = json!([{ "mesh": 0, "rotation": turn.to_array() }]);
        let turned = parse_gltf_splats(&serde_json::to_vec(&doc3).unwrap(), Path::new(".")).unwrap();
        let h = |v: Vec3| Vec3::new(-v.x, -v.y, v.z);
        for (p, q) in sh3.particles.iter().zip(&turned.particles) {
            for d in [Vec3::X, Vec3::new(0.3, -0.8, 0.52).normalize(), Vec3::new(-0.6, 0.1, -0.79).normalize()] {
                let seen = splat_core::sh::eval(&q.sh.to_array(), 3, d);
                let original = splat_core::sh::eval(&p.sh.to_array(), 3, h(turn.inverse() * h(d)));
                assert!((seen - original).abs().max_element() < 1e-4, "{seen} against {original}");
            }
        }
        doc["nodes"][1]["scale"] = json!([1.0, 2.0, 1.0]);
        let e = parse_gltf_splats(&serde_json::to_vec(&doc).unwrap(), Path::new(".")).unwrap_err().to_string();
        assert!(e.contains("node 1") && e.contains("uniform scale"), "{e}");
    }

    /// Quantised attributes (the extension's normalized integer rotations and opacities),
    /// interleaved in one strided buffer view, read with glTF's normalisation.
    #[test]
    fn quantised_interleaved_attributes_are_dequantised() {
        let s = scene(0);
        let mut doc: Value = serde_json::from_slice(&encode_gltf_splats(&s, GltfContainer::Embedded).unwrap()).unwrap();
        // Per splat 12 bytes: rotation as 4 × i16 normalized, opacity as u8 normalized, 3 pad.
        let snorm = |x: f32| (x * 32767.0).round() as i16;
        let mut bytes = Vec::new();
        for p in &s.particles {
            let mut g = p.clone();
            half_turn(&mut g);
            for c in g.rotation.to_array() {
                bytes.extend(snorm(c).to_le_bytes());
            }
            bytes.extend([(p.opacity * 255.0).round() as u8, 0, 0, 0]);
        }
        let uri = format!("data:application/octet-stream;base64,{}", base64_encode(&bytes));
        doc["buffers"].as_array_mut().unwrap().push(json!({ "byteLength": bytes.len(), "uri": uri }));
        let view = doc["bufferViews"].as_array().unwrap().len();
        doc["bufferViews"]
            .as_array_mut()
            .unwrap()
            .push(json!({ "buffer": 1, "byteLength": bytes.len(), "byteStride": 12 }));
        let first = doc["accessors"].as_array().unwrap().len();
        doc["accessors"].as_array_mut().unwrap().extend([
            json!({ "bufferView": view, "componentType": SHORT, "normalized": true, "count": s.particles.len(), "type": "VEC4" }),
            json!({ "bufferView": view, "byteOffset": 8, "componentType": UNSIGNED_BYTE, "normalized": true, "count": s.particles.len(), "type": "SCALAR" }),
        ]);
        let attributes = &mut doc["meshes"][0]["primitives"][0]["attributes"];
        attributes[format!("{EXTENSION}:ROTATION")] = json!(first);
        attributes[format!("{EXTENSION}:OPACITY")] = json!(first + 1);
        let read = parse_gltf_splats(&serde_json::to_vec(&doc).unwrap(), Path::new(".")).unwrap();
        for (p, q) in s.particles.iter().zip(&read.particles) {
            assert!((p.opacity - q.opacity).abs() <= 0.5 / 255.0 + 1e-7, "{} {}", p.opacity, q.opacity);
            assert!(p.rotation.dot(q.rotation).abs() > 1.0 - 1e-4, "{:?} {:?}", p.rotation, q.rotation);
            assert_eq!(p.mean, q.mean);
        }
        // The stride is honoured: without it the elements run together and the values differ.
        doc["bufferViews"][view]["byteStride"] = Value::Null;
        let packed = parse_gltf_splats(&serde_json::to_vec(&doc).unwrap(), Path::new("."));
        assert!(
            packed.map_or(true, |r| r
                .particles
                .iter()
                .zip(&s.particles)
                .any(|(q, p)| (q.opacity - p.opacity).abs() > 0.01))
        );
    }

    #[test]
    fn malformed_documents_are_refused_with_the_problem_named() {
        let bytes = encode_gltf_splats(&scene(1), GltfContainer::Embedded).unwrap();
        let doc: Value = serde_json::from_slice(&bytes).unwrap();
        let refused = |edit: &dyn Fn(&mut Value), needle: &str| {
            let mut d = doc.clone();
            edit(&mut d);
            let e = parse_gltf_splats(&serde_json::to_vec(&d).unwrap(), Path::new(".")).unwrap_err().to_string();
            assert!(e.contains(needle), "expected '{needle}' in: {e}");
        };
        fn attributes(d: &mut Value) -> &mut Map<String, Value> {
            d["meshes"][0]["primitives"][0]["attributes"].as_object_mut().unwrap()
        }
        refused(
            &|d| {
                attributes(d).remove("KHR_gaussian_splatting:SCALE");
            },
            "KHR_gaussian_splatting:SCALE is missing",
        );
        refused(
            &|d| {
                attributes(d).remove("KHR_gaussian_splatting:SH_DEGREE_1_COEF_2");
            },
            "SH degree 1 has 2 of its 3",
        );
        refused(
            &|d| d["extensionsRequired"] = json!(["KHR_gaussian_splatting_compression_spz_2"]),
            "KHR_gaussian_splatting_compression_spz_2",
        );
        refused(
            &|d| d["meshes"][0]["primitives"][0]["extensions"][EXTENSION]["colorSpace"] = json!("lin_rec709_display"),
            "lin_rec709_display",
        );
        refused(&|d| d["accessors"][3]["count"] = json!(1000), "do not fit");
        refused(&|d| d["accessors"][4]["type"] = json!("VEC2"), "expected SCALAR");
        refused(&|d| d["meshes"][0]["primitives"][0]["extensions"] = json!({}), "no mesh primitive");
        // A NaN opacity is the particle's error, with its index.
        let mut nan = scene(0);
        nan.particles[5].opacity = f32::NAN;
        let e = parse_gltf_splats(&encode_gltf_splats(&nan, GltfContainer::Glb).unwrap(), Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(e.contains("vertex 5"), "{e}");
        // Every prefix of a .glb gives an error, never a panic.
        let glb = encode_gltf_splats(&scene(3), GltfContainer::Glb).unwrap();
        for end in 0..glb.len() - 1 {
            assert!(parse_gltf_splats(&glb[..end], Path::new(".")).is_err(), "a {end}-byte prefix read");
        }
    }

    #[test]
    fn base64_round_trips() {
        for len in 0..10 {
            let bytes: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            assert_eq!(crate::mesh::base64_decode(&base64_encode(&bytes)).unwrap(), bytes);
        }
        assert_eq!(base64_encode(b"glTF"), "Z2xURg==");
    }
}
