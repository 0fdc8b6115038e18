//! Scene formats: round trips through every writer, with each format's quantisation bounds, and
//! files written by other tools (`cargo xtask assets` makes them with the pinned npm packages
//! PlayCanvas splat-transform and spz-js).
//!
//! A round trip passes when (1) every attribute is within half the format's quantisation step
//! (derived from the encoder, below) and (2) the exact image (Eq. 3, the oracle) moves by no
//! more than twice what a random within-step perturbation of the same attributes moves it: the
//! round trip costs what the format's precision costs, and not more. The controls decode with
//! the wrong axes and with a version 2 file read as version 3 data, and must fail (2).

use glam::{Quat, Vec3};
use splat_core::rng::SplitMix64;
use splat_core::sh::SH_C0;
use splat_core::{Camera, Particle, RenderSettings, Scene, ScreenFilter, render_oracle, scenes};
use splat_io::spz::{SpzAxes, SpzWriteOptions, encode_spz, parse_spz};
use std::path::PathBuf;

/// Half quantisation steps of a format, per attribute.
#[derive(Clone, Copy, Debug)]
struct Steps {
    /// Position, scene units.
    position: f32,
    /// ln(scale).
    log_scale: f32,
    /// Linear opacity.
    opacity: f32,
    /// SH DC coefficient.
    dc: f32,
    /// Band-1 SH coefficients.
    sh1: f32,
    /// Band 2–3 SH coefficients.
    sh_rest: f32,
    /// Rotation angle between the quaternions, radians.
    angle: f32,
}

/// `.spz` with 12 fractional bits: half steps of its encoder. SH: rounding to 1/128, then to
/// the centre of a bucket of 8 (band 1, 5 bits) or 16 (bands 2–3, 4 bits) steps.
fn spz_steps(version: u32) -> Steps {
    Steps {
        position: 0.5 / 4096.0,
        log_scale: 0.5 / 16.0,
        opacity: 0.5 / 255.0,
        dc: 0.5 / (0.15 * 255.0),
        sh1: 4.5 / 128.0,
        sh_rest: 8.5 / 128.0,
        angle: if version == 2 { v2_angle_bound() } else { 0.004 },
    }
}

/// Version 2 stores x, y, z of q (w ≥ 0) to δ = 0.5/127.5 and derives w = √(1 − |xyz|²): near
/// w = 0 the rounding can raise |xyz|² by up to 2√3δ + 3δ², which the decoder takes from w², so
/// w is lost up to √(2√3δ + 3δ²) and the rotation angle up to twice its arcsine (0.234 rad).
/// Versions 3–4 store the three smallest components to √½/511 (the bound 0.004 rad holds with
/// room: each component is off by ≤ 6.9e-4).
fn v2_angle_bound() -> f32 {
    let d = 0.5f32 / 127.5;
    2.0 * (2.0 * 3f32.sqrt() * d + 3.0 * d * d).sqrt().asin()
}

/// `.splat`: f32 position and scale, 8-bit RGB of the degree-0 colour and opacity, 8-bit
/// quaternion components.
fn splat_steps() -> Steps {
    Steps {
        position: 1e-7,
        log_scale: 1e-6,
        opacity: 0.5 / 255.0,
        dc: 0.5 / 255.0 / SH_C0,
        sh1: 0.0,
        sh_rest: 0.0,
        angle: 0.03,
    }
}

/// Largest error of each attribute between two scenes, as a `Steps`.
fn errors(a: &Scene, b: &Scene) -> Steps {
    assert_eq!(a.particles.len(), b.particles.len());
    assert_eq!(a.sh_degree, b.sh_degree);
    let mut e = Steps { position: 0.0, log_scale: 0.0, opacity: 0.0, dc: 0.0, sh1: 0.0, sh_rest: 0.0, angle: 0.0 };
    let max = |m: &mut f32, v: f32| *m = m.max(v);
    for (p, q) in a.particles.iter().zip(&b.particles) {
        max(&mut e.position, (p.mean - q.mean).abs().max_element());
        max(&mut e.log_scale, (p.scale.ln() - q.scale.ln()).abs().max_element());
        max(&mut e.opacity, (p.opacity - q.opacity).abs());
        max(&mut e.dc, (p.sh[0] - q.sh[0]).abs().max_element());
        for k in 1..16 {
            let d = (p.sh[k] - q.sh[k]).abs().max_element();
            max(if k < 4 { &mut e.sh1 } else { &mut e.sh_rest }, d);
        }
        max(&mut e.angle, 2.0 * p.rotation.dot(q.rotation).abs().min(1.0).acos());
    }
    e
}

fn within(e: Steps, s: Steps) -> Result<(), String> {
    let checks = [
        ("position", e.position, s.position),
        ("ln scale", e.log_scale, s.log_scale),
        ("opacity", e.opacity, s.opacity),
        ("dc", e.dc, s.dc),
        ("sh band 1", e.sh1, s.sh1),
        ("sh bands 2-3", e.sh_rest, s.sh_rest),
        ("rotation angle", e.angle, s.angle),
    ];
    for (name, error, bound) in checks {
        // One part in 10⁵ (plus 1e-6 absolute) for f32 arithmetic in the decode.
        if error > bound * 1.00001 + 1e-6 {
            return Err(format!("{name}: error {error:.3e} exceeds the half step {bound:.3e}"));
        }
    }
    Ok(())
}

/// The test scene: the 3,000-splat SH degree 3 cloud at 64 × 48.
fn cloud() -> (Scene, Camera) {
    let (scene, camera) = scenes::cloud();
    (scene, camera.rescaled(64, 48).unwrap())
}

fn image(scene: &Scene, camera: &Camera) -> Vec<f32> {
    render_oracle(scene, camera, &RenderSettings::default(), &splat_core::Frames::default(), &|_| {})
        .unwrap()
        .mean
        .data()
        .to_vec()
}

fn rmse(a: &[f32], b: &[f32]) -> f64 {
    let sum: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
    (sum / a.len() as f64).sqrt()
}

/// The scene with every attribute moved by a uniform random amount within ± its half step.
fn perturbed(scene: &Scene, s: Steps, seed: u64) -> Scene {
    let mut rng = SplitMix64::new(seed);
    let mut u = |h: f32| rng.range(-h, h);
    let particles = scene
        .particles
        .iter()
        .map(|p| {
            let mut q = p.clone();
            q.mean += Vec3::new(u(s.position), u(s.position), u(s.position));
            q.scale *= Vec3::new(u(s.log_scale).exp(), u(s.log_scale).exp(), u(s.log_scale).exp());
            q.opacity = (q.opacity + u(s.opacity)).clamp(0.0, 1.0);
            q.sh[0] += Vec3::new(u(s.dc), u(s.dc), u(s.dc));
            for k in 1..16 {
                let h = if k < 4 { s.sh1 } else { s.sh_rest };
                q.sh[k] += Vec3::new(u(h), u(h), u(h));
            }
            let axis = Vec3::new(u(1.0), u(1.0), u(1.0)).normalize_or(Vec3::X);
            q.rotation = (Quat::from_axis_angle(axis, u(s.angle)) * q.rotation).normalize();
            q
        })
        .collect();
    Scene { particles, ..Scene::new(Vec::new(), scene.sh_degree) }
}

/// Image RMSE of `back` against `scene`, and the bound: twice the RMSE of a within-step
/// perturbation.
fn image_check(scene: &Scene, back: &Scene, camera: &Camera, s: Steps) -> (f64, f64) {
    let reference = image(scene, camera);
    let bound = 2.0 * rmse(&reference, &image(&perturbed(scene, s, 7), camera));
    (rmse(&reference, &image(back, camera)), bound)
}

#[test]
fn spz_round_trips_stay_within_the_quantisation_step() {
    let (scene, camera) = cloud();
    for version in [2, 3, 4] {
        for axes in [SpzAxes::AsStored, SpzAxes::Rub] {
            let bytes = encode_spz(&scene, SpzWriteOptions { version, axes }).unwrap();
            let back = parse_spz(&bytes, axes).unwrap();
            let e = errors(&scene, &back);
            within(e, spz_steps(version)).unwrap_or_else(|m| panic!("spz v{version} {axes:?}: {m}"));
            let (error, bound) = image_check(&scene, &back, &camera, spz_steps(version));
            eprintln!(
                "spz v{version} {axes:?}: {} bytes ({:.1} per splat); image RMSE {error:.2e}, bound {bound:.2e}; \
                 errors {e:?}",
                bytes.len(),
                bytes.len() as f64 / scene.particles.len() as f64
            );
            assert!(error <= bound, "spz v{version}: image RMSE {error:.3e} > bound {bound:.3e}");
        }
    }
}

