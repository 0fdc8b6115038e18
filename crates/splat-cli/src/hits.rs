//! `splat hit-distance`: the comparison of vk_gaussian_splatting Lighting §1.4.3 — the surface
//! each hit distance convention picks on one view. Sorted ray tracing (`exact`) picks its
//! iso-opacity depth with each convention of §1.4.1 (the icosahedron proxy's front face, the
//! maximum density point of the AABB parametric mode) and Sun et al.'s centre convention (§4.1);
//! sorted splatting picks it on the billboards through the centres (§1.4.2). One image side by
//! side (near bright, far dark, one scale for all) and a table of how far each lies from the
//! maximum density's surface.

use crate::args::SceneArgs;
use anyhow::Result;
use clap::Args;
use splat_core::raster::{Blend, RasterMethod, RasterSettings};
use splat_core::trace::Method;
use splat_core::{Algorithm, Frames, HitDistance, Image, RenderSettings};
use splat_io::image::{depth_for_display, write_image};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `splat hit-distance`.
#[derive(Args)]
pub struct HitDistanceArgs {
    /// The scene, camera and shading.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output prefix: writes PREFIX.png (the picked depths side by side, in the table's order).
    #[arg(short, long, default_value = "hit-distance")]
    pub output: PathBuf,
}

/// One picked surface: what picked it and its depth image (NaN where none).
struct Picked {
    name: String,
    depth: Image,
}

/// The picked depth of every convention, the table, the image.
pub fn run(args: HitDistanceArgs) -> Result<()> {
    let (scene, camera, settings) = args.scene.load(640, 480)?;
    let pool = args.scene.pool()?;
    let depth = |algorithm: Algorithm, settings: RenderSettings| -> Result<Image> {
        let render = || algorithm.render(&scene, &camera, &settings, &Frames::default(), &|_| {});
        Ok(pool.install(render)?.depth)
    };
    let mut picked = Vec::new();
    for hit_distance in [HitDistance::Icosahedron, HitDistance::Mean, HitDistance::Center] {
        let name = format!("ray tracing, {}", hit_distance.name());
        let settings = RenderSettings { hit_distance, ..settings };
        picked.push(Picked { name, depth: depth(Algorithm::Trace(Method::Exact), settings)? });
    }
    let sorted = Algorithm::Raster(RasterMethod::Sorted { blend: Blend::Under }, RasterSettings::default());
    picked.push(Picked { name: "rasterization, billboard".into(), depth: depth(sorted, settings)? });
    print!("{}", table(&picked, 1));
    let path = args.output.with_extension("png");
    write_image(&path, &depth_for_display(&side_by_side(&picked)))?;
    eprintln!("wrote {} ({})", path.display(), picked.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(" | "));
    Ok(())
}

/// A Markdown table: per surface, the pixels it picks and its distance to the surface of
/// `reference` (mean and 99th percentile of |Δdepth| / depth where both pick).
fn table(picked: &[Picked], reference: usize) -> String {
    let mut out = String::from(
        "| surface | pixels picked | mean relative difference | 99th percentile |\n|---|---:|---:|---:|\n",
    );
    let base = picked[reference].depth.data();
    for p in picked {
        let d = p.depth.data();
        let share = d.iter().filter(|v| v.is_finite()).count() as f64 / d.len() as f64;
        let mut rel: Vec<f64> = d
            .iter()
            .zip(base)
            .filter(|(a, b)| a.is_finite() && b.is_finite() && **b > 0.0)
            .map(|(a, b)| f64::from((a - b).abs() / b))
            .collect();
        rel.sort_by(f64::total_cmp);
        let mean = rel.iter().sum::<f64>() / rel.len().max(1) as f64;
        let p99 = rel.get((rel.len() * 99 / 100).min(rel.len().saturating_sub(1))).copied().unwrap_or(0.0);
        let _ = writeln!(out, "| {} | {:.1} % | {:.3} % | {:.3} % |", p.name, 100.0 * share, 100.0 * mean, 100.0 * p99);
    }
    out
}

/// The depth images in a row.
fn side_by_side(picked: &[Picked]) -> Image {
    let (w, h) = (picked[0].depth.width(), picked[0].depth.height());
    let mut out = Image::filled(w * picked.len() as u32, h, 1, f32::NAN);
    for (i, p) in picked.iter().enumerate() {
        for y in 0..h {
            for x in 0..w {
                out.pixel_mut(i as u32 * w + x, y)[0] = p.depth.pixel(x, y)[0];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_measures_relative_depth_differences() {
        let image = |v: [f32; 4]| Image::from_data(2, 2, 1, v.to_vec()).unwrap();
        let picked = [
            Picked { name: "a".into(), depth: image([1.0, 2.0, f32::NAN, 4.0]) },
            Picked { name: "b".into(), depth: image([1.1, 2.0, 3.0, f32::NAN]) },
        ];
        let t = table(&picked, 0);
        // b picks 3 of 4 pixels; where both pick, |Δ|/depth is 10 % and 0 %: a mean of 5 %.
        assert!(t.contains("| b | 75.0 % | 5.000 % | 10.000 % |"), "{t}");
        assert!(t.contains("| a | 75.0 % | 0.000 % | 0.000 % |"), "{t}");
        let row = side_by_side(&picked);
        assert_eq!((row.width(), row.pixel(2, 0)[0]), (4, 1.1));
    }
}
