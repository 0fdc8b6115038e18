//! Triangle meshes for worlds: Wavefront `.obj` (through `tobj`) and glTF 2.0 `.gltf` / `.glb`
//! (through `gltf`), read into one [`TriangleMesh`] each, positions in the file's own units.
//!
//! OBJ: every object and group, polygons fanned into triangles, normals where the file has them;
//! `mtllib` is ignored (materials come from the world file). glTF: every triangle primitive of
//! the default scene (or the first), each node's transform applied, buffers from the `.glb`
//! binary chunk, a file beside the `.gltf`, or a base64 `data:` URI; one part per material,
//! read as [`gltf_material`] maps it.

use crate::{Error, ErrorKind};
use glam::{Mat4, Vec3};
use splat_core::lighting::Material;
use splat_core::mesh::{MeshMaterial, TriangleMesh};
use std::path::Path;

/// The triangles of one material of a mesh file.
#[derive(Clone, Debug, Default)]
pub struct MeshPart {
    /// The triangles, in the file's units.
    pub mesh: TriangleMesh,
    /// The file's material ([`gltf_material`]); `None` where the file gives none (an OBJ, a
    /// glTF primitive without a material): the world's, else the matte default.
    pub material: Option<MeshMaterial>,
}

/// A mesh file read: its parts, and what of its materials this renderer does not represent.
#[derive(Clone, Debug, Default)]
pub struct MeshRead {
    /// One part per material, in the order the file first uses them.
    pub parts: Vec<MeshPart>,
    /// What was not read (textures, vertex colours, extensions), for the user.
    pub notes: Vec<String>,
}

impl MeshRead {
    /// Every triangle of every part.
    pub fn triangle_count(&self) -> usize {
        self.parts.iter().map(|p| p.mesh.triangles.len()).sum()
    }
}

/// Read a mesh, choosing the format by extension (`.obj`, `.gltf`, `.glb`).
pub fn read_mesh(path: &Path) -> Result<MeshRead, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let bytes = crate::read_file(path)?;
    let read = match ext.as_deref() {
        Some("obj") => {
            parse_obj(&bytes).map(|mesh| MeshRead { parts: vec![MeshPart { mesh, material: None }], notes: Vec::new() })
        }
        Some("gltf" | "glb") => parse_gltf(&bytes, path.parent().unwrap_or(Path::new("."))),
        _ => return Err(Error::new(path, ErrorKind::UnknownExtension { expected: ".obj, .gltf or .glb" })),
    };
    let read = read.and_then(|r| {
        r.parts.iter().try_for_each(|p| p.mesh.validate())?;
        if r.triangle_count() == 0 { Err("the file holds no triangles".into()) } else { Ok(r) }
    });
    read.map_err(|m| Error::new(path, ErrorKind::Mesh(m)))
}

/// Parse OBJ text: all models into one mesh; normals only when every model has them.
pub fn parse_obj(bytes: &[u8]) -> Result<TriangleMesh, String> {
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (models, _) = tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &options, |_| {
        Err(tobj::LoadError::OpenFileFailed) // materials come from the world file
    })
    .map_err(|e| format!("OBJ: {e}"))?;
    let with_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
    let mut mesh = TriangleMesh::default();
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(m.positions.chunks_exact(3).map(Vec3::from_slice));
        if with_normals {
            mesh.normals.extend(m.normals.chunks_exact(3).map(Vec3::from_slice));
        }
        let count = (m.positions.len() / 3) as u32;
        for t in m.indices.chunks_exact(3) {
            if let Some(&bad) = t.iter().find(|&&v| v >= count) {
                return Err(format!("OBJ object '{}' indexes vertex {bad} of {count}", model.name));
            }
            mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
        }
    }
    Ok(mesh)
}

