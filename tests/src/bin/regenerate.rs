//! Regenerate what the tests compare against: `regenerate fixtures` writes `fixtures/*.ply`
//! and `fixtures/*.cameras.json` from the built-in scenes; `regenerate bless` re-renders the
//! golden images in `fixtures/golden/`. Run by `cargo xtask fixtures` and `cargo xtask bless`,
//! which stay free of the workspace's libraries so that CI builds those once, with the test
//! build's features.

use anyhow::{Context, Result, bail};
use splat_core::scenes;
use splat_io::ply::{PlyFormat, write_ply};
use splat_tests::golden;

fn main() -> Result<()> {
    match std::env::args().nth(1).as_deref() {
        Some("fixtures") => fixtures(),
        Some("bless") => bless(),
        _ => bail!("usage: regenerate fixtures | bless"),
    }
}

/// Write every fixture scene and its camera.
fn fixtures() -> Result<()> {
    let dir = splat_tests::root().join("fixtures");
    std::fs::create_dir_all(&dir)?;
    for name in golden::FIXTURES.iter().chain(&golden::STRATIFICATION_FIXTURES) {
        let (scene, camera) = scenes::by_name(name).expect("fixture names are built-in scenes");
        let ply = dir.join(format!("{name}.ply"));
        write_ply(&ply, &scene, PlyFormat::BinaryLittleEndian)?;
        splat_io::cameras::write_cameras(&dir.join(format!("{name}.cameras.json")), &[camera])?;
        println!("wrote {} ({} particles, SH degree {})", ply.display(), scene.particles.len(), scene.sh_degree);
    }
    Ok(())
}

/// Write one golden image.
fn save(image: image::RgbImage, fixture: &str, suffix: &str) -> Result<()> {
    let path = golden::path(fixture, suffix);
    image.save(&path).with_context(|| format!("writing {}", path.display()))?;
    println!("blessed {}", path.display());
    Ok(())
}

/// Render every golden case of every fixture into `fixtures/golden/FIXTURE-METHOD.png`.
fn bless() -> Result<()> {
    std::fs::create_dir_all(splat_tests::root().join("fixtures/golden"))?;
    for fixture in golden::FIXTURES {
        for (suffix, case, frames) in golden::cases() {
            save(golden::render(fixture, &case, &frames), fixture, suffix)?;
        }
    }
    for (suffix, case, frames) in golden::lit_cases() {
        save(golden::render_lit(&case, &frames), "demo-lit", suffix)?;
    }
    for (suffix, case, frames) in golden::mesh_cases() {
        save(golden::render_meshes(&case, &frames), "demo-meshes", suffix)?;
    }
    for (suffix, gaussians, frames) in golden::path_cases() {
        save(golden::render_path(gaussians, &frames), "demo-meshes", suffix)?;
    }
    Ok(())
}
