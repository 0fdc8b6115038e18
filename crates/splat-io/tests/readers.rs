//! Round trips and every malformed-input error of the readers.

use approx::assert_relative_eq;
use glam::{Quat, Vec3};
use proptest::prelude::*;
use splat_core::{Particle, Scene, ScreenFilter, scenes};
use splat_io::ErrorKind;
use splat_io::cameras::{parse_cameras, write_cameras};
use splat_io::ply::{PlyFormat, PlyOptions, encode_ply, parse_ply};
use splat_io::splat::{encode_splat, parse_splat};

fn assert_same_scene(a: &Scene, b: &Scene, eps: f32) {
    assert_eq!(a.sh_degree, b.sh_degree);
    assert_eq!(a.particles.len(), b.particles.len());
    for (p, q) in a.particles.iter().zip(&b.particles) {
        assert!(p.mean.abs_diff_eq(q.mean, eps), "{} vs {}", p.mean, q.mean);
        assert!(p.scale.abs_diff_eq(q.scale, eps * p.scale.max_element()));
        assert!(p.rotation.dot(q.rotation).abs() > 1.0 - eps);
        assert_relative_eq!(p.opacity, q.opacity, epsilon = eps.max(1e-6));
        for (c, d) in p.sh.to_array().iter().zip(&q.sh.to_array()) {
            assert!(c.abs_diff_eq(*d, eps), "{c} vs {d}");
        }
    }
}

#[test]
fn ply_round_trips_in_every_encoding() {
    let (scene, _) = scenes::cloud();
    for format in [PlyFormat::BinaryLittleEndian, PlyFormat::BinaryBigEndian, PlyFormat::Ascii] {
        let back = parse_ply(&encode_ply(&scene, format), PlyOptions::default()).unwrap();
        assert_same_scene(&scene, &back, 1e-5);
    }
}

#[test]
fn splat_round_trips_within_quantisation() {
    let (scene, _) = scenes::layers();
    let back = parse_splat(&encode_splat(&scene)).unwrap();
    assert_eq!(back.particles.len(), scene.particles.len());
    for (p, q) in scene.particles.iter().zip(&back.particles) {
        assert_eq!(p.mean, q.mean);
        assert_eq!(p.scale, q.scale);
        assert!(p.rotation.dot(q.rotation).abs() > 0.999);
        assert!((p.opacity - q.opacity).abs() <= 0.5 / 255.0 + 1e-6);
        let rgb = |p: &Particle| splat_core::sh::eval(p.sh.as_slice(), 0, Vec3::Z);
        assert!(rgb(p).abs_diff_eq(rgb(q), 0.5 / 255.0 + 1e-5));
    }
}