#[test]
fn the_round_trip_check_rejects_wrong_axes_and_a_wrong_rotation_code() {
    let (scene, camera) = cloud();
    let bytes = encode_spz(&scene, SpzWriteOptions { version: 3, axes: SpzAxes::Rub }).unwrap();
    let wrong_axes = parse_spz(&bytes, SpzAxes::AsStored).unwrap();
    let (error, bound) = image_check(&scene, &wrong_axes, &camera, spz_steps(3));
    eprintln!("control, RUB file read as stored: image RMSE {error:.2e}, bound {bound:.2e}");
    assert!(error > 4.0 * bound, "reading RUB data unconverted must fail the check ({error:.3e} vs {bound:.3e})");
    assert!(within(errors(&scene, &wrong_axes), spz_steps(3)).is_err());
    // A version 2 file whose header is changed to say 3 (its 3-byte rotations read as 4): the
    // decode fails or the check does.
    let v2 = encode_spz(&scene, SpzWriteOptions { version: 2, axes: SpzAxes::AsStored }).unwrap();
    let raw = gunzip(&v2);
    let mut relabelled = raw.clone();
    relabelled[4] = 3;
    match parse_spz(&gzip(&relabelled), SpzAxes::AsStored) {
        Err(e) => eprintln!("control, v2 data labelled v3: refused ({e})"),
        Ok(back) => assert!(within(errors(&scene, &back), spz_steps(3)).is_err()),
    }
    // The smallest detected change: one quantisation step of ln(scale) on every splat.
    let mut nudged = parse_spz(&bytes, SpzAxes::Rub).unwrap();
    for p in &mut nudged.particles {
        p.scale *= (1.0f32 / 16.0).exp();
    }
    assert!(within(errors(&scene, &nudged), spz_steps(3)).is_err(), "one step of scale must be seen");
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(bytes), &mut out).unwrap();
    out
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, bytes).unwrap();
    gz.finish().unwrap()
}

#[test]
fn ply_and_splat_round_trips() {
    use splat_io::ply::{PlyFormat, PlyOptions, encode_ply, parse_ply};
    let (scene, camera) = cloud();
    let back = parse_ply(&encode_ply(&scene, PlyFormat::BinaryLittleEndian), PlyOptions::default()).unwrap();
    let lossless =
        Steps { position: 0.0, log_scale: 1e-6, opacity: 1e-6, dc: 0.0, sh1: 0.0, sh_rest: 0.0, angle: 1e-3 };
    within(errors(&scene, &back), lossless).unwrap();
    // .splat keeps the degree-0 colour only: compare with the scene at degree 0.
    let flat = Scene::new(scene.particles.clone(), 0);
    let mut back = splat_io::splat::parse_splat(&splat_io::splat::encode_splat(&flat)).unwrap();
    for (b, p) in back.particles.iter_mut().zip(&flat.particles) {
        let mut all = p.sh.to_array(); // the format has no higher bands to compare
        all[0] = b.sh[0];
        b.sh = all.into();
    }
    within(errors(&flat, &back), splat_steps()).unwrap();
    let (error, bound) = image_check(&flat, &back, &camera, splat_steps());
    eprintln!(".splat: image RMSE {error:.2e}, bound {bound:.2e}");
    assert!(error <= bound);
}

/// Files written by other tools from `interop/source.ply` (`cargo xtask assets`).
fn interop_dir() -> Option<PathBuf> {
    let dir = splat_tests::root().join("target/interop");
    if !dir.join("source.ply").exists() {
        splat_tests::skip(
            &splat_tests::current_test(),
            &format!("{} has no files from other tools (run `cargo xtask assets`, needs Node.js)", dir.display()),
        );
        return None;
    }
    Some(dir)
}

#[test]
fn files_written_by_other_tools_read_within_their_quantisation() {
    let Some(dir) = interop_dir() else { return };
    let source = splat_io::read_scene(&dir.join("source.ply")).unwrap();
    let (_, camera) = cloud();
    let files = [
        ("spz-js-v2.spz", Some(spz_steps(2))),
        ("splat-transform-v3.spz", Some(spz_steps(3))),
        ("splat-transform-v4.spz", Some(spz_steps(4))),
        ("splat-transform.compressed.ply", None),
        ("spz-js.compressed.ply", None),
    ];
    for (name, steps) in files {
        let read = splat_io::read_scene_with(&dir.join(name), Default::default())
            .unwrap_or_else(|e| panic!("{name} does not read: {e}"));
        // Compressed .ply writers reorder the splats (by Morton code) into their chunks.
        let back = if read.format == splat_io::SceneFormat::CompressedPly {
            in_source_order(&source, read.scene)
        } else {
            read.scene
        };
        let e = errors(&source, &back);
        // Compressed .ply quantises within each 256-splat chunk's range: 11 bits of position
        // and log scale, 10 bits of each rotation component, 8 bits of colour, opacity and SH
        // over [−4, 4]. Its steps are the chunk ranges over those counts; the cloud's chunks
        // span the whole ball, so these bounds hold for every chunk.
        let steps = steps.unwrap_or(Steps {
            position: 0.5 * 2.0 / 1023.0,
            log_scale: 0.5 * (0.08f32 / 0.015).ln() / 1023.0,
            opacity: 0.5 / 255.0,
            dc: 0.5 / 255.0 / SH_C0 * 1.05,
            sh1: 4.0 / 255.0 + 1e-3,
            sh_rest: 4.0 / 255.0 + 1e-3,
            angle: 0.004,
        });
        within(e, steps).unwrap_or_else(|m| panic!("{name}: {m} ({e:?})"));
        let (error, bound) = image_check(&source, &back, &camera, steps);
        eprintln!("{name}: {:?}, image RMSE {error:.2e}, bound {bound:.2e}; errors {e:?}", read.format);
        assert!(error <= bound, "{name}: image RMSE {error:.3e} > bound {bound:.3e}");
    }
}

/// The spz v4 writer's zstd streams are the reference writer's: the interop source's splats in
/// v4 are byte for byte splat-transform's v4 file of the same splats (libzstd at level 12), and
/// smaller than this writer's v3 (gzip), as v4 is meant to be. ruzstd's encoder, used before,
/// wrote 116,268 bytes against 85,708 (+36 %, larger than v3's 92,984).
#[test]
fn spz_v4_is_the_reference_writers_file() {
    let Some(dir) = interop_dir() else { return };
    let source = splat_io::read_scene(&dir.join("source.ply")).unwrap();
    let theirs = std::fs::read(dir.join("splat-transform-v4.spz")).unwrap();
    let ours = |version| encode_spz(&source, SpzWriteOptions { version, axes: SpzAxes::AsStored }).unwrap();
    let (v3, v4) = (ours(3), ours(4));
    eprintln!("spz v4: {} bytes here, {} by splat-transform; v3 here {}", v4.len(), theirs.len(), v3.len());
    assert!(v4 == theirs, "v4 differs from splat-transform's ({} against {} bytes)", v4.len(), theirs.len());
    assert!(v4.len() < v3.len(), "v4 ({} bytes) is no smaller than v3 ({})", v4.len(), v3.len());
}

/// glTF with `KHR_gaussian_splatting` as splat-transform writes it from the interop source: the
/// reader turns the data from glTF's +Y-up axes (a half turn about z) and takes linear scales
/// and opacities after the sigmoid, and gets the source's splats back to f32 rounding (the
/// reference converts with exp and sigmoid in f64; measured: every attribute equal, the
/// rotations within the 2e-3 rad that f32's acos resolves near 1). The writer's file holds the reference's attributes, accessor for accessor, the
/// same values to f32 rounding. Controls: the reference's raw positions are the source's with x
/// and y negated (so a reader that skipped the turn would fail), and its scales are not logs.
#[test]
fn gltf_splats_read_and_write_as_splat_transform_does() {
    let Some(dir) = interop_dir() else { return };
    let source = splat_io::read_scene(&dir.join("source.ply")).unwrap();
    let read = splat_io::read_scene_with(&dir.join("splat-transform.glb"), Default::default()).unwrap();
    assert_eq!(read.format, splat_io::SceneFormat::Gltf);
    let e = errors(&source, &read.scene);
    eprintln!("splat-transform.glb against the source: {e:?}");
    let f32_rounding =
        Steps { position: 1e-6, log_scale: 1e-6, opacity: 1e-6, dc: 0.0, sh1: 1e-6, sh_rest: 1e-6, angle: 2e-3 };
    within(e, f32_rounding).unwrap_or_else(|m| panic!("splat-transform.glb: {m} ({e:?})"));
    // Both files' attributes, accessor by accessor, as f32 (or bytes for COLOR_0).
    let attributes = |bytes: &[u8]| -> std::collections::BTreeMap<String, (String, u64, Vec<f64>)> {
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        let bin = &bytes[20 + json_len + 8..];
        let primitive = &doc["meshes"][0]["primitives"][0];
        assert_eq!(primitive["extensions"]["KHR_gaussian_splatting"]["kernel"], "ellipse");
        primitive["attributes"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(name, index)| {
                let a = &doc["accessors"][index.as_u64().unwrap() as usize];
                let view = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
                let start = view["byteOffset"].as_u64().unwrap_or(0) as usize;
                let data = &bin[start..start + view["byteLength"].as_u64().unwrap() as usize];
                let component = a["componentType"].as_u64().unwrap();
                let values = match component {
                    5126 => data.chunks(4).map(|c| f64::from(f32::from_le_bytes(c.try_into().unwrap()))).collect(),
                    _ => data.iter().map(|&b| f64::from(b)).collect(),
                };
                (name.clone(), (a["type"].as_str().unwrap().to_string(), component, values))
            })
            .collect()
    };
    let theirs = attributes(&std::fs::read(dir.join("splat-transform.glb")).unwrap());
    let ours = attributes(
        &splat_io::gltf_splats::encode_gltf_splats(&source, splat_io::gltf_splats::GltfContainer::Glb).unwrap(),
    );
    assert_eq!(
        ours.keys().collect::<Vec<_>>(),
        theirs.keys().collect::<Vec<_>>(),
        "the attributes differ from the reference's"
    );
    for (name, (kind, component, values)) in &ours {
        let (their_kind, their_component, their_values) = &theirs[name];
        assert_eq!((kind, component), (their_kind, their_component), "{name}");
        assert_eq!(values.len(), their_values.len(), "{name}");
        // A quaternion and its negative are one rotation: compare up to the sign of each.
        let worst = values
            .chunks(if name.ends_with("ROTATION") { 4 } else { 1 })
            .zip(their_values.chunks(if name.ends_with("ROTATION") { 4 } else { 1 }))
            .map(|(a, b)| {
                let d = |s: f64| a.iter().zip(b).map(|(x, y)| (x - s * y).abs()).fold(0.0, f64::max);
                d(1.0).min(d(-1.0))
            })
            .fold(0.0, f64::max);
        // COLOR_0 is 8-bit: a value at a rounding boundary may round either way.
        let bound = if name == "COLOR_0" { 1.0 } else { 2e-6 };
        eprintln!("{name}: largest difference from the reference {worst:.2e}");
        assert!(worst <= bound, "{name}: {worst} from the reference's values");
    }
    // Controls: the reference stores turned positions and linear scales.
    let raw = &theirs["POSITION"].2;
    let p0 = source.particles[0].mean;
    assert!((raw[0] + f64::from(p0.x)).abs() < 1e-6 && (raw[1] + f64::from(p0.y)).abs() < 1e-6, "not turned");
    assert!((raw[2] - f64::from(p0.z)).abs() < 1e-6);
    assert!(p0.x.abs() > 1e-3 && p0.y.abs() > 1e-3, "the control needs a splat off the z axis");
    let scale = &theirs["KHR_gaussian_splatting:SCALE"].2;
    assert!((scale[0] - f64::from(source.particles[0].scale.x)).abs() < 1e-6, "scales are not linear");
}