/// Parse a glTF 2.0 document (`.gltf` JSON or `.glb`); external buffers are read relative to
/// `base`. Primitives of a material that draws nothing (blended at alpha 0, masked below its
/// cutoff) are left out.
pub fn parse_gltf(bytes: &[u8], base: &Path) -> Result<MeshRead, String> {
    let raw = gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| format!("glTF: {e}"))?;
    let mut json = raw.document.into_json();
    // Primitives with attributes gltf-json cannot name are the splats of KHR_gaussian_splatting
    // (read by crate::gltf_splats): the triangles beside them are this reader's.
    for mesh in &mut json.meshes {
        mesh.primitives.retain(|p| p.attributes.keys().all(|k| matches!(k, gltf::json::validation::Checked::Valid(_))));
    }
    // A mesh left without primitives goes, and the nodes that placed it place nothing.
    let mut kept = 0;
    let renumber: Vec<Option<u32>> = json
        .meshes
        .iter()
        .map(|m| {
            (!m.primitives.is_empty()).then(|| {
                kept += 1;
                kept - 1
            })
        })
        .collect();
    json.meshes.retain(|m| !m.primitives.is_empty());
    for node in &mut json.nodes {
        node.mesh = match node.mesh {
            // An index past the meshes stays, for the validation to name.
            Some(m) if m.value() < renumber.len() => renumber[m.value()].map(gltf::json::Index::new),
            other => other,
        };
    }
    // gltf-json 1.4's validation indexes a primitive's POSITION accessor unchecked: check first.
    let accessors = json.accessors.len();
    for (i, mesh) in json.meshes.iter().enumerate() {
        for primitive in &mesh.primitives {
            if let Some(a) = primitive.attributes.values().map(|a| a.value()).find(|&a| a >= accessors) {
                return Err(format!("glTF mesh {i} names accessor {a} of {accessors}"));
            }
        }
    }
    let document = gltf::Document::from_json(json).map_err(|e| format!("glTF: {e}"))?;
    let gltf = gltf::Gltf { document, blob: raw.blob };
    let mut buffers = Vec::new();
    for buffer in gltf.document.buffers() {
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => gltf.blob.clone().ok_or("glTF buffer refers to a missing binary chunk")?,
            gltf::buffer::Source::Uri(uri) => buffer_from_uri(uri, base)?,
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "glTF buffer {} holds {} bytes, fewer than the {} it declares",
                buffer.index(),
                data.len(),
                buffer.length()
            ));
        }
        buffers.push(data);
    }
    let scene = gltf.document.default_scene().or_else(|| gltf.document.scenes().next());
    let roots: Vec<gltf::Node> = match scene {
        Some(s) => s.nodes().collect(),
        None => gltf.document.nodes().collect(),
    };
    let mut notes = Vec::new();
    let materials =
        gltf.document.materials().map(|m| gltf_material(&m, &mut notes)).collect::<Result<Vec<_>, String>>()?;
    let unread: Vec<&str> = gltf.document.extensions_used().filter(|e| !READ_EXTENSIONS.contains(e)).collect();
    if !unread.is_empty() {
        notes.push(format!("glTF extensions not read: {}", unread.join(", ")));
    }
    let mut parts = Parts { materials, parts: Vec::new(), colours: false };
    // Depth first, in the document's order: a node, then its children in turn.
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().rev().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 1 << 20 {
            return Err("glTF node hierarchy is cyclic or too deep".into());
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(m) = node.mesh() {
            parts.append(&m, world, &buffers)?;
        }
        let children: Vec<gltf::Node> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    if parts.colours {
        notes.push(
            "glTF vertex colours (COLOR_0): their rgb is not read, nor their alpha outside BLEND materials".into(),
        );
    }
    Ok(MeshRead { parts: parts.parts.into_iter().map(|(_, part)| part).collect(), notes })
}

/// The glTF extensions [`gltf_material`] reads (`KHR_gaussian_splatting` is read by
/// [`crate::gltf_splats`]).
const READ_EXTENSIONS: [&str; 5] = [
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_materials_unlit",
    "KHR_gaussian_splatting",
];

