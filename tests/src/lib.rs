//! Shared helpers of the end-to-end tests, a module a concern: [`mod@reference`] (an independent
//! f64 implementation of the exact render, Eq. 3, written from the formulas rather than from
//! `splat-core`), [`inria`] (a port of the INRIA rasterizer and its trainers' variants),
//! [`colmap_models`] (a port of COLMAP's camera models), [`harness`] (the statistical
//! method: z-tests, power studies, convergence), [`flips`] (how close a frame's decisions came
//! to their thresholds, for CPU = GPU comparisons), [`golden`] (the golden images),
//! [`path_worlds`] (the path tracer's test worlds); here, what they share: the workspace root,
//! golden-image comparison, loud skips, the bonsai capture and its standard view.

pub mod colmap_models;
pub mod inria;

use std::path::{Path, PathBuf};

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ is in the workspace").to_path_buf()
}

#[allow(clippy::needless_range_loop)] // matrix algebra reads best with explicit indices
pub mod reference;

/// Compare an 8-bit rendering with a committed golden PNG: every channel within `tolerance`
/// units. On mismatch (or a missing golden) write `NAME-actual.png` and `NAME-diff.png` beside
/// the golden and return a message naming them.
pub fn compare_golden(golden: &Path, actual: &image::RgbImage, tolerance: u8) -> Result<(), String> {
    let stem = golden.with_extension("");
    let actual_path = PathBuf::from(format!("{}-actual.png", stem.display()));
    let diff_path = PathBuf::from(format!("{}-diff.png", stem.display()));
    let expected = match image::open(golden) {
        Ok(img) => img.to_rgb8(),
        Err(e) => {
            actual.save(&actual_path).map_err(|e| e.to_string())?;
            return Err(format!(
                "cannot read {}: {e}; wrote {} (run `cargo xtask bless`)",
                golden.display(),
                actual_path.display()
            ));
        }
    };
    if expected.dimensions() != actual.dimensions() {
        actual.save(&actual_path).map_err(|e| e.to_string())?;
        return Err(format!(
            "{}: size {:?}, rendered {:?}",
            golden.display(),
            expected.dimensions(),
            actual.dimensions()
        ));
    }
    let mut worst = 0u8;
    let mut bad = 0usize;
    let diff = image::RgbImage::from_fn(actual.width(), actual.height(), |x, y| {
        let (a, e) = (actual.get_pixel(x, y), expected.get_pixel(x, y));
        let d = [0, 1, 2].map(|k| a[k].abs_diff(e[k]));
        let m = d.into_iter().max().unwrap_or(0);
        worst = worst.max(m);
        bad += usize::from(m > tolerance);
        image::Rgb(d.map(|v| v.saturating_mul(16)))
    });
    if bad == 0 {
        return Ok(());
    }
    actual.save(&actual_path).map_err(|e| e.to_string())?;
    diff.save(&diff_path).map_err(|e| e.to_string())?;
    Err(format!(
        "{}: {bad} pixels differ by more than {tolerance} (worst {worst}); wrote {} and {}",
        golden.display(),
        actual_path.display(),
        diff_path.display()
    ))
}

pub mod harness;

pub mod flips;

/// File where skipped tests are recorded, one line each: the one the environment variable
/// `SPLAT_SKIP_LOG` names (`cargo xtask test` sets it, and prints the file as a summary after
/// the run); none without it.
pub fn skip_log() -> Option<PathBuf> {
    std::env::var_os("SPLAT_SKIP_LOG").map(PathBuf::from)
}

/// A test that cannot run here (no GPU adapter, no asset): under `CI=true` it fails, naming
/// `reason`; otherwise it says so on stderr and in [`skip_log`], and the caller returns.
pub fn skip(test: &str, reason: &str) {
    assert!(std::env::var("CI").is_err(), "CI=true and {test} cannot run: {reason}");
    record_skip("SKIPPED", test, reason);
}

/// A test that does not apply to this machine (a lavapipe-only check on a hardware GPU): said
/// on stderr and in [`skip_log`] like a skip, but not a failure under `CI=true`.
pub fn not_applicable(test: &str, reason: &str) {
    record_skip("NOT APPLICABLE", test, &format!("not applicable, {reason}"));
}

