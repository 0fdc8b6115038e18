//! Project automation: `cargo xtask test | fixtures | bless`.

use anyhow::{Context, Result, bail};
use splat_core::render::{RenderSettings, render_exact};
use splat_core::scenes;
use splat_io::ply::{PlyFormat, read_ply, write_ply};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The fixtures generated into `fixtures/`, each with a camera.
const FIXTURES: [&str; 3] = ["layers", "ramp", "cloud"];

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("test") => test(&args[1..]),
        Some("fixtures") => fixtures(),
        Some("bless") => bless(),
        _ => {
            eprintln!(
                "usage: cargo xtask <command>\n\n\
                 commands:\n  \
                 test [ARGS]  run every test of the workspace (optimized build); ARGS go to cargo test\n  \
                 fixtures     regenerate fixtures/*.ply and fixtures/*.cameras.json\n  \
                 bless        re-render the golden images in fixtures/golden/"
            );
            bail!("missing or unknown command");
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

fn test(extra: &[String]) -> Result<()> {
    let status = Command::new(env!("CARGO"))
        .current_dir(root())
        .args(["test", "--workspace", "--release"])
        .args(extra)
        .status()
        .context("running cargo test")?;
    if !status.success() {
        bail!("tests failed ({status})");
    }
    Ok(())
}

/// Write every fixture scene and its camera.
fn fixtures() -> Result<()> {
    let dir = root().join("fixtures");
    std::fs::create_dir_all(&dir)?;
    for name in FIXTURES {
        let (scene, camera) = scenes::by_name(name).expect("fixture names are built-in scenes");
        let ply = dir.join(format!("{name}.ply"));
        write_ply(&ply, &scene, PlyFormat::BinaryLittleEndian)?;
        splat_io::cameras::write_cameras(&dir.join(format!("{name}.cameras.json")), &[camera])?;
        println!(
            "wrote {} ({} particles, SH degree {})",
            ply.display(),
            scene.particles.len(),
            scene.sh_degree
        );
    }
    Ok(())
}

/// Render the exact method for each fixture into `fixtures/golden/NAME-exact.png`.
fn bless() -> Result<()> {
    let dir = root().join("fixtures");
    std::fs::create_dir_all(dir.join("golden"))?;
    for name in FIXTURES {
        let scene = read_ply(&dir.join(format!("{name}.ply")))?;
        let camera = splat_io::cameras::read_cameras(&dir.join(format!("{name}.cameras.json")))?[0];
        let out = render_exact(&scene, &camera, &RenderSettings::default(), &|_| {})?;
        let path = dir.join("golden").join(format!("{name}-exact.png"));
        splat_io::image::write_image(&path, &out.radiance)?;
        println!("blessed {}", path.display());
    }
    Ok(())
}