/// One `.glb` holds a world's splats and its meshes: the splat reader takes the
/// `KHR_gaussian_splatting` primitive, the mesh reader the triangles beside it, and a world
/// opened from the file has both.
#[test]
fn a_gltf_file_holds_splats_and_meshes_together() {
    let (scene, _) = cloud();
    let small = Scene::new(scene.particles[..30].to_vec(), 3);
    let gltf =
        splat_io::gltf_splats::encode_gltf_splats(&small, splat_io::gltf_splats::GltfContainer::Embedded).unwrap();
    let mut doc: serde_json::Value = serde_json::from_slice(&gltf).unwrap();
    // A floor quad (two triangles) in a second buffer, a file beside the .gltf, placed by a
    // second node.
    let corners: [f32; 12] = [-2.0, -1.0, -2.0, 2.0, -1.0, -2.0, 2.0, -1.0, 2.0, -2.0, -1.0, 2.0];
    let indices: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let mut bytes: Vec<u8> = corners.iter().flat_map(|f| f.to_le_bytes()).collect();
    bytes.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    let folder = scratch_dir("gltf-world");
    std::fs::write(folder.join("floor.bin"), &bytes).unwrap();
    doc["buffers"].as_array_mut().unwrap().push(serde_json::json!({ "byteLength": bytes.len(), "uri": "floor.bin" }));
    let views = doc["bufferViews"].as_array().unwrap().len();
    let accessors = doc["accessors"].as_array().unwrap().len();
    doc["bufferViews"].as_array_mut().unwrap().extend([
        serde_json::json!({ "buffer": 1, "byteOffset": 0, "byteLength": 48 }),
        serde_json::json!({ "buffer": 1, "byteOffset": 48, "byteLength": 12 }),
    ]);
    doc["accessors"].as_array_mut().unwrap().extend([
        serde_json::json!({ "bufferView": views, "componentType": 5126, "count": 4, "type": "VEC3",
                            "min": [-2.0, -1.0, -2.0], "max": [2.0, -1.0, 2.0] }),
        serde_json::json!({ "bufferView": views + 1, "componentType": 5123, "count": 6, "type": "SCALAR" }),
    ]);
    doc["meshes"].as_array_mut().unwrap().push(serde_json::json!({
        "primitives": [{ "attributes": { "POSITION": accessors }, "indices": accessors + 1 }]
    }));
    doc["nodes"].as_array_mut().unwrap().push(serde_json::json!({ "mesh": 1 }));
    doc["scenes"][0]["nodes"] = serde_json::json!([0, 1]);
    let path = folder.join("world.gltf");
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    let opened = splat_io::world::open_world(Some(&path), Default::default()).unwrap();
    assert_eq!(opened.world.scene.particles.len(), 30);
    assert_eq!(opened.world.scene.sh_degree, 3);
    assert_eq!(opened.world.meshes.len(), 1);
    assert_eq!(opened.world.meshes[0].0.triangles.len(), 2);
    let mesh = splat_io::mesh::read_mesh(&path).unwrap();
    assert_eq!(mesh.triangle_count(), 2, "the mesh reader skips the splats and keeps the floor");
    // Without the floor the file is splats only; the mesh reader then finds no triangles.
    let splats_only = folder.join("splats.gltf");
    std::fs::write(&splats_only, &gltf).unwrap();
    assert!(splat_io::world::open_world(Some(&splats_only), Default::default()).unwrap().world.meshes.is_empty());
    let e = splat_io::mesh::read_mesh(&splats_only).unwrap_err().to_string();
    assert!(e.contains("no triangles"), "{e}");
}

/// three.js's GLTFExporter writes seven quads, a material each (xtask/interop/make.mjs, the
/// parameters named again here); each reads as glTF 2.0 §3.9 and its extensions define the
/// material, mapped onto the mesh material's shares as `splat_io::mesh::gltf_material`
/// documents: the masked quad (opacity 0.3, cutoff 0.5) draws nothing, the black blue channel
/// that emits is read as `EMITTING_BLACK`, a metal's mirror tint is its base colour, and the
/// unread `KHR_materials_volume` is noted. A world file's keys override every part's; a colour
/// keeps what a lit part emits and retints a metal.
#[test]
fn gltf_materials_read_as_three_js_writes_them() {
    use splat_core::lighting::Material;
    use splat_core::mesh::MeshMaterial;
    let Some(dir) = interop_dir() else { return };
    let path = dir.join("three-materials.glb");
    let read = splat_io::mesh::read_mesh(&path).unwrap();
    let matte =
        |emissive: Vec3| Material { emissive, ambient: Vec3::splat(0.1), diffuse: Vec3::ONE, ..Material::DIFFUSE };
    let standard = |c: Vec3, metallic: f32, roughness: f32, opacity: f32| MeshMaterial {
        color: c,
        shading: matte(Vec3::ZERO),
        mirror: metallic,
        // glTF's conductor_fresnel: a metal's F₀ is its base colour.
        mirror_tint: if metallic > 0.0 { c } else { Vec3::ONE },
        transmission: 0.0,
        ior: 1.5,
        roughness,
        specular_layer: true,
        opacity,
    };
    let black = splat_io::mesh::EMITTING_BLACK;
    let expected = [
        standard(Vec3::new(0.5, 0.25, 0.125), 0.0, 0.5, 1.0),
        standard(Vec3::new(0.2, 0.4, 0.6), 0.25, 0.3, 0.4),
        // Transmission is the dielectric (1 − metallic) share: 0.5 × 0.8.
        MeshMaterial { transmission: 0.4, ior: 1.33, ..standard(Vec3::ONE, 0.5, 0.1, 1.0) },
        MeshMaterial {
            shading: matte(Vec3::new(0.25 * 4.0 / 0.5, 4.0 / 0.5, 0.5 * 4.0 / black)),
            ..standard(Vec3::new(0.5, 0.5, black), 0.0, 1.0, 1.0)
        },
        MeshMaterial {
            shading: Material::EMISSIVE,
            specular_layer: false,
            ..standard(Vec3::new(0.3, 0.6, 0.9), 0.0, 0.9, 1.0)
        },
        standard(Vec3::splat(0.7), 0.0, 1.0, 0.5),
    ];
    let materials: Vec<MeshMaterial> = read.parts.iter().map(|p| p.material.expect("every quad has one")).collect();
    assert_eq!(materials.len(), expected.len(), "{materials:#?}");
    for (i, (got, want)) in materials.iter().zip(&expected).enumerate() {
        let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() <= 1e-6 * b.abs().max_element().max(1.0);
        let scalars = [
            (got.mirror, want.mirror),
            (got.transmission, want.transmission),
            (got.ior, want.ior),
            (got.roughness, want.roughness),
            (got.opacity, want.opacity),
        ];
        assert!(
            close(got.color, want.color)
                && close(got.mirror_tint, want.mirror_tint)
                && got.specular_layer == want.specular_layer
                && close(got.shading.emissive, want.shading.emissive)
                && close(got.shading.diffuse, want.shading.diffuse)
                && close(got.shading.ambient, want.shading.ambient)
                && scalars.iter().all(|(a, b)| (a - b).abs() <= 1e-6),
            "quad {i}: {got:?}, expected {want:?}"
        );
    }
    // Emission as glTF defines it: k_e ⊙ c = emissiveFactor × emissiveStrength.
    let emitted = materials[3].shading.emissive * materials[3].color;
    assert!((emitted - Vec3::new(1.0, 4.0, 2.0)).abs().max_element() < 1e-5, "{emitted}");
    assert!(read.parts.iter().all(|p| p.mesh.triangles.len() == 2));
    // The blended quad's vertex colours: their alpha is the vertices' opacity, their rgb noted.
    let opacities: Vec<Vec<f32>> = read.parts.iter().map(|p| p.mesh.opacities.clone()).collect();
    assert_eq!(opacities[..5], vec![Vec::<f32>::new(); 5]);
    assert_eq!(opacities[5], [0.2, 0.4, 0.6, 0.8]);
    assert!(read.notes.iter().any(|n| n.contains("COLOR_0")), "{:?}", read.notes);
    assert!(read.notes.iter().any(|n| n.contains("KHR_materials_volume")), "{:?}", read.notes);
    // As a world of its own, and under a world file's keys.
    let opened = splat_io::world::open_world(Some(&path), Default::default()).unwrap();
    assert_eq!(opened.world.meshes.iter().map(|m| m.1).collect::<Vec<_>>(), materials);
    assert_eq!(opened.notes, read.notes);
    let folder = scratch_dir("gltf-materials");
    let world = folder.join("world.toml");
    let entry = format!(
        "[[splats]]\nbuiltin = \"demo\"\n[[meshes]]\nfile = {:?}\ncolor = [0, 1, 0]\nroughness = 0.7\n",
        path.to_str().unwrap()
    );
    std::fs::write(&world, entry).unwrap();
    let spec = splat_io::world::read_world(&world).unwrap();
    assert_eq!(spec.meshes.len(), expected.len());
    for (i, ((_, m), file)) in spec.meshes.iter().zip(&materials).enumerate() {
        if i == 3 {
            // The new colour recolours what the quad reflects; it emits what the file says,
            // its red and blue channels, black in the new colour, read as EMITTING_BLACK.
            let emitted = m.shading.emissive * m.color;
            assert!((emitted - Vec3::new(1.0, 4.0, 2.0)).abs().max_element() < 1e-5, "{emitted}");
            assert_eq!(m.color, Vec3::new(black, 1.0, black));
            assert_eq!(*m, MeshMaterial { color: m.color, shading: m.shading, roughness: 0.7, ..*file });
        } else {
            // The unlit quad's colour is its emission, which the override sets; a metal's tint
            // is its base colour, which the override sets too.
            let mirror_tint = if file.mirror > 0.0 { Vec3::Y } else { file.mirror_tint };
            assert_eq!(*m, MeshMaterial { color: Vec3::Y, roughness: 0.7, mirror_tint, ..*file });
        }
    }
    assert!(spec.notes.iter().all(|n| n.starts_with("meshes[0]: ")) && spec.notes.len() == read.notes.len());
}