#[test]
fn cameras_round_trip_and_follow_the_inria_convention() {
    let (_, camera) = scenes::layers();
    let dir = std::env::temp_dir().join(format!("splat-io-cam-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cameras.json");
    write_cameras(&path, &[camera]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let back = parse_cameras(text.as_bytes()).unwrap();
    assert_relative_eq!(back[0].center().x, camera.center().x, epsilon = 1e-5);
    assert!(back[0].forward().abs_diff_eq(camera.forward(), 1e-6));
    // The INRIA entry stores the centre and the camera-to-world rotation: its third row's
    // transposed column, i.e. rotation[k][2], is the forward axis.
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let fwd = (0..3).map(|k| json[0]["rotation"][k][2].as_f64().unwrap() as f32).collect::<Vec<_>>();
    assert!(Vec3::from_slice(&fwd).abs_diff_eq(camera.forward(), 1e-6));
}

#[test]
fn hand_written_inria_camera() {
    // Identity rotation at (1, 2, 3): looks along +z with y down.
    let json = br#"[{"id": 0, "img_name": "a", "width": 100, "height": 50,
        "position": [1, 2, 3], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fy": 80, "fx": 90}]"#;
    let cam = &parse_cameras(json).unwrap()[0];
    assert_eq!((cam.cx, cam.cy), (50.0, 25.0));
    assert!(cam.center().abs_diff_eq(Vec3::new(1.0, 2.0, 3.0), 1e-6));
    let ray = cam.pixel_ray(49, 24);
    assert!(ray.dir.abs_diff_eq(Vec3::Z, 1e-2));
}

fn header(props: &[&str], count: usize, format: &str) -> String {
    let mut h = format!("ply\nformat {format} 1.0\nelement vertex {count}\n");
    for p in props {
        h += &format!("property float {p}\n");
    }
    h + "end_header\n"
}

const PROPS: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2",
    "rot_3",
];

fn ascii(values: &[&str]) -> Vec<u8> {
    (header(&PROPS, 1, "ascii") + &values.join(" ") + "\n").into_bytes()
}

const GOOD: [&str; 14] = ["0", "0", "0", "0", "0", "0", "0", "-1", "-1", "-1", "1", "0", "0", "0"];

fn with(i: usize, v: &'static str) -> Vec<u8> {
    let mut values = GOOD;
    values[i] = v;
    ascii(&values)
}

fn err(bytes: &[u8]) -> ErrorKind {
    parse_ply(bytes, PlyOptions::default()).expect_err("must be refused")
}

#[test]
fn minimal_ascii_ply_applies_the_activations() {
    let scene = parse_ply(&ascii(&GOOD), PlyOptions::default()).unwrap();
    let p = &scene.particles[0];
    assert_relative_eq!(p.opacity, 0.5);
    assert_relative_eq!(p.scale.x, (-1.0f32).exp());
    assert_eq!(p.rotation, Quat::IDENTITY);
}

/// Mip-Splatting's `filter_3D` (σ_f) is its 3D smoothing filter: the Gaussian Mip-Splatting
/// renders has covariance Σ + σ_f² I and opacity α √(det Σ / det(Σ + σ_f² I)). The reference
/// here is that matrix formula (rotation matrix, determinants), not the reader's per-axis form.
/// Control: the same file read without the filter (the property renamed, so skipped) is off by
/// far more than the tolerance.
#[test]
fn mip_splatting_filter_3d_is_applied_as_its_trainer_renders_it() {
    let props: Vec<&str> = PROPS.iter().copied().chain(["filter_3D"]).collect();
    // Anisotropic and rotated, so that every entry of Σ and its determinant matter.
    let (log_scale, logit, q, sigma) = ([-2.0f64, -3.5, -1.2], 0.4f64, [0.8f64, 0.3, -0.4, 0.33], 0.05f64);
    let values = [
        0.1,
        -0.2,
        0.3,
        0.5,
        0.1,
        -0.3,
        logit,
        log_scale[0],
        log_scale[1],
        log_scale[2],
        q[0],
        q[1],
        q[2],
        q[3],
        sigma,
    ];
    let body: Vec<String> = values.iter().map(|v| format!("{v}")).collect();
    let file = header(&props, 1, "ascii") + &body.join(" ") + "\n";
    let read = splat_io::ply::parse_ply_report(file.as_bytes(), PlyOptions::default()).unwrap();
    assert!(read.filter_3d && read.skipped.is_empty());

    let n = (q.iter().map(|c| c * c).sum::<f64>()).sqrt();
    let r = glam::DMat3::from_quat(glam::DQuat::from_xyzw(q[1] / n, q[2] / n, q[3] / n, q[0] / n));
    let s2 = glam::DMat3::from_diagonal(glam::DVec3::from(log_scale.map(|l| (2.0 * l).exp())));
    let sigma_3d = r * s2 * r.transpose();
    let filtered = sigma_3d + glam::DMat3::from_diagonal(glam::DVec3::splat(sigma * sigma));
    let alpha = 1.0 / (1.0 + (-logit).exp()) * (sigma_3d.determinant() / filtered.determinant()).sqrt();
    let close = |p: &Particle| {
        let c = p.covariance().as_dmat3();
        let worst = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| (c.col(i)[j] - filtered.col(i)[j]).abs())
            .fold(0.0, f64::max);
        (worst / filtered.col(0).max_element(), (f64::from(p.opacity) - alpha).abs() / alpha)
    };
    let (cov, opacity) = close(&read.scene.particles[0]);
    assert!(cov < 1e-5 && opacity < 1e-5, "covariance off by {cov:.2e}, opacity by {opacity:.2e} (relative)");

    let classic = file.replace("filter_3D", "filter_off");
    let lenient = PlyOptions { allow_unknown_properties: true };
    let (cov, opacity) = close(&parse_ply(classic.as_bytes(), lenient).unwrap().particles[0]);
    assert!(cov > 1e-2 && opacity > 1e-2, "the control must be far off: {cov:.2e}, {opacity:.2e}");
}