/// Say `KIND test: reason` on stderr and append `test: reason` to [`skip_log`].
fn record_skip(kind: &str, test: &str, reason: &str) {
    eprintln!("{kind} {test}: {reason}");
    let Some(log) = skip_log() else { return };
    let line = format!("{test}: {reason}\n");
    let logged = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log)
        .and_then(|mut f| std::io::Write::write_all(&mut f, line.as_bytes()));
    if let Err(e) = logged {
        eprintln!("(not recorded in {}: {e})", log.display());
    }
}

/// The name of the running test (its thread's name under libtest).
pub fn current_test() -> String {
    std::thread::current().name().unwrap_or("a test").to_string()
}

/// The bonsai capture fetched by `cargo xtask assets`, if present (tests skip without it,
/// loudly; with `CI=true` they fail instead).
pub fn bonsai() -> Option<splat_core::Scene> {
    let path = root().join("target/assets/bonsai-7k-mini.splat");
    if !path.exists() {
        skip(&current_test(), &format!("{} is absent (run `cargo xtask assets`)", path.display()));
        return None;
    }
    Some(splat_io::read_scene(&path).expect("the verified bonsai capture loads"))
}

/// `mesh` scaled by `scale`, turned so that its +y axis faces `facing`, and moved to `at`: how
/// the mesh tests place the procedural plane and sphere.
pub fn placed(
    mesh: splat_core::mesh::TriangleMesh,
    scale: f32,
    facing: glam::Vec3,
    at: glam::Vec3,
) -> splat_core::mesh::TriangleMesh {
    let r = glam::Quat::from_rotation_arc(glam::Vec3::Y, facing.normalize());
    mesh.transformed(glam::Affine3A::from_scale_rotation_translation(glam::Vec3::splat(scale), r, at))
}

/// The particles of `scene` whose splats reach `camera`'s image, in id order: the same image
/// (the others cover none of its pixels), and a frame costs what the crop needs rather than
/// the whole capture (lavapipe runs the vertex stage of every instance: 66 ms a frame for the
/// bonsai's 273k splats).
pub fn in_view(scene: &splat_core::Scene, camera: &splat_core::Camera) -> splat_core::Scene {
    let r = splat_core::raster::Rasterizer::new(
        scene,
        camera,
        splat_core::RenderSettings::default(),
        splat_core::raster::RasterSettings::default(),
    )
    .unwrap();
    let mut ids: Vec<u32> = r.splats().iter().map(|s| s.id).collect();
    ids.sort_unstable();
    splat_core::Scene {
        particles: ids.iter().map(|&i| scene.particles[i as usize].clone()).collect(),
        sh_degree: scene.sh_degree,
        screen_filter: scene.screen_filter,
        trained: scene.trained,
    }
}

/// The standard bonsai view (the capture's world up is −y): 1200 × 800 from (0, −1.5, 4)
/// looking at (0, 0.5, 0), 50° vertical field of view.
pub fn bonsai_camera() -> splat_core::Camera {
    splat_core::Camera::look_at(
        glam::Vec3::new(0.0, -1.5, 4.0),
        glam::Vec3::new(0.0, 0.5, 0.0),
        glam::Vec3::new(0.0, -1.0, 0.0),
        50.0,
        1200,
        800,
    )
    .expect("valid camera")
}

pub mod path_worlds;

pub mod golden;

/// `scene` as the text of an ASCII `.ply` that 2DGS writes: `scale_0` and `scale_1` without
/// `scale_2` (so a reader takes its particles as surfels).
pub fn two_dgs_ply(scene: &splat_core::Scene) -> String {
    let text = String::from_utf8(splat_io::ply::encode_ply(scene, splat_io::ply::PlyFormat::Ascii)).expect("ASCII");
    let (header, body) = text.split_once("end_header\n").expect("a header");
    let names: Vec<&str> = header.lines().filter_map(|l| l.strip_prefix("property float ")).collect();
    let drop = names.iter().position(|&n| n == "scale_2").expect("a scale_2 property");
    let header = header.replace("property float scale_2\n", "");
    let body: String = body
        .lines()
        .map(|l| {
            l.split(' ').enumerate().filter(|&(i, _)| i != drop).map(|(_, v)| v).collect::<Vec<_>>().join(" ") + "\n"
        })
        .collect();
    header + "end_header\n" + &body
}