/// splat-transform reads Postshot's `antialiased 1` and writes the mode in every format (Brush's
/// `SplatRenderMode: mip`, the spz flag 0x1): each of its files reads as gsplat's antialiased
/// mode, and the `.spz` writer here sets the flag byte as splat-transform does (the plain
/// source, the control, reads as the 3DGS dilation and is written without it).
#[test]
fn the_antialiased_mode_is_read_and_written_as_splat_transform_does() {
    let Some(dir) = interop_dir() else { return };
    let read = |name: &str| splat_io::read_scene(&dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(read("source.ply").screen_filter, ScreenFilter::Dilation);
    for name in [
        "antialiased.ply",
        "splat-transform-antialiased.ply",
        "splat-transform-antialiased.compressed.ply",
        "splat-transform-antialiased-v3.spz",
        "splat-transform-antialiased-v4.spz",
    ] {
        assert_eq!(read(name).screen_filter, ScreenFilter::Antialiased, "{name}");
    }
    let flags = |version: u32, bytes: &[u8]| if version == 4 { bytes[14] } else { gunzip(bytes)[14] };
    let scene = read("antialiased.ply");
    for version in [3, 4] {
        let theirs = std::fs::read(dir.join(format!("splat-transform-antialiased-v{version}.spz"))).unwrap();
        let options = SpzWriteOptions { version, axes: SpzAxes::AsStored };
        assert_eq!(flags(version, &encode_spz(&scene, options).unwrap()), flags(version, &theirs), "v{version}");
        let plain = Scene { screen_filter: ScreenFilter::Dilation, ..scene.clone() };
        assert_eq!(flags(version, &encode_spz(&plain, options).unwrap()), 0, "v{version}");
    }
}

/// `read`'s splats reordered to match `source`'s: each source splat takes the read splat nearest
/// to it (the positions are distinct by far more than the quantisation step).
fn in_source_order(source: &Scene, read: Scene) -> Scene {
    let mut taken = vec![false; read.particles.len()];
    let particles = source
        .particles
        .iter()
        .map(|p| {
            let nearest = (0..read.particles.len())
                .filter(|&i| !taken[i])
                .min_by(|&a, &b| {
                    let d = |i: usize| (read.particles[i].mean - p.mean).length_squared();
                    d(a).total_cmp(&d(b))
                })
                .expect("as many splats read as written");
            taken[nearest] = true;
            read.particles[nearest].clone()
        })
        .collect();
    Scene { particles, ..read }
}

#[test]
fn spz_errors_name_the_problem() {
    let (scene, _) = cloud();
    let v3 = encode_spz(&scene, SpzWriteOptions::default()).unwrap();
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"ply\n".to_vec(), "not an spz file"),
        (v3[..v3.len() / 2].to_vec(), "stream"),
        (gzip(&[0u8; 16]), "bad magic"),
        (
            {
                let mut raw = gunzip(&v3);
                raw[4] = 9;
                gzip(&raw)
            },
            "version 9",
        ),
        (
            {
                let mut raw = gunzip(&v3);
                raw[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
                gzip(&raw)
            },
            "truncated or the header's count",
        ),
        (
            {
                // Degree 4 is read (band 4 dropped), but this file has degree 3's SH bytes.
                let mut raw = gunzip(&v3);
                raw[12] = 4;
                gzip(&raw)
            },
            "the sh stream ends after",
        ),
        (b"NGSP\x04\0\0\0".to_vec(), "shorter than the 32-byte"),
    ];
    for (bytes, expected) in cases {
        let e = parse_spz(&bytes, SpzAxes::AsStored).expect_err(expected).to_string();
        assert!(e.contains(expected), "'{e}' should mention '{expected}'");
    }
    let v4 = encode_spz(&scene, SpzWriteOptions { version: 4, axes: SpzAxes::AsStored }).unwrap();
    let e = parse_spz(&v4[..v4.len() - 10], SpzAxes::AsStored).unwrap_err().to_string();
    assert!(e.contains("runs past the end"), "{e}");
    let particle = Particle::with_rgb(Vec3::splat(1e7), Vec3::ONE, Quat::IDENTITY, 0.5, Vec3::ONE);
    let far = Scene::new(vec![particle], 0);
    assert!(encode_spz(&far, SpzWriteOptions::default()).unwrap_err().to_string().contains("24-bit range"));
}

/// Three views of the cloud with distinct poses and focal lengths, principal point at the
/// centre (what cameras.json can express), in the order of their names.
fn views() -> Vec<(String, Camera)> {
    let eyes = [Vec3::new(0.0, 0.6, 3.4), Vec3::new(2.5, -0.5, 2.0), Vec3::new(-1.0, 2.5, -2.2)];
    eyes.iter()
        .zip([40.0, 55.0, 35.0])
        .enumerate()
        .map(|(i, (&eye, fov))| {
            let camera = Camera::look_at(eye, Vec3::ZERO, Vec3::new(0.0, 1.0, 0.1), fov, 64, 48).unwrap();
            (format!("frame_{i:03}.jpg"), camera)
        })
        .collect()
}