#[test]
fn unnormalised_quaternion_is_normalised() {
    let scene = parse_ply(&with(10, "3"), PlyOptions::default()).unwrap();
    assert_eq!(scene.particles[0].rotation, Quat::IDENTITY);
    let mut values = GOOD;
    values[10] = "0";
    values[12] = "-7";
    let q = parse_ply(&ascii(&values), PlyOptions::default()).unwrap().particles[0].rotation;
    assert_relative_eq!(q.length(), 1.0);
    assert_relative_eq!(q.y, -1.0);
}

#[test]
fn malformed_ply_errors_name_the_problem() {
    let mut zero_q = GOOD;
    zero_q[10] = "0";
    assert!(matches!(err(&ascii(&zero_q)), ErrorKind::ZeroQuaternion { index: 0 }));
    assert!(matches!(err(&with(1, "nan")), ErrorKind::NonFinite { index: 0, ref property, .. } if property == "y"));
    assert!(matches!(err(&with(7, "inf")), ErrorKind::NonFinite { .. }));
    assert!(matches!(err(&with(8, "-1000")), ErrorKind::BadScale { index: 0, .. }));
    assert!(matches!(err(&with(9, "1000")), ErrorKind::BadScale { index: 0, .. }));
    assert!(matches!(err(&with(3, "abc")), ErrorKind::Parse { index: 0, ref property, .. } if property == "f_dc_0"));
    // Missing and unknown properties.
    let missing = header(&PROPS[..13], 0, "ascii");
    assert!(matches!(err(missing.as_bytes()), ErrorKind::MissingProperty(ref p) if p == "rot_3"));
    let mut props = PROPS.to_vec();
    props.push("semantic_id");
    let unknown = header(&props, 0, "ascii");
    assert!(matches!(err(unknown.as_bytes()), ErrorKind::UnknownProperty { ref name, .. } if name == "semantic_id"));
    let lenient = PlyOptions { allow_unknown_properties: true };
    assert!(parse_ply(unknown.as_bytes(), lenient).is_ok());
    // Wrong f_rest count.
    let mut props = PROPS.to_vec();
    props.push("f_rest_0");
    assert!(matches!(err(header(&props, 0, "ascii").as_bytes()), ErrorKind::Header { .. }));
    // Not a PLY, big header garbage, missing end_header.
    assert!(matches!(err(b"PK\x03\x04"), ErrorKind::Header { line: 1, .. }));
    assert!(matches!(err(b"ply\nformat ascii 1.0\n"), ErrorKind::Header { .. }));
    // ASCII: too few values, missing vertex.
    assert!(matches!(err(&ascii(&GOOD[..13])), ErrorKind::ValueCount { index: 0, found: 13, expected: 14, .. }));
    let short = header(&PROPS, 2, "ascii") + &GOOD.join(" ") + "\n";
    assert!(matches!(err(short.as_bytes()), ErrorKind::Truncated { index: 1, count: 2, .. }));
}