/// A glTF material (glTF 2.0 §3.9, metallic–roughness) as this renderer's, or `None` for one
/// that draws nothing. Each factor maps onto [`MeshMaterial`]'s shares as the path tracer reads
/// them ([`splat_core::path`]: a Lambertian lobe of albedo k_d ⊙ c, a GGX conductor with
/// Schlick's Fresnel, a dielectric, GGX α = roughness² as in glTF):
///
/// - c = `baseColorFactor`.rgb; the conductor share (`mirror`) is `metallicFactor`, its F₀
///   (`mirror_tint`) c, as glTF's `conductor_fresnel` (Appendix B); the
///   dielectric's (`transmission`) (1 − metallic) × `KHR_materials_transmission`, the rest
///   Lambertian with k_d = 1 (albedo c) and the matte default's ambient stand-in k_a = 0.1;
///   `roughness` = `roughnessFactor`; `ior` = `KHR_materials_ior` (1.5).
/// - Emission k_e ⊙ c = `emissiveFactor` × `KHR_materials_emissive_strength`, so k_e = that ÷ c
///   (a black channel that emits is read as [`EMITTING_BLACK`]); `KHR_materials_unlit`: c
///   emitted, unlit.
/// - Opacity: `baseColorFactor`.a for `BLEND` (0 draws nothing; times each vertex's `COLOR_0`
///   alpha, the mesh's per-vertex opacities), 1 for `OPAQUE`, and for `MASK` 1 at or above
///   `alphaCutoff` (0.5), else nothing.
///
/// - The Lambertian part lies under glTF's dielectric specular layer (`specular_layer`: F₀ =
///   ((ior − 1)/(ior + 1))², 0.04 at 1.5, `fresnel_mix`), which the path tracer draws.
///
/// Not represented: textures (the factors alone are read; noted).
pub fn gltf_material(m: &gltf::Material, notes: &mut Vec<String>) -> Result<Option<MeshMaterial>, String> {
    let name = m.index().map_or("the default material".to_string(), |i| format!("material {i}"));
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, a] = pbr.base_color_factor();
    let opacity = match m.alpha_mode() {
        gltf::material::AlphaMode::Opaque => 1.0,
        gltf::material::AlphaMode::Mask if a >= m.alpha_cutoff().unwrap_or(0.5) => 1.0,
        gltf::material::AlphaMode::Mask => return Ok(None),
        gltf::material::AlphaMode::Blend if a > 0.0 => a.min(1.0),
        gltf::material::AlphaMode::Blend => return Ok(None),
    };
    let textures = [
        ("base colour", pbr.base_color_texture().is_some()),
        ("metallic-roughness", pbr.metallic_roughness_texture().is_some()),
        ("emissive", m.emissive_texture().is_some()),
        ("normal", m.normal_texture().is_some()),
        ("transmission", m.transmission().is_some_and(|t| t.transmission_texture().is_some())),
    ];
    let unread: Vec<&str> = textures.iter().filter(|t| t.1).map(|t| t.0).collect();
    if !unread.is_empty() {
        notes.push(format!("glTF {name}: {} textures not read (their factors are)", unread.join(", ")));
    }
    let emission = Vec3::from(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0);
    let (c, emissive) = emitting(emission, Vec3::new(r, g, b));
    let metallic = pbr.metallic_factor().clamp(0.0, 1.0);
    let transmission = m.transmission().map_or(0.0, |t| t.transmission_factor().clamp(0.0, 1.0));
    let shading = if m.unlit() {
        Material::EMISSIVE
    } else {
        Material { emissive, ambient: Vec3::splat(0.1), diffuse: Vec3::ONE, ..Material::DIFFUSE }
    };
    let material = MeshMaterial {
        color: c,
        shading,
        mirror: if m.unlit() { 0.0 } else { metallic },
        // glTF's conductor_fresnel: a metal's F₀ is its base colour.
        mirror_tint: if metallic > 0.0 && !m.unlit() { c.clamp(Vec3::ZERO, Vec3::ONE) } else { Vec3::ONE },
        transmission: if m.unlit() { 0.0 } else { (1.0 - metallic) * transmission },
        ior: m.ior().unwrap_or(1.5),
        roughness: pbr.roughness_factor().clamp(0.0, 1.0),
        // glTF's dielectric BRDF: the base under a specular layer of F₀ from the ior.
        specular_layer: !m.unlit(),
        opacity,
    };
    material.validate().map_err(|e| format!("glTF {name}: {e}"))?;
    Ok(Some(material))
}