/// COLMAP's binary model written from cameras.json values by the formulas of COLMAP's own
/// documentation (independent of the reader): R = (camera-to-world)ᵀ, t = −R C, q = quat(R).
fn write_colmap_bin(dir: &std::path::Path, entries: &[splat_io::cameras::CameraEntry], order: &[usize]) {
    let mut cameras = Vec::new();
    let mut images = Vec::new();
    cameras.extend((entries.len() as u64).to_le_bytes());
    images.extend((entries.len() as u64).to_le_bytes());
    for &i in order {
        let e = &entries[i];
        let id = i as u32 + 1;
        cameras.extend(id.to_le_bytes());
        cameras.extend(1u32.to_le_bytes()); // PINHOLE
        cameras.extend(u64::from(e.width).to_le_bytes());
        cameras.extend(u64::from(e.height).to_le_bytes());
        for v in [e.fx, e.fy, 0.5 * f64::from(e.width), 0.5 * f64::from(e.height)] {
            cameras.extend(v.to_le_bytes());
        }
        let c2w = glam::DMat3::from_cols_array_2d(&e.rotation).transpose(); // rows as written
        let w2c = c2w.transpose();
        let q = glam::DQuat::from_mat3(&w2c);
        let t = -(w2c * glam::DVec3::from(e.position));
        images.extend(id.to_le_bytes());
        for v in [q.w, q.x, q.y, q.z, t.x, t.y, t.z] {
            images.extend(v.to_le_bytes());
        }
        images.extend(id.to_le_bytes());
        images.extend(e.img_name.as_bytes());
        images.push(0);
        images.extend(2u64.to_le_bytes()); // two 2D points, skipped by the reader
        images.extend([0u8; 48]);
    }
    std::fs::write(dir.join("cameras.bin"), cameras).unwrap();
    std::fs::write(dir.join("images.bin"), images).unwrap();
}

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("splat-formats-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn colmap_models_render_the_views_of_the_equivalent_cameras_json() {
    let (scene, _) = cloud();
    let views = views();
    let dir = scratch_dir("colmap");
    let cameras: Vec<Camera> = views.iter().map(|(_, c)| *c).collect();
    let json = dir.join("cameras.json");
    let entries: Vec<_> = views
        .iter()
        .enumerate()
        .map(|(i, (name, c))| splat_io::cameras::CameraEntry::from_camera(i as i64, name, c))
        .collect();
    std::fs::write(&json, serde_json::to_string(&entries).unwrap()).unwrap();
    let from_json = splat_io::cameras::read_named_cameras(&json).unwrap();
    assert_eq!(from_json.len(), cameras.len());
    // Binary, images listed out of name order; text, from the writer.
    let bin = scratch_dir("colmap-bin");
    write_colmap_bin(&bin, &entries, &[2, 0, 1]);
    let txt = scratch_dir("colmap-txt");
    let named: Vec<_> =
        views.iter().map(|(name, camera)| splat_io::colmap::View { name: name.clone(), camera: *camera }).collect();
    splat_io::colmap::write_colmap_txt(&txt, &named).unwrap();
    for model in [bin.clone(), bin.join("images.bin"), txt.clone(), txt.join("cameras.txt")] {
        let read = splat_io::colmap::read_colmap(&model).unwrap_or_else(|e| panic!("{}: {e}", model.display()));
        for (i, (view, (name, camera))) in read.iter().zip(&from_json).enumerate() {
            assert_eq!(&view.name, name, "{}: views sorted by name", model.display());
            let a = image(&scene, camera);
            let b = image(&scene, &view.camera);
            let max = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            assert!(max < 1e-3, "{} view {i}: images differ by {max}", model.display());
            assert!((view.camera.center() - camera.center()).length() < 1e-5);
        }
    }
    // A hand-made model: identity rotation, t = (0, 0, 5): the centre is (0, 0, −5).
    let hand = scratch_dir("colmap-hand");
    std::fs::write(hand.join("cameras.txt"), "# comment\n7 SIMPLE_PINHOLE 64 48 50 32 24\n").unwrap();
    std::fs::write(hand.join("images.txt"), "# two lines per image\n3 1 0 0 0 0 0 5 7 my image.png\n\n").unwrap();
    let read = splat_io::colmap::read_colmap(&hand).unwrap();
    assert_eq!(read[0].name, "my image.png");
    assert!((read[0].camera.center() - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-6);
    assert_eq!((read[0].camera.fx, read[0].camera.fy, read[0].camera.cx), (50.0, 50.0, 32.0));
    // Errors name the problem.
    std::fs::write(hand.join("cameras.txt"), "7 FOV 64 48 50 50 32 24 0.9\n").unwrap();
    let e = splat_io::colmap::read_colmap(&hand).unwrap_err().to_string();
    assert!(e.contains("FOV is not supported") && e.contains("undistort"), "{e}");
    std::fs::write(hand.join("cameras.txt"), "7 OPENCV 64 48 50 50 32 24 0.1\n").unwrap();
    let e = splat_io::colmap::read_colmap(&hand).unwrap_err().to_string();
    assert!(e.contains("OPENCV takes 8 parameters, not 5"), "{e}");
    let images = std::fs::read(bin.join("images.bin")).unwrap();
    std::fs::write(bin.join("images.bin"), &images[..images.len() - 30]).unwrap();
    let e = splat_io::colmap::read_colmap(&bin).unwrap_err().to_string();
    assert!(e.contains("images.bin") && e.contains("truncated"), "{e}");
}

/// Every prefix (in steps) and many single-byte corruptions of valid files of each new reader
/// give a value or an error, never a panic (the fuzz targets in fuzz/ explore further).
#[test]
fn new_readers_survive_truncation_and_corruption() {
    let (scene, _) = cloud();
    let small = Scene::new(scene.particles[..40].to_vec(), 3);
    let mut files: Vec<(String, Vec<u8>)> = [2, 3, 4]
        .map(|version| {
            let bytes = encode_spz(&small, SpzWriteOptions { version, axes: SpzAxes::AsStored }).unwrap();
            (format!("v{version}.spz"), bytes)
        })
        .to_vec();
    // The raw (uncompressed) version 3 body behind a valid gzip: corruptions reach the decoder.
    let raw = gunzip(&files[1].1);
    let hand = scratch_dir("robust");
    let named: Vec<_> = views().into_iter().map(|(name, camera)| splat_io::colmap::View { name, camera }).collect();
    splat_io::colmap::write_colmap_txt(&hand, &named).unwrap();
    let cameras_txt = std::fs::read(hand.join("cameras.txt")).unwrap();
    let images_txt = std::fs::read(hand.join("images.txt")).unwrap();
    let mut rng = SplitMix64::new(11);
    let mut cases = 0;
    for (name, bytes) in files.drain(..) {
        for end in (0..bytes.len()).step_by(7) {
            let _ = parse_spz(&bytes[..end], SpzAxes::AsStored);
            cases += 1;
        }
        for _ in 0..300 {
            let mut b = bytes.clone();
            let i = (rng.next_f32() * b.len() as f32) as usize % b.len();
            b[i] ^= 1 << (rng.next_f32() * 8.0) as u32;
            let _ = parse_spz(&b, SpzAxes::Rub);
            cases += 1;
        }
        eprintln!("{name}: survived");
    }
    // glTF splats: every prefix (the reader's unit test) and corruptions of the JSON chunk and the
    // binary data of a .glb.
    let glb = splat_io::gltf_splats::encode_gltf_splats(&small, splat_io::gltf_splats::GltfContainer::Glb).unwrap();
    for _ in 0..600 {
        let mut b = glb.clone();
        let i = (rng.next_f32() * b.len() as f32) as usize % b.len();
        b[i] = (rng.next_f32() * 256.0) as u8;
        let _ = splat_io::gltf_splats::parse_gltf_splats(&b, std::path::Path::new("/nonexistent"));
        cases += 1;
    }
    for _ in 0..500 {
        let mut b = raw.clone();
        let i = (rng.next_f32() * 16.0) as usize; // the header
        b[i] = (rng.next_f32() * 256.0) as u8;
        let _ = parse_spz(&gzip(&b), SpzAxes::AsStored);
        cases += 1;
    }
    for end in 0..cameras_txt.len() {
        let _ = splat_io::colmap::parse_colmap(&cameras_txt[..end], &images_txt, false);
        let _ = splat_io::colmap::parse_colmap(&cameras_txt, &images_txt[..end.min(images_txt.len())], false);
        let _ = splat_io::colmap::parse_colmap(&images_txt[..end.min(images_txt.len())], &cameras_txt, true);
        cases += 3;
    }
    if let Some(dir) = interop_dir() {
        let bytes = std::fs::read(dir.join("splat-transform.compressed.ply")).unwrap();
        let options = splat_io::ply::PlyOptions::default();
        for end in (0..bytes.len()).step_by(331) {
            let _ = splat_io::ply::parse_ply(&bytes[..end], options);
            cases += 1;
        }
        for _ in 0..300 {
            let mut b = bytes.clone();
            let i = (rng.next_f32() * 4000.0) as usize % b.len(); // header and chunk bounds
            b[i] = (rng.next_f32() * 256.0) as u8;
            let _ = splat_io::ply::parse_ply(&b, options);
            cases += 1;
        }
    }
    // .ksplat: prefixes and corruptions (headers, bucket records, splats) of GaussianSplats3D's
    // file of three sections.
    if let Some(dir) = interop_dir() {
        let bytes = std::fs::read(dir.join("gaussian-splats-3d-sections.ksplat")).unwrap();
        for end in (0..bytes.len()).step_by(313) {
            let _ = splat_io::ksplat::parse_ksplat(&bytes[..end]);
            cases += 1;
        }
        for _ in 0..400 {
            let mut b = bytes.clone();
            let i = (rng.next_f32() * 12_000.0) as usize % b.len();
            b[i] = (rng.next_f32() * 256.0) as u8;
            let _ = splat_io::ksplat::parse_ksplat(&b);
            cases += 1;
        }
    }
    // USD: prefixes and corruptions of a .usda layer (the lexer, the prim and value parsers).
    let usda = splat_io::usd::encode_usda(&small).into_bytes();
    for end in (0..usda.len()).step_by(53) {
        let _ = splat_io::usd::parse_usda(&usda[..end]);
        cases += 1;
    }
    for _ in 0..400 {
        let mut b = usda.clone();
        let i = (rng.next_f32() * b.len() as f32) as usize % b.len();
        let alphabet = b"()[]{}=,\"'<>@#-.0e:abc \n";
        b[i] = alphabet[(rng.next_f32() * alphabet.len() as f32) as usize % alphabet.len()];
        let _ = splat_io::usd::parse_usda(&b);
        cases += 1;
    }
    // SOG: prefixes of a bundle (the zip container), and corruptions of meta.json and of each
    // image behind it (the WebP decoder and the splats' decode).
    let sog = splat_io::sog::encode_sog(&small).unwrap();
    let bundle = sog_bundle(&small, &scratch_dir("robust-sog"));
    for end in (0..bundle.len()).step_by(97) {
        let _ = splat_io::sog::parse_sog_bundle(&bundle[..end]);
        cases += 1;
    }
    for target in sog.iter().map(|(name, _)| name) {
        for _ in 0..60 {
            let mut files = sog.clone();
            let data = &mut files.iter_mut().find(|(n, _)| n == target).unwrap().1;
            let i = (rng.next_f32() * data.len() as f32) as usize % data.len();
            data[i] = (rng.next_f32() * 256.0) as u8;
            let load = |name: &str| {
                files
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, d)| d.clone())
                    .ok_or(splat_io::ErrorKind::Sog(name.into()))
            };
            let _ = splat_io::sog::parse_sog(&files[0].1, &load);
            cases += 1;
        }
    }
    eprintln!("{cases} damaged inputs read without a panic");
}

/// The bytes of `scene` written by `splat_io::write_scene` as `DIR/small.sog`.
fn sog_bundle(scene: &Scene, dir: &std::path::Path) -> Vec<u8> {
    let path = dir.join("small.sog");
    splat_io::write_scene(&path, scene, Default::default()).unwrap();
    std::fs::read(path).unwrap()
}

