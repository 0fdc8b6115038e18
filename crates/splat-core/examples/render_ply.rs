//! Render a 3DGS scene with exact sorted compositing (Eq. 3 of Sun et al. 2025) through the
//! BVH and write a PNG — the core does the rendering, `splat-io` reads and writes files:
//!
//! ```sh
//! cargo run --release -p splat-core --example render_ply -- fixtures/cloud.ply cloud.png
//! ```
use splat_core::trace::{Method, TraceScene, render_frames};
use splat_core::{Camera, Frames, RenderSettings, glam::Vec3};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let input = args.next().unwrap_or_else(|| "fixtures/cloud.ply".into());
    let output = args.next().unwrap_or_else(|| "render_ply.png".into());
    let scene = splat_io::read_scene(input.as_ref())?;
    // Frame the central 96 % of the particles from +z, 320 × 240, world up +y.
    let camera = Camera::framing(&scene.robust_bounds(0.02), Vec3::Y, 320, 240)?;
    let trace = TraceScene::new(&scene, RenderSettings::default())?;
    let out = render_frames(&trace, &camera, &Method::Exact, &Frames::default(), &|_| {})?;
    splat_io::image::write_image(output.as_ref(), &out.mean)?;
    println!("{} particles → {output}", scene.particles.len());
    Ok(())
}