/// The base colour an emitting black channel is read as: k_e ⊙ c is a mesh's emission, so c
/// cannot be 0 where it emits; 10⁻⁶ reflects nothing visible.
pub const EMITTING_BLACK: f32 = 1e-6;

/// The colour c and emissive coefficients k_e of a surface of base colour `base` that emits
/// `emission`, so that k_e ⊙ c is the emission: a black channel that emits reflects
/// [`EMITTING_BLACK`] of the light instead (k_e ⊙ 0 would emit nothing).
pub fn emitting(emission: Vec3, base: Vec3) -> (Vec3, Vec3) {
    let emits = emission.cmpgt(Vec3::ZERO);
    let c = Vec3::select(emits & base.cmpeq(Vec3::ZERO), Vec3::splat(EMITTING_BLACK), base);
    (c, Vec3::select(emits, emission / c, Vec3::ZERO))
}

/// The parts of a glTF file as its primitives are appended: keyed by material index.
struct Parts {
    /// Each material of the file as [`gltf_material`] read it (`None`: draws nothing).
    materials: Vec<Option<MeshMaterial>>,
    parts: Vec<(Option<usize>, MeshPart)>,
    /// Whether a primitive had vertex colours whose rgb (or alpha, outside BLEND) went unread.
    colours: bool,
}

impl Parts {
    /// Append every triangle primitive of `m` under transform `world` to its material's part.
    fn append(&mut self, m: &gltf::Mesh, world: Mat4, buffers: &[Vec<u8>]) -> Result<(), String> {
        for primitive in m.primitives() {
            let index = primitive.material().index();
            let material = match index {
                None => None,
                Some(i) => match self.materials.get(i) {
                    Some(Some(material)) => Some(*material),
                    Some(None) => continue,
                    None => {
                        return Err(format!("glTF mesh {} names material {i} of {}", m.index(), self.materials.len()));
                    }
                },
            };
            // A blended material's vertex colours' alpha is the vertex opacity (glTF's default
            // material is opaque).
            let blend = primitive.material().alpha_mode() == gltf::material::AlphaMode::Blend;
            self.colours |= primitive.get(&gltf::Semantic::Colors(0)).is_some();
            let at = match self.parts.iter().position(|(k, _)| *k == index) {
                Some(at) => at,
                None => {
                    self.parts.push((index, MeshPart { mesh: TriangleMesh::default(), material }));
                    self.parts.len() - 1
                }
            };
            append_primitive(&mut self.parts[at].1.mesh, m, &primitive, world, buffers, blend)?;
        }
        Ok(())
    }
}

/// Append a triangle primitive of `m` under transform `world` (others are skipped), with its
/// vertex colours' alpha as the vertices' opacities where its material `blend`s (glTF 2.0
/// §3.9: `COLOR_0` multiplies the base colour, alpha included).
fn append_primitive(
    mesh: &mut TriangleMesh,
    m: &gltf::Mesh,
    primitive: &gltf::Primitive,
    world: Mat4,
    buffers: &[Vec<u8>],
    blend: bool,
) -> Result<(), String> {
    if primitive.mode() != gltf::mesh::Mode::Triangles {
        return Ok(());
    }
    let normal_map = glam::Mat3::from_mat4(world).inverse().transpose();
    let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| format!("glTF mesh {} has a primitive without positions", m.index()))?
        .map(|p| world.transform_point3(Vec3::from(p)))
        .collect();
    let normals: Option<Vec<Vec3>> =
        reader.read_normals().map(|n| n.map(|n| (normal_map * Vec3::from(n)).normalize_or_zero()).collect());
    let count = positions.len() as u32;
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..count).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&v| v >= count) {
        return Err(format!("glTF mesh {} indexes vertex {bad} of {count}", m.index()));
    }
    // Opacities for every vertex of the part once one has them (1 where a primitive has none).
    let (before, added) = (mesh.positions.len(), positions.len());
    match reader.read_colors(0).filter(|_| blend) {
        Some(colours) => {
            let alphas: Vec<f32> = colours.into_rgba_f32().map(|c| c[3]).collect();
            if alphas.len() != added {
                return Err(format!("glTF mesh {} has {} colours for {added} vertices", m.index(), alphas.len()));
            }
            mesh.opacities.resize(before, 1.0);
            mesh.opacities.extend(alphas);
        }
        None if !mesh.opacities.is_empty() => mesh.opacities.resize(before + added, 1.0),
        None => {}
    }
    // Normals for every vertex of the part or for none.
    match (&normals, mesh.positions.is_empty() || !mesh.normals.is_empty()) {
        (Some(n), true) if n.len() == positions.len() => mesh.normals.extend(n),
        _ => mesh.normals.clear(),
    }
    let base = mesh.positions.len() as u32;
    mesh.positions.extend(positions);
    mesh.triangles.extend(indices.chunks_exact(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
    if !mesh.normals.is_empty() && mesh.normals.len() != mesh.positions.len() {
        mesh.normals.clear();
    }
    Ok(())
}

/// The bytes of a buffer URI: a base64 `data:` URI, or a file relative to `base`.
pub(crate) fn buffer_from_uri(uri: &str, base: &Path) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, data) = rest.split_once(";base64,").ok_or("glTF data URI is not base64")?;
        return base64_decode(data).ok_or_else(|| "glTF data URI holds invalid base64".into());
    }
    if uri.contains("://") {
        return Err(format!("glTF buffer URI '{uri}' is remote: only files and data URIs are read"));
    }
    let path = base.join(uri);
    std::fs::read(&path).map_err(|e| format!("glTF buffer {}: {e}", path.display()))
}