/// `scene` written as SOG (a `.sog` bundle, or for `folder` a `meta.json` and its images) and
/// read back, its splats in the scene's order (the writer stores them in Morton order); the
/// `meta.json` and the bytes of every file, for a folder.
fn sog_round_trip(scene: &Scene, folder: bool) -> (Scene, Option<(serde_json::Value, u64)>) {
    let dir = scratch_dir(if folder { "sog-folder" } else { "sog-bundle" });
    let path = dir.join(if folder { "meta.json" } else { "round-trip.sog" });
    splat_io::write_scene(&path, scene, Default::default()).unwrap();
    let read = splat_io::read_scene_with(&path, Default::default()).unwrap();
    let detail = if folder { "version 2, meta.json and images" } else { "version 2, bundled .sog" };
    assert_eq!((read.format, read.detail.as_str()), (splat_io::SceneFormat::Sog, detail));
    let files = folder.then(|| {
        let meta = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        (meta, std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum())
    });
    (in_source_order(scene, read.scene), files)
}

/// The most a value of `values` moves when stored at its nearest entry of the codebook of
/// `attribute` in `meta`: half the largest gap between neighbouring entries, or the distance
/// from the values' extremes to the outermost entries.
fn nearest_entry_bound(meta: &serde_json::Value, attribute: &str, values: impl Iterator<Item = f32> + Clone) -> f32 {
    let book: Vec<f32> =
        meta[attribute]["codebook"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
    let (lo, hi) = values.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let gaps = 0.5 * book.windows(2).map(|w| w[1] - w[0]).fold(0.0, f32::max);
    gaps.max(book[0] - lo).max(hi - book[book.len() - 1])
}

/// SOG's steps for `scene` written with `meta`, half steps for a rounding writer (ours), whole
/// ones for a truncating one (splat-transform's, which stores floats into byte arrays):
/// positions 16 bits of l(p) = sign(p) ln(1 + |p|) between the bounds in `meta` (dp/dl =
/// e^|l|); opacity 8 bits; rotations 8 bits of each smaller component × √2, so the three are
/// off by |δ| ≤ √3 · √½ / 255 (half steps), the derived largest one by at most √3 |δ|, and the
/// rotation angle by at most 4 asin |δ|; scales and DC colours at their nearest codebook entry
/// ([`nearest_entry_bound`]). The SH palette has no step (k-means entries, then a codebook): its
/// error is measured, and the image bounds it.
fn sog_steps(scene: &Scene, meta: &serde_json::Value, truncating: bool) -> Steps {
    let step = if truncating { 1.0 } else { 0.5 };
    let l_max = scene.particles.iter().map(|p| p.mean.abs().max_element().ln_1p()).fold(0.0, f32::max);
    let span = (0..3)
        .map(|a| meta["means"]["maxs"][a].as_f64().unwrap() - meta["means"]["mins"][a].as_f64().unwrap())
        .fold(0.0, f64::max) as f32;
    let log_scales = scene.particles.iter().flat_map(|p| p.scale.to_array().map(f32::ln));
    let dc = scene.particles.iter().flat_map(|p| p.sh[0].to_array());
    Steps {
        position: step * span / 65535.0 * l_max.exp(),
        log_scale: nearest_entry_bound(meta, "scales", log_scales),
        opacity: step / 255.0,
        dc: nearest_entry_bound(meta, "sh0", dc),
        sh1: f32::INFINITY,
        sh_rest: f32::INFINITY,
        angle: 4.0 * (2.0 * step * 3f32.sqrt() * std::f32::consts::FRAC_1_SQRT_2 / 255.0).asin(),
    }
}

/// SOG written here and read back: every attribute within its step (positions, rotations,
/// opacities, scales and colours at their nearest codebook entries), and the image within the
/// bound of spz v3's steps (the SH palette's error shows there); the antialiased mode is kept.
#[test]
fn sog_round_trips_within_its_steps() {
    let (scene, camera) = cloud();
    let (back, files) = sog_round_trip(&scene, true);
    let (meta, bytes) = files.unwrap();
    let steps = sog_steps(&scene, &meta, false);
    let e = errors(&scene, &back);
    within(e, steps).unwrap_or_else(|m| panic!("SOG: {m} ({e:?})"));
    let (error, bound) = image_check(&scene, &back, &camera, spz_steps(3));
    eprintln!("SOG: {bytes} bytes; image RMSE {error:.2e}, spz v3's bound {bound:.2e}; errors {e:?}; steps {steps:?}");
    assert!(error <= bound, "SOG: image RMSE {error:.3e} > bound {bound:.3e}");
    assert_eq!(back.screen_filter, ScreenFilter::Dilation);
    // A bundle holds the same splats as the folder; the antialiased mode is kept.
    let small = Scene { screen_filter: ScreenFilter::Antialiased, ..Scene::new(scene.particles[..200].to_vec(), 3) };
    let (bundled, _) = sog_round_trip(&small, false);
    assert_eq!(bundled.screen_filter, ScreenFilter::Antialiased);
    let (folder, _) = sog_round_trip(&small, true);
    let same = Steps { position: 0.0, log_scale: 0.0, opacity: 0.0, dc: 0.0, sh1: 0.0, sh_rest: 0.0, angle: 1e-3 };
    within(errors(&bundled, &folder), same).unwrap();
}

/// splat-transform's SOG files of the interop source (bundled, and as a folder) read within
/// SOG's steps, and decode to what splat-transform itself decodes them to (its `.ply` of the
/// bundle): the reader is the reference's. Our bundle decodes through splat-transform's reader
/// (run with Node) to what ours reads: the writer is one the reference reads.
#[test]
fn sog_files_read_and_write_as_splat_transform_does() {
    let Some(dir) = interop_dir() else { return };
    let source = splat_io::read_scene(&dir.join("source.ply")).unwrap();
    let (_, camera) = cloud();
    for (name, decoded) in [
        ("splat-transform.sog", "splat-transform-sog-decoded.ply"),
        ("sog/meta.json", "splat-transform-sog-folder-decoded.ply"),
    ] {
        let reference = splat_io::read_scene(&dir.join(decoded)).unwrap();
        let read =
            splat_io::read_scene_with(&dir.join(name), Default::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(read.format, splat_io::SceneFormat::Sog);
        assert_same_splats(name, &read.scene, &reference);
        let back = in_source_order(&source, read.scene);
        // The folder's meta.json: the bundle's has the same bounds (one writer, one source).
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("sog/meta.json")).unwrap()).unwrap();
        let e = errors(&source, &back);
        let (error, bound) = image_check(&source, &back, &camera, spz_steps(3));
        eprintln!("{name} ({}): image RMSE {error:.2e}, bound {bound:.2e}; errors {e:?}", read.detail);
        let steps = Steps { log_scale: f32::INFINITY, dc: f32::INFINITY, ..sog_steps(&source, &meta, true) };
        within(e, steps).unwrap_or_else(|m| panic!("{name}: {m} ({e:?})"));
        assert!(error <= bound, "{name}: image RMSE {error:.3e} > bound {bound:.3e}");
    }
    assert_eq!(
        splat_io::read_scene(&dir.join("splat-transform-antialiased.sog")).unwrap().screen_filter,
        ScreenFilter::Antialiased
    );
    // Ours, decoded by the reference.
    let ours = scratch_dir("sog-ours").join("ours.sog");
    splat_io::write_scene(&ours, &source, Default::default()).unwrap();
    let decoded = ours.with_extension("ply");
    let cli = dir.join("npm/node_modules/@playcanvas/splat-transform/bin/cli.mjs");
    let status = std::process::Command::new("node").arg(&cli).args(["-q", "-w"]).arg(&ours).arg(&decoded).status();
    assert!(status.is_ok_and(|s| s.success()), "splat-transform does not read our .sog");
    let theirs = splat_io::read_scene(&decoded).unwrap();
    assert_same_splats("ours.sog", &splat_io::read_scene(&ours).unwrap(), &theirs);
}

/// Two decodings of the same file hold the same splats, in the same order, up to f32
/// arithmetic (and opacities splat-transform clamps to [1e-6, 1 − 1e-6] on the way to a logit).
fn assert_same_splats(name: &str, ours: &Scene, theirs: &Scene) {
    assert_eq!((ours.particles.len(), ours.sh_degree), (theirs.particles.len(), theirs.sh_degree), "{name}");
    let e = errors(ours, theirs);
    eprintln!("{name}: against the reference's decoding {e:?}");
    let same =
        Steps { position: 1e-6, log_scale: 1e-5, opacity: 1.5e-6, dc: 1e-6, sh1: 1e-6, sh_rest: 1e-6, angle: 1e-3 };
    within(e, same).unwrap_or_else(|m| panic!("{name} decodes unlike splat-transform: {m}"));
}

