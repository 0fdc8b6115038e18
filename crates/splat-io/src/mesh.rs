//! Triangle meshes for worlds: Wavefront `.obj` (through `tobj`) and glTF 2.0 `.gltf` / `.glb`
//! (through `gltf`), read into one [`TriangleMesh`] each, positions in the file's own units.
//!
//! OBJ: every object and group, polygons fanned into triangles, normals where the file has them;
//! `mtllib` is ignored (materials come from the world file). glTF: every triangle primitive of
//! the default scene (or the first), each node's transform applied, buffers from the `.glb`
//! binary chunk, a file beside the `.gltf`, or a base64 `data:` URI.

use crate::{Error, ErrorKind};
use glam::{Mat4, Vec3};
use splat_core::mesh::TriangleMesh;
use std::path::Path;

/// Read a mesh, choosing the format by extension (`.obj`, `.gltf`, `.glb`).
pub fn read_mesh(path: &Path) -> Result<TriangleMesh, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let bytes = crate::read_file(path)?;
    let mesh = match ext.as_deref() {
        Some("obj") => parse_obj(&bytes),
        Some("gltf" | "glb") => parse_gltf(&bytes, path.parent().unwrap_or(Path::new("."))),
        _ => return Err(Error::new(path, ErrorKind::UnknownExtension { expected: ".obj, .gltf or .glb" })),
    };
    let mesh = mesh.and_then(|m| {
        m.validate()?;
        if m.triangles.is_empty() { Err("the file holds no triangles".into()) } else { Ok(m) }
    });
    mesh.map_err(|m| Error::new(path, ErrorKind::Mesh(m)))
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
/// `base`.
pub fn parse_gltf(bytes: &[u8], base: &Path) -> Result<TriangleMesh, String> {
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
    let mut mesh = TriangleMesh::default();
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 1 << 20 {
            return Err("glTF node hierarchy is cyclic or too deep".into());
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(m) = node.mesh() {
            append_gltf_mesh(&mut mesh, &m, world, &buffers)?;
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    Ok(mesh)
}

/// Append every triangle primitive of `m` under transform `world`.
fn append_gltf_mesh(mesh: &mut TriangleMesh, m: &gltf::Mesh, world: Mat4, buffers: &[Vec<u8>]) -> Result<(), String> {
    let normal_map = glam::Mat3::from_mat4(world).inverse().transpose();
    for primitive in m.primitives() {
        if primitive.mode() != gltf::mesh::Mode::Triangles {
            continue;
        }
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
        // Normals for every vertex of the mesh or for none.
        match (&normals, mesh.positions.is_empty() || !mesh.normals.is_empty()) {
            (Some(n), true) if n.len() == positions.len() => mesh.normals.extend(n),
            _ => mesh.normals.clear(),
        }
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(positions);
        mesh.triangles.extend(indices.chunks_exact(3).map(|t| [base + t[0], base + t[1], base + t[2]]));
    }
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
        let mesh = parse_gltf(json.as_bytes(), Path::new(".")).unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
        assert_eq!(mesh.positions[1], Vec3::new(1.0, 0.0, 2.0));
        // A buffer shorter than declared is refused, not read past its end.
        let short = json.replace("\"byteLength\":36,\"uri\"", "\"byteLength\":48,\"uri\"");
        assert!(parse_gltf(short.as_bytes(), Path::new(".")).unwrap_err().contains("fewer than"));
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