/// Standard base64 (RFC 4648 §4), padding optional.
pub(crate) fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let digits = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for &c in digits {
        acc = (acc << 6) | u32::from(value(c)?);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_quads_fan_into_triangles_with_their_normals() {
        let text = b"o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n";
        let mesh = parse_obj(text).unwrap();
        assert_eq!(mesh.triangles.len(), 2);
        assert_eq!(mesh.positions.len(), mesh.normals.len());
        assert!(mesh.normals.iter().all(|&n| n == Vec3::Z));
        mesh.validate().unwrap();
    }

    #[test]
    fn gltf_with_an_embedded_buffer_and_a_node_transform() {
        // One triangle: positions (0,0,0), (1,0,0), (0,1,0) as 36 bytes of f32, base64-encoded,
        // under a node translated by (0, 0, 2).
        let floats: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
        let b64 = base64_encode(&bytes);
        let json = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
            "nodes":[{{"mesh":0,"translation":[0,0,2]}}],
            "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}],
            "bufferViews":[{{"buffer":0,"byteLength":36}}],
            "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}]}}"#
        );
        let read = parse_gltf(json.as_bytes(), Path::new(".")).unwrap();
        assert_eq!(read.parts.len(), 1);
        assert_eq!(read.parts[0].material, None, "no material: the world's");
        let mesh = &read.parts[0].mesh;
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
        assert_eq!(mesh.positions[1], Vec3::new(1.0, 0.0, 2.0));
        // A buffer shorter than declared is refused, not read past its end.
        let short = json.replace("\"byteLength\":36,\"uri\"", "\"byteLength\":48,\"uri\"");
        assert!(parse_gltf(short.as_bytes(), Path::new(".")).unwrap_err().contains("fewer than"));
    }

    /// One part per material in the order of first use (two primitives of material 1 share
    /// one, the vertex colours' alpha of one of them its vertices' opacities, 1 for the
    /// other's), the default material's primitive left to the world (`None`), a blended
    /// material at alpha 0 drawing nothing, a texture noted, and a material the renderer cannot
    /// hold (a negative factor) refused by name.
    #[test]
    fn gltf_primitives_are_parted_by_material() {
        let floats: [f32; 21] =
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.25, 1.0, 1.0, 1.0, 0.5, 1.0, 1.0, 1.0, 0.75];
        let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
        let b64 = base64_encode(&bytes);
        let primitive = |material: &str| format!(r#"{{"attributes":{{"POSITION":0}}{material}}}"#);
        let primitives = [
            r#"{"attributes":{"POSITION":0,"COLOR_0":1},"material":1}"#.to_string(),
            primitive(""),
            primitive(r#","material":0"#),
            primitive(r#","material":1"#),
            primitive(r#","material":2"#),
        ]
        .join(",");
        let json = |red: &str| {
            format!(
                r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
                "meshes":[{{"primitives":[{primitives}]}}],
                "materials":[
                  {{"pbrMetallicRoughness":{{"baseColorFactor":[{red},0.5,0.5,1],"baseColorTexture":{{"index":0}}}}}},
                  {{"pbrMetallicRoughness":{{"baseColorFactor":[0.1,0.2,0.3,0.6],"metallicFactor":0}},"alphaMode":"BLEND"}},
                  {{"pbrMetallicRoughness":{{"baseColorFactor":[1,1,1,0]}},"alphaMode":"BLEND"}}],
                "textures":[{{"source":0}}],"images":[{{"uri":"nowhere.png"}}],
                "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                  {{"bufferView":1,"componentType":5126,"count":3,"type":"VEC4"}}],
                "bufferViews":[{{"buffer":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":48}}],
                "buffers":[{{"byteLength":84,"uri":"data:application/octet-stream;base64,{b64}"}}]}}"#
            )
        };
        let read = parse_gltf(json("0.9").as_bytes(), Path::new(".")).unwrap();
        let summary: Vec<(usize, Option<f32>)> =
            read.parts.iter().map(|p| (p.mesh.triangles.len(), p.material.map(|m| m.opacity))).collect();
        assert_eq!(summary, [(2, Some(0.6)), (1, None), (1, Some(1.0))]);
        assert_eq!(read.parts[0].material.unwrap().color, Vec3::new(0.1, 0.2, 0.3));
        assert_eq!(read.parts[0].mesh.opacities, [0.25, 0.5, 0.75, 1.0, 1.0, 1.0]);
        assert!(read.parts[1..].iter().all(|p| p.mesh.opacities.is_empty()));
        assert_eq!(read.parts[2].material.unwrap().mirror, 1.0, "glTF's metallicFactor defaults to 1");
        assert!(read.notes.iter().any(|n| n.contains("material 0: base colour textures not read")), "{:?}", read.notes);
        let e = parse_gltf(json("-1").as_bytes(), Path::new(".")).unwrap_err();
        assert!(e.contains("glTF material 0") && e.contains("colour"), "{e}");
    }

    #[test]
    fn bad_mesh_files_are_refused_with_the_reason() {
        assert!(parse_obj(b"v 0 0 0\nf 1 2 3\n").is_err());
        assert!(parse_gltf(b"{not json", Path::new(".")).unwrap_err().starts_with("glTF"));
        assert!(parse_gltf(b"glTF\x02\x00\x00\x00\xff\xff", Path::new(".")).is_err());
    }

    fn base64_encode(bytes: &[u8]) -> String {
        const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut out = String::new();
        for chunk in bytes.chunks(3) {
            let v = chunk.iter().enumerate().fold(0u32, |v, (i, &b)| v | u32::from(b) << (16 - 8 * i));
            for k in 0..=chunk.len() {
                out.push(A[(v >> (18 - 6 * k) & 63) as usize] as char);
            }
        }
        out
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 512, ..Default::default() })]

        /// No input makes either reader panic: arbitrary bytes, and the valid glTF above with
        /// one byte changed (the fuzz targets `obj` and `gltf` go further).
        #[test]
        fn no_input_panics(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..400), at in 0usize..1200, b in 32u8..127) {
            let _ = parse_obj(&bytes);
            let _ = parse_gltf(&bytes, Path::new("/nonexistent"));
            let mut text = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/seeds/gltf/triangle.gltf")).unwrap();
            let i = at % text.len();
            text[i] = b;
            let _ = parse_gltf(&text, Path::new("/nonexistent"));
        }
    }

    #[test]
    fn base64_round_trip() {
        for n in 0..10u8 {
            let bytes: Vec<u8> = (0..n).map(|i| i.wrapping_mul(37)).collect();
            assert_eq!(base64_decode(&base64_encode(&bytes)).unwrap(), bytes);
        }
    }
}