/// Bad SOG files are refused with the problem named.
#[test]
fn sog_errors_name_the_problem() {
    let (scene, _) = cloud();
    let small = Scene::new(scene.particles[..40].to_vec(), 3);
    let files = splat_io::sog::encode_sog(&small).unwrap();
    let meta: serde_json::Value = serde_json::from_slice(&files[0].1).unwrap();
    let load = |name: &str| {
        files
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, d)| d.clone())
            .ok_or(splat_io::ErrorKind::Sog(format!("no {name}")))
    };
    let with = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut m = meta.clone();
        edit(&mut m);
        splat_io::sog::parse_sog(&serde_json::to_vec(&m).unwrap(), &load).unwrap_err().to_string()
    };
    assert!(with(&|m| m["version"] = 7.into()).contains("version 7 is not supported"));
    assert!(with(&|m| m["count"] = 100_000.into()).contains("texels for 100000 splats"));
    assert!(with(&|m| m["count"] = u64::MAX.into()).contains("more than WebP images can hold"));
    assert!(with(&|m| m["model"] = "2dgs".into()).contains("2DGS"));
    assert!(with(&|m| m["scales"]["codebook"] = serde_json::json!([1.0])).contains("scales.codebook"));
    assert!(with(&|m| m["quats"]["files"] = serde_json::json!(["nowhere.webp"])).contains("no nowhere.webp"));
    let bad_webp = |name: &str| if name == "quats.webp" { Ok(b"RIFF....WEBPVP8L".to_vec()) } else { load(name) };
    assert!(splat_io::sog::parse_sog(&files[0].1, &bad_webp).unwrap_err().to_string().contains("quats.webp"));
    // A folder's meta.json names images beside it, never a path elsewhere.
    let dir = scratch_dir("sog-errors");
    let mut m = meta.clone();
    m["quats"]["files"] = serde_json::json!(["../../etc/passwd"]);
    std::fs::write(dir.join("meta.json"), serde_json::to_vec(&m).unwrap()).unwrap();
    for (name, data) in &files[1..] {
        std::fs::write(dir.join(name), data).unwrap();
    }
    let e = splat_io::read_scene(&dir.join("meta.json")).unwrap_err().to_string();
    assert!(e.contains("not a file name beside meta.json"), "{e}");
    let bundle = sog_bundle(&small, &dir);
    let e = splat_io::sog::parse_sog_bundle(&bundle[..bundle.len() - 5]).unwrap_err().to_string();
    assert!(e.contains("end-of-central-directory"), "{e}");
    let mut damaged = bundle.clone();
    damaged[200] ^= 0x40;
    assert!(splat_io::sog::parse_sog_bundle(&damaged).unwrap_err().to_string().contains("CRC-32"));
}

/// An extension record of the spz library's layout: type, byte length, payload.
fn spz_record(kind: u32, payload: &[u8]) -> Vec<u8> {
    [&kind.to_le_bytes()[..], &(payload.len() as u32).to_le_bytes(), payload].concat()
}

/// `file` (an spz of any version) with extension `records` and the extension flag (0x2): in
/// version 4 between the header and the table of contents, in versions 2–3 after the attribute
/// arrays inside the gzip stream.
fn with_spz_records(file: &[u8], records: &[u8]) -> Vec<u8> {
    if file.starts_with(b"NGSP") {
        let mut out = file[..32].to_vec();
        out[14] |= 0x2;
        let toc = u32::from_le_bytes(out[16..20].try_into().unwrap()) + records.len() as u32;
        out[16..20].copy_from_slice(&toc.to_le_bytes());
        out.extend_from_slice(records);
        out.extend_from_slice(&file[32..]);
        out
    } else {
        let mut raw = gunzip(file);
        raw[14] |= 0x2;
        raw.extend_from_slice(records);
        gzip(&raw)
    }
}

/// spz extension records: the coordinate-system record is honoured (RUB data read as `--spz-axes
/// rub` reads them, RUF's mirror flips y alone), the safe-orbit record and unknown types are
/// skipped with a note, and malformed records are refused by name; a degree-4 file reads with
/// band 4 dropped and said so.
#[test]
fn spz_extension_records_are_honoured_or_skipped_with_a_note() {
    let (scene, _) = cloud();
    let small = Scene::new(scene.particles[..40].to_vec(), 3);
    let system = |value: u32| spz_record(0xADBE_0003, &value.to_le_bytes());
    let orbit = spz_record(0xADBE_0002, &[0.0f32, 1.2, 3.0].map(f32::to_le_bytes).concat());
    let unknown = spz_record(0x1234_5678, &[1, 2, 3, 4, 5]);
    for version in [3, 4] {
        let plain = encode_spz(&small, SpzWriteOptions { version, axes: SpzAxes::AsStored }).unwrap();
        let rub = splat_io::spz::parse_spz_report(&plain, SpzAxes::Rub).unwrap().scene;
        let records = [system(4), orbit.clone(), unknown.clone()].concat();
        let read = splat_io::spz::parse_spz_report(&with_spz_records(&plain, &records), SpzAxes::AsStored).unwrap();
        assert_eq!(read.scene, rub, "v{version}: a RUB record reads as --spz-axes rub");
        let notes = read.notes.join("; ");
        for said in
            ["RUB axes, converted", "safe_orbit_camera (elevation 0–1.2, radius ≥ 3)", "0x12345678 (5 bytes) skipped"]
        {
            assert!(notes.contains(said), "v{version}: {notes}");
        }
        let stored = parse_spz(&plain, SpzAxes::AsStored).unwrap();
        let ruf = parse_spz(&with_spz_records(&plain, &system(8)), SpzAxes::AsStored).unwrap();
        for (a, b) in stored.particles.iter().zip(&ruf.particles) {
            assert_eq!(b.mean, a.mean * Vec3::new(1.0, -1.0, 1.0), "v{version}: RUF flips y");
        }
        let refused = |records: &[u8]| {
            splat_io::spz::parse_spz_report(&with_spz_records(&plain, records), SpzAxes::AsStored)
                .unwrap_err()
                .to_string()
        };
        assert!(refused(&system(9)).contains("LBD"), "v{version}");
        assert!(refused(&system(20)).contains("not one of spz's 0–16"), "v{version}");
        assert!(refused(&[system(4), system(4)].concat()).contains("second or malformed"), "v{version}");
        let mut long = unknown.clone();
        long[4] = 200;
        assert!(refused(&long).contains("runs past"), "v{version}: {}", refused(&long));
    }
    // Degree 4: nine more coefficients a splat (value 128: zero) after each splat's 15.
    let plain = encode_spz(&small, SpzWriteOptions { version: 3, axes: SpzAxes::AsStored }).unwrap();
    let mut raw = gunzip(&plain);
    let sh_at = 16 + small.particles.len() * (9 + 1 + 3 + 3 + 4);
    let sh: Vec<u8> = raw[sh_at..].chunks(45).flat_map(|c| [c, &[128u8; 27][..]].concat()).collect();
    raw.truncate(sh_at);
    raw.extend_from_slice(&sh);
    raw[12] = 4;
    let read = splat_io::spz::parse_spz_report(&gzip(&raw), SpzAxes::AsStored).unwrap();
    assert_eq!(read.scene, parse_spz(&plain, SpzAxes::AsStored).unwrap());
    assert!(read.notes.join("; ").contains("SH band 4 dropped"), "{:?}", read.notes);
}

/// The interop source as `.ksplat` keeps it: SH degree 2 (band 3 dropped).
fn at_degree_2(scene: &Scene) -> Scene {
    let particles = scene
        .particles
        .iter()
        .map(|p| {
            let mut p = p.clone();
            for k in 9..16 {
                p.sh[k] = Vec3::ZERO;
            }
            p
        })
        .collect();
    Scene { particles, sh_degree: 2, ..scene.clone() }
}

/// Bounds of a `.ksplat` file's errors (GaussianSplats3D's `SplatBuffer`, from its encoder):
/// colour and opacity are floored to 8 bits (up to one step, 1/255), positions rounded to a
/// step of (block / 2) / 32767 about their bucket's centre (levels 1–2), scales, rotations and
/// level 1's SH truncated to f16 (three.js's `toHalfFloat` drops the mantissa's low bits: up to
/// an ulp, 2⁻¹⁰ relative; measured 0.99 of it), level 2's SH floored over the
/// header's [min, max] in 255 steps; level 0 stores f32. Rotation angles to the 2e-3 rad that
/// f32's acos resolves near 1.
fn ksplat_steps(source: &Scene, file: &[u8], level: u8, block: f32) -> Steps {
    let sh_max = source
        .particles
        .iter()
        .flat_map(|p| p.sh.as_slice()[1..9].to_vec())
        .fold(0f32, |m, c| m.max(c.abs().max_element()));
    let f32_at = |at: usize| f32::from_le_bytes(file[at..at + 4].try_into().unwrap());
    let (sh_min_file, sh_max_file) = (f32_at(36), f32_at(40));
    let ulp = 2f32.powi(-10);
    let sh = match level {
        0 => 1e-7,
        1 => sh_max * ulp,
        _ => (sh_max_file - sh_min_file) / 255.0,
    };
    let (log_scale, position) =
        if level == 0 { (1e-6, 1e-7) } else { (-(1.0 - ulp).ln(), 0.5 * block / 2.0 / 32767.0) };
    Steps { position, log_scale, opacity: 1.0 / 255.0, dc: 1.0 / 255.0 / SH_C0, sh1: sh, sh_rest: sh, angle: 2e-3 }
}