#[test]
fn truncated_and_absurd_binary_counts_are_refused_before_allocating() {
    let (scene, _) = scenes::layers();
    let bytes = encode_ply(&scene, PlyFormat::BinaryLittleEndian);
    let cut = &bytes[..bytes.len() - 5];
    match err(cut) {
        ErrorKind::CountTooLarge { count: 4, first_incomplete: 3, .. } => {}
        other => panic!("unexpected {other:?}"),
    }
    let text = String::from_utf8_lossy(&bytes).replacen("element vertex 4", "element vertex 18446744073709551615", 1);
    let absurd = [text.as_bytes()].concat();
    let e = err(&absurd);
    assert!(matches!(e, ErrorKind::CountTooLarge { count: u64::MAX, .. }), "{e:?}");
    assert!(e.to_string().contains("truncated"), "{e}");
    // ASCII with an absurd count: refused as truncated, without allocating the count.
    let ascii = header(&PROPS, usize::MAX, "ascii") + &GOOD.join(" ") + "\n";
    assert!(matches!(err(ascii.as_bytes()), ErrorKind::Truncated { index: 1, .. }));
}

#[test]
fn malformed_splat_errors_name_the_problem() {
    let (scene, _) = scenes::layers();
    let good = encode_splat(&scene);
    assert!(matches!(
        parse_splat(&good[..40]).unwrap_err(),
        ErrorKind::SplatLength { index: 1, offset: 32, remainder: 8, .. }
    ));
    let mut zero_q = good.clone();
    zero_q[32 + 28..64].fill(128);
    assert!(matches!(parse_splat(&zero_q).unwrap_err(), ErrorKind::ZeroQuaternion { index: 1 }));
    let mut nan = good.clone();
    nan[64..68].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(parse_splat(&nan).unwrap_err(), ErrorKind::NonFinite { index: 2, .. }));
    let mut neg = good.clone();
    neg[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
    assert!(matches!(parse_splat(&neg).unwrap_err(), ErrorKind::BadScale { index: 0, .. }));
    assert_eq!(parse_splat(&[]).unwrap().particles.len(), 0);
}