/// GaussianSplats3D 0.4.7's `.ksplat` files of the interop source (compression levels 0, 1, 2,
/// and level 1 in three sections of partly filled buckets) decode to what splat-transform's
/// reader decodes them to, and to the source (at SH degree 2, reordered: the writer sorts the
/// splats by distance from the centre) within the format's steps, images included. Control: a
/// reader that took the SH components in the `.ply`'s channel-major order over both bands (not
/// band by band) fails the bounds.
#[test]
fn ksplat_files_read_as_gaussian_splats_3d_wrote_them() {
    let Some(dir) = interop_dir() else { return };
    let source = at_degree_2(&splat_io::read_scene(&dir.join("source.ply")).unwrap());
    let (_, camera) = cloud();
    for (name, level, block) in [("0", 0, 5.0), ("1", 1, 5.0), ("2", 2, 5.0), ("sections", 1, 0.5)] {
        let path = dir.join(format!("gaussian-splats-3d-{name}.ksplat"));
        let read = splat_io::read_scene_with(&path, Default::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(read.format, splat_io::SceneFormat::Ksplat);
        let decoded = splat_io::read_scene(&dir.join(format!("gaussian-splats-3d-{name}-decoded.ply"))).unwrap();
        assert_same_splats(name, &read.scene, &decoded);
        let back = in_source_order(&source, read.scene);
        let steps = ksplat_steps(&source, &std::fs::read(&path).unwrap(), level, block);
        let e = errors(&source, &back);
        let (error, bound) = image_check(&source, &back, &camera, steps);
        eprintln!("{name} ({}): image RMSE {error:.2e}, bound {bound:.2e}; errors {e:?}", read.detail);
        within(e, steps).unwrap_or_else(|m| panic!("{name}: {m} ({e:?})"));
        assert!(error <= bound, "{name}: image RMSE {error:.3e} > bound {bound:.3e}");
        // The control: components 0..24 put in the .ply's order (8 coefficients of red, then
        // green, then blue).
        let misread = Scene {
            particles: back
                .particles
                .iter()
                .map(|p| {
                    let mut q = p.clone();
                    let stored: Vec<f32> = (0..24)
                        .map(|k| if k < 9 { p.sh[1 + k % 3][k / 3] } else { p.sh[4 + (k - 9) % 5][(k - 9) / 5] })
                        .collect();
                    for (k, v) in stored.into_iter().enumerate() {
                        q.sh[1 + k % 8][k / 8] = v;
                    }
                    q
                })
                .collect(),
            ..back.clone()
        };
        assert!(within(errors(&source, &misread), steps).is_err(), "{name}: the misread SH layout passes");
    }
}

/// Bad `.ksplat` files (GaussianSplats3D's level 1 file, edited) are refused with the problem
/// named; a scale stored as 0 (f16 underflow) reads as the least f16 with a note.
#[test]
fn ksplat_errors_name_the_problem() {
    let Some(dir) = interop_dir() else { return };
    let file = std::fs::read(dir.join("gaussian-splats-3d-1.ksplat")).unwrap();
    let with = |edit: &dyn Fn(&mut Vec<u8>)| {
        let mut b = file.clone();
        edit(&mut b);
        splat_io::ksplat::parse_ksplat(&b).map(|_| ()).unwrap_err().to_string()
    };
    type Edit<'a> = &'a dyn Fn(&mut Vec<u8>);
    let cases: [(Edit, &str); 8] = [
        (&|b| b.truncate(4000), "shorter than the format's 4096-byte header"),
        (&|b| b[1] = 0, "version 0.0"),
        (&|b| b[20] = 3, "compression level 3"),
        (&|b| b.truncate(b.len() - 10), "the file is truncated"),
        (&|b| b[4096 + 40] = 3, "SH degree 3 is beyond the format's 2"),
        (&|b| b[16] ^= 1, "declares 3001 splats but its sections hold 3000"),
        (&|b| b[4] = 250, "header declares 250 sections"),
        // The first bucket centre's x, after the one partly filled bucket's size.
        (&|b| b[5120 + 4..5120 + 8].copy_from_slice(&f32::NAN.to_le_bytes()), "bucket 0's centre"),
    ];
    for (edit, expected) in cases {
        let e = with(edit);
        assert!(e.contains(expected), "expected '{expected}' in: {e}");
    }
    // Splat 0's scale x (after its 6-byte position) set to f16 0.
    let data = 5120 + 4 + 12 * 12;
    let mut b = file.clone();
    b[data + 6..data + 8].copy_from_slice(&[0, 0]);
    let read = splat_io::ksplat::parse_ksplat(&b).unwrap();
    assert_eq!(read.scene.particles[0].scale.x, 5.960_464_5e-8);
    assert!(read.notes[0].contains("1 scale component(s) stored as 0"), "{:?}", read.notes);
}

/// usd-core's interpreter in `target/interop/usd` (`cargo xtask assets`), and usd.py.
fn usd_python(dir: &std::path::Path) -> Option<(PathBuf, PathBuf)> {
    let python = dir.join("usd/bin/python");
    if !python.exists() {
        splat_tests::skip(
            &splat_tests::current_test(),
            &format!("{} has no usd-core (run `cargo xtask assets`, needs Python's venv)", python.display()),
        );
        return None;
    }
    Some((python, splat_tests::root().join("xtask/interop/usd.py")))
}

/// OpenUSD (usd-core 26.11, the reference implementation) and this reader and writer agree on
/// `ParticleField3DGaussianSplat`:
/// - usd-core's layer of the interop source (laid out as 3dgrut's exporter lays one out) reads
///   to the source's splats (positions and SH bit for bit; scales, opacities and rotations to
///   the f32 rounding of usd.py's exp, sigmoid and normalisation in f64);
/// - its layer with the splats under translate, pivot, rotateXYZ, orient, a mirroring scale,
///   an inverted op and a matrix reads to those splats placed by usd-core's own world matrix
///   (means, covariances L Σ Lᵀ, and the colour along L d against the source's along d): the
///   reader composes xformOps as USD does;
/// - usd-core reads our layer of the source as a `ParticleField3DGaussianSplat` whose every
///   attribute is the scene's, f32 for f32, with `elementSize` 16 and the sRGB colour space.
#[test]
fn usd_layers_read_and_write_as_openusd_does() {
    let Some(dir) = interop_dir() else { return };
    let Some((python, script)) = usd_python(&dir) else { return };
    let source = splat_io::read_scene(&dir.join("source.ply")).unwrap();
    let plain = splat_io::read_scene_with(&dir.join("usd-core.usda"), Default::default()).unwrap();
    assert_eq!(
        (plain.format, plain.detail.as_str()),
        (splat_io::SceneFormat::Usd, "usda layer, 1 prim: /World/Gaussians/gaussians")
    );
    assert_same_splats("usd-core.usda", &plain.scene, &source);
    for (p, q) in plain.scene.particles.iter().zip(&source.particles) {
        assert_eq!((p.mean, p.sh.to_array()), (q.mean, q.sh.to_array()));
    }

    let placed = splat_io::read_scene(&dir.join("usd-core-placed.usda")).unwrap();
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("usd-core-placed.json")).unwrap()).unwrap();
    let rows: Vec<f64> = json["world"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
        .collect();
    // USD's rows (x' = x M) are the columns of the column-vector matrix.
    let world = glam::DMat4::from_cols_array(&rows.try_into().unwrap()).as_mat4();
    let linear = glam::Mat3::from_mat4(world);
    assert!(linear.determinant() < 0.0, "the placed layer mirrors");
    let (mut mean_error, mut covariance, mut colour) = (0f32, 0f32, 0f32);
    for (p, q) in placed.particles.iter().zip(&source.particles) {
        mean_error = mean_error.max((p.mean - world.transform_point3(q.mean)).length());
        let expected = Particle { mean: p.mean, ..q.clone() };
        let l_sigma = linear * expected.covariance() * linear.transpose();
        let diff = (p.covariance() - l_sigma).to_cols_array().iter().fold(0f32, |m, v| m.max(v.abs()));
        covariance = covariance.max(diff / l_sigma.to_cols_array().iter().fold(0f32, |m, v| m.max(v.abs())));
        for d in [Vec3::new(0.3, -0.5, 0.8), Vec3::new(-0.9, 0.1, 0.2)] {
            let d = d.normalize();
            let a = splat_core::sh::eval(q.sh.as_slice(), 3, d);
            let b = splat_core::sh::eval(p.sh.as_slice(), 3, (linear * d).normalize());
            colour = colour.max((a - b).abs().max_element());
        }
    }
    eprintln!(
        "placed by usd-core's world matrix: mean {mean_error:.2e}, covariance {covariance:.2e} (relative), colour {colour:.2e}"
    );
    assert!(mean_error < 1e-5 && covariance < 1e-5 && colour < 1e-4, "{mean_error} {covariance} {colour}");

    let ours = scratch_dir("usd-ours").join("ours.usda");
    splat_io::write_scene(&ours, &source, Default::default()).unwrap();
    let dumped = ours.with_extension("json");
    let status = std::process::Command::new(&python).arg(&script).arg("dump").arg(&ours).arg(&dumped).status();
    assert!(status.is_ok_and(|s| s.success()), "usd-core does not read our layer");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&dumped).unwrap()).unwrap();
    let prims = json["prims"].as_array().unwrap();
    assert_eq!(prims.len(), 1, "{json}");
    let prim = &prims[0];
    assert_eq!(prim["path"], "/World/gaussians");
    assert_eq!(
        (prim["is_a"].as_bool(), prim["degree"].as_u64(), prim["element_size"].as_u64()),
        (Some(true), Some(3), Some(16))
    );
    assert_eq!(prim["color_space"], "srgb_rec709_display");
    let floats = |name: &str| -> Vec<f32> {
        prim[name].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect()
    };
    let expect = |name: &str, each: &dyn Fn(&Particle) -> Vec<f32>| {
        let ours: Vec<f32> = source.particles.iter().flat_map(each).collect();
        assert!(floats(name) == ours, "usd-core reads our {name} otherwise");
    };
    expect("positions", &|p| p.mean.to_array().to_vec());
    expect("orientations", &|p| vec![p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z]);
    expect("scales", &|p| p.scale.to_array().to_vec());
    expect("opacities", &|p| vec![p.opacity]);
    expect("coefficients", &|p| p.sh.to_array().iter().flat_map(|c| c.to_array()).collect());
}