#[test]
fn malformed_cameras_are_refused() {
    assert!(matches!(parse_cameras(b"[]").unwrap_err(), ErrorKind::Camera { .. }));
    assert!(matches!(parse_cameras(b"{").unwrap_err(), ErrorKind::Json(_)));
    let bad_rot = br#"[{"width": 10, "height": 10, "position": [0,0,0], "rotation": [[2,0,0],[0,1,0],[0,0,1]], "fx": 5, "fy": 5}]"#;
    assert!(matches!(parse_cameras(bad_rot).unwrap_err(), ErrorKind::Camera { index: 0, .. }));
    let zero_f = br#"[{"width": 10, "height": 10, "position": [0,0,0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 0, "fy": 5}]"#;
    assert!(matches!(parse_cameras(zero_f).unwrap_err(), ErrorKind::Camera { index: 0, .. }));
    // Nerfstudio's `ns-export cameras` list is named, with the way to the same views.
    let dir = std::env::temp_dir().join(format!("splat-exported-poses-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exported = dir.join("transforms_train.json");
    std::fs::write(
        &exported,
        r#"[{"file_path": "images/a.png", "transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]}]"#,
    )
    .unwrap();
    let message = splat_io::cameras::read_views(&exported).unwrap_err().to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        message.contains("`ns-export cameras` output") && message.contains("with the run's dataparser_transforms.json"),
        "{message}"
    );
}

#[test]
fn errors_name_the_file() {
    let path = std::path::Path::new("/nonexistent/dir/scene.ply");
    let e = splat_io::read_scene(path).unwrap_err();
    assert!(e.to_string().starts_with("/nonexistent/dir/scene.ply: "), "{e}");
    assert!(splat_io::read_scene("x.obj".as_ref()).unwrap_err().to_string().contains(
        ".ply, .splat, .spz, .glb, .gltf, .sog, meta.json, .ksplat, .usda, .usd, .pt (a gsplat or 3DGRUT checkpoint), \
         .pth (a 3DGS checkpoint) or .ckpt (a Nerfstudio splatfacto checkpoint)"
    ));
}

fn particle() -> impl Strategy<Value = Particle> {
    (
        prop::array::uniform3(-100.0f32..100.0),
        prop::array::uniform3(-8.0f32..2.0),
        prop::array::uniform4(-1.0f32..1.0),
        0.001f32..0.999,
        prop::array::uniform32(-2.0f32..2.0),
    )
        .prop_filter_map("zero quaternion", |(m, s, q, o, sh)| {
            let q = Quat::from_array(q);
            (q.length() > 1e-3).then(|| {
                let mut coeffs = [Vec3::ZERO; 16];
                for (k, c) in coeffs.iter_mut().enumerate().take(10) {
                    *c = Vec3::new(sh[3 * k % 32], sh[(3 * k + 1) % 32], sh[(3 * k + 2) % 32]);
                }
                Particle::new(Vec3::from(m), Vec3::from(s.map(f32::exp)), q, o, coeffs).unwrap()
            })
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    /// Any valid scene survives write → read in every PLY encoding (SH degree 2 here: the
    /// coefficients past degree 2 are zeroed by the writer's degree).
    #[test]
    fn ply_round_trip_property(ps in prop::collection::vec(particle(), 0..20)) {
        let mut scene = Scene::new(ps, 2);
        for p in &mut scene.particles {
            p.sh.truncate(9);
        }
        for format in [PlyFormat::BinaryLittleEndian, PlyFormat::Ascii] {
            let back = parse_ply(&encode_ply(&scene, format), PlyOptions::default()).unwrap();
            assert_same_scene(&scene, &back, 1e-4);
        }
    }
}

/// The minimal ASCII file with `comments` in its header.
fn commented(comments: &[&str]) -> Vec<u8> {
    let file = String::from_utf8(ascii(&GOOD)).unwrap();
    let lines: String = comments.iter().map(|c| format!("comment {c}\n")).collect();
    file.replacen("element vertex", &format!("{lines}element vertex"), 1).into_bytes()
}

fn filter_of(bytes: &[u8]) -> ScreenFilter {
    parse_ply(bytes, PlyOptions::default()).unwrap().screen_filter
}

/// The render-mode comments in the wild, read as splat-transform reads them: Brush's and
/// gsplat's `SplatRenderMode` in any case and spacing (`mip` is gsplat's antialiased mode, an
/// unknown mode the default), Postshot's `antialiased 0|1`, the last one deciding; none at all
/// is the 3DGS dilation; Mip-Splatting's `filter_3D` outranks any comment.
#[test]
fn the_render_mode_comments_of_every_trainer_are_read() {
    let (dilation, antialiased) = (ScreenFilter::Dilation, ScreenFilter::Antialiased);
    for (comments, expected) in [
        (&[][..], dilation),
        (&["Exported from Brush", "SH degree: 0"][..], dilation),
        (&["SplatRenderMode: mip"][..], antialiased),
        (&["  SPLATRENDERMODE:  MIP  "][..], antialiased),
        (&["SplatRenderMode: default"][..], dilation),
        (&["SplatRenderMode: banana"][..], dilation),
        (&["antialiased 1"][..], antialiased),
        (&["antialiased 0"][..], dilation),
        (&["antialiased 1", "SplatRenderMode: default"][..], dilation),
        (&["SplatRenderMode: default", "antialiased 1"][..], antialiased),
    ] {
        assert_eq!(filter_of(&commented(comments)), expected, "{comments:?}");
    }
    let mip = String::from_utf8(commented(&["SplatRenderMode: mip"])).unwrap();
    let mip = mip.replace("property float rot_3\n", "property float rot_3\nproperty float filter_3D\n");
    let mip = mip.replace("1 0 0 0\n", "1 0 0 0 0.01\n");
    assert_eq!(filter_of(mip.as_bytes()), ScreenFilter::Mip, "filter_3D makes a Mip-Splatting capture");
}

/// A 2DGS capture, whether its properties (two scales) or its comment say so, is read as
/// surfels: the third scale is the surfel thickness × the larger one, whatever a stored
/// `scale_2` says; a 3DGS file keeps its third scale.
#[test]
fn a_2dgs_capture_is_read_as_surfels() {
    use splat_core::particle::SURFEL_THICKNESS;
    let thin = |scene: &Scene| scene.particles[0].scale.z / scene.particles[0].scale.x.max(scene.particles[0].scale.y);
    let props: Vec<&str> = PROPS.iter().copied().filter(|&p| p != "scale_2").collect();
    let values: Vec<&str> = GOOD.iter().enumerate().filter(|&(i, _)| i != 9).map(|(_, v)| *v).collect();
    let two_scales =
        parse_ply((header(&props, 1, "ascii") + &values.join(" ") + "\n").as_bytes(), PlyOptions::default());
    let tagged = parse_ply(&commented(&["SplatRenderMode: 2dgs"]), PlyOptions::default());
    for scene in [two_scales.unwrap(), tagged.unwrap()] {
        assert!((thin(&scene) - SURFEL_THICKNESS).abs() < 1e-9, "{:?}", scene.particles[0].scale);
        assert_relative_eq!(scene.particles[0].scale.x, (-1.0f32).exp());
    }
    assert_relative_eq!(thin(&parse_ply(&ascii(&GOOD), PlyOptions::default()).unwrap()), 1.0);
}

/// A 2DGS scene is written back as 2DGS writes it (two scales, `SplatRenderMode: 2dgs`) and
/// reads back as the same surfels; one 3DGS particle among them makes the scene 3DGS again.
#[test]
fn surfels_round_trip_as_2dgs() {
    let props: Vec<&str> = PROPS.iter().copied().filter(|&p| p != "scale_2").collect();
    let values: Vec<&str> = GOOD.iter().enumerate().filter(|&(i, _)| i != 9).map(|(_, v)| *v).collect();
    let line = values.join(" ") + "\n";
    let file = header(&props, 2, "ascii") + &line + &line.replace("-1 -1 1", "-2 -1 1");
    let scene = parse_ply(file.as_bytes(), PlyOptions::default()).unwrap();
    assert!(scene.is_surfels());
    let bytes = encode_ply(&scene, PlyFormat::BinaryLittleEndian);
    let text =
        String::from_utf8_lossy(&bytes[..bytes.windows(10).position(|w| w == b"end_header").unwrap()]).into_owned();
    assert!(text.contains("comment SplatRenderMode: 2dgs") && !text.contains("scale_2"), "{text}");
    let back = parse_ply(&bytes, PlyOptions::default()).unwrap();
    assert!(back.is_surfels());
    assert_same_scene(&scene, &back, 1e-6);
    let mut mixed = scene.clone();
    mixed.particles[1].scale.z = mixed.particles[1].scale.x;
    let text = String::from_utf8(encode_ply(&mixed, PlyFormat::Ascii)).unwrap();
    assert!(text.contains("scale_2") && !text.contains("2dgs"));
}

/// Every filter survives the `.ply` writer and reader, with the particles: antialiased as
/// Brush's comment, Mip-Splatting's as a `filter_3D` of zeros (its 3D filter is already in the
/// particles, so reading it back changes none); the 3DGS dilation writes no comment.
#[test]
fn every_screen_filter_round_trips_through_ply() {
    let (scene, _) = scenes::layers();
    for filter in ScreenFilter::ALL {
        let scene = Scene { screen_filter: filter, ..scene.clone() };
        let bytes = encode_ply(&scene, PlyFormat::BinaryLittleEndian);
        let header =
            String::from_utf8_lossy(&bytes[..bytes.windows(10).position(|w| w == b"end_header").unwrap()]).into_owned();
        assert_eq!(header.contains("comment SplatRenderMode: mip"), filter == ScreenFilter::Antialiased, "{header}");
        assert_eq!(header.contains("property float filter_3D"), filter == ScreenFilter::Mip, "{header}");
        assert_eq!(header.contains("comment"), filter == ScreenFilter::Antialiased, "{header}");
        let back = parse_ply(&bytes, PlyOptions::default()).unwrap();
        assert_eq!(back.screen_filter, filter);
        assert_same_scene(&scene, &back, 1e-5);
    }
}

/// The streamed, parallel binary `.ply` reader (`read_ply_report`: chunks of `CHUNK_RECORDS`
/// vertices, each decoded on every thread) reads the particles, and the first error, of the
/// sequential in-memory parser, whatever the thread count and across chunk boundaries.
#[test]
fn streamed_ply_reads_as_the_in_memory_parser_whatever_the_threads() {
    use splat_io::ply::{CHUNK_RECORDS, parse_ply_report, read_ply_report};
    let n = 2 * CHUNK_RECORDS as usize + 123;
    let particles = (0..n)
        .map(|i| {
            let t = i as f32 * 0.001;
            let sh: [Vec3; 16] = std::array::from_fn(|k| Vec3::new(t.sin() * 0.1, k as f32 * 0.01, -t.cos() * 0.1));
            Particle::new(
                Vec3::new(t.sin(), t.cos(), t * 0.01),
                Vec3::new(0.01 + 0.001 * t.sin().abs(), 0.02, 0.03),
                Quat::from_euler(glam::EulerRot::XYZ, t, 2.0 * t, 0.5),
                0.5 + 0.4 * t.sin(),
                sh,
            )
            .unwrap()
        })
        .collect();
    let bytes = encode_ply(&Scene::new(particles, 3), PlyFormat::BinaryLittleEndian);
    let dir = std::env::temp_dir().join(format!("splat-io-streamed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scene.ply");
    std::fs::write(&path, &bytes).unwrap();
    let expected = parse_ply_report(&bytes, PlyOptions::default()).unwrap().scene;
    let in_pool = |threads: usize, path: &std::path::Path| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| read_ply_report(path, PlyOptions::default()))
    };
    for threads in [1, 3] {
        let read = in_pool(threads, &path).unwrap().scene;
        assert_eq!(read.particles.len(), n);
        assert!(read.particles == expected.particles, "{threads} threads read other particles");
    }
    // Two bad vertices in different chunks (x = NaN): the lower one is named.
    let header_len = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let stride = (bytes.len() - header_len) / n;
    let mut bad = bytes.clone();
    for vertex in [CHUNK_RECORDS as usize + 5, 2 * CHUNK_RECORDS as usize + 1] {
        let at = header_len + vertex * stride;
        bad[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    }
    std::fs::write(&path, &bad).unwrap();
    let in_memory = parse_ply_report(&bad, PlyOptions::default()).unwrap_err().to_string();
    assert!(in_memory.contains(&format!("vertex {}", CHUNK_RECORDS + 5)), "{in_memory}");
    for threads in [1, 3] {
        let streamed = in_pool(threads, &path).unwrap_err();
        assert_eq!(streamed.kind.to_string(), in_memory, "{threads} threads");
    }
    // A truncated body is refused before any decoding, as the in-memory parser refuses it.
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let in_memory = parse_ply_report(&bytes[..bytes.len() - 100], PlyOptions::default()).unwrap_err().to_string();
    assert_eq!(in_pool(2, &path).unwrap_err().kind.to_string(), in_memory);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene whose particles would not fit in the memory available is refused before it is
/// read, with the estimate; what `splat info` reports as held is that estimate.
#[test]
fn scenes_beyond_the_memory_available_are_refused_with_the_estimate() {
    use splat_io::memory::check_scene;
    let e = check_scene(100_000_000, 3, Some(8 << 30)).unwrap_err().to_string();
    assert!(e.contains("100000000 splats needs about 25.6 GB, more than the 8.6 GB"), "{e}");
    assert!(check_scene(1_000_000, 3, Some(8 << 30)).is_ok());
    assert!(check_scene(u64::MAX, 3, None).is_ok());
    let scene = scenes::cloud().0;
    assert_eq!(Scene::bytes_for(scene.particles.len() as u64, 3), scene.heap_bytes() as u64);
}
