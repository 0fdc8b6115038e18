//! `splat convert`: a scene from one format to another.

use crate::args::ReadArgs;
use anyhow::{Result, bail};
use clap::Args;
use splat_io::SceneFormat;
use splat_io::spz::SpzWriteOptions;
use std::path::{Path, PathBuf};

/// Arguments of `splat convert`.
#[derive(Args)]
pub struct ConvertArgs {
    /// Input scene: .ply (3DGS or PlayCanvas compressed), .splat, .spz (versions 2–4), glTF
    /// .glb / .gltf (KHR_gaussian_splatting), PlayCanvas SOG (.sog or meta.json),
    /// GaussianSplats3D .ksplat, OpenUSD .usda, or a trainer's checkpoint (3DGS's .pth, gsplat's
    /// or 3DGRUT's .pt, Nerfstudio splatfacto's .ckpt).
    pub input: PathBuf,
    /// Output scene, format by extension: .ply (f32, lossless), .splat (8-bit degree-0 colour,
    /// no view dependence), .spz (quantised, about 10× smaller than .ply), .sog (PlayCanvas SOG
    /// bundle; a path ending in meta.json writes the images beside it), .glb / .gltf
    /// (KHR_gaussian_splatting, f32, lossless; glTF's +Y-up axes) or .usda (OpenUSD
    /// ParticleField3DGaussianSplat, f32, lossless).
    pub output: PathBuf,
    /// Version of a .spz output: 2 (8-bit rotations), 3 (smallest-three rotations, gzip) or
    /// 4 (zstd streams; readers from 2025 on).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(2..=4))]
    pub spz_version: u32,
    /// How scene files are read.
    #[command(flatten)]
    pub read: ReadArgs,
}

/// Run `splat convert`.
pub fn run(args: ConvertArgs) -> Result<()> {
    let format = SceneFormat::for_output(&args.output)?;
    refuse_overwriting_the_input(&args.input, &args.output)?;
    let read = crate::args::read_scene(&args.input, args.read)?;
    let scene = read.scene;
    if format == SceneFormat::Splat && scene.sh_degree > 0 {
        eprintln!(
            "warning: .splat has no view-dependent colour: SH bands 1–{} are dropped, the degree-0 colour is kept",
            scene.sh_degree
        );
    }
    if scene.is_surfels() && format != SceneFormat::Ply {
        eprintln!(
            "warning: {} cannot record 2D Gaussians (2DGS): written as 3D Gaussians of their thickness, which renders \
             the same with the ray-tracing methods",
            format.name()
        );
    }
    let recorded = format.records(scene.screen_filter);
    if recorded != scene.screen_filter {
        eprintln!(
            "warning: {} cannot record {}: written as {}, so it renders differently",
            format.name(),
            scene.screen_filter.describe(),
            recorded.describe()
        );
    }
    if let Some(trained) = scene.trained {
        let mut flags = format!("--preset {}", trained.preset.name());
        if !trained.has_presets_kernel() {
            flags += &format!(" --kernel-degree {} --cutoff {}", trained.kernel_degree, trained.cutoff);
        }
        if !trained.has_presets_near() {
            flags += &format!(" --near-plane {}", trained.near);
        }
        if let Some(b) = trained.background {
            flags += &format!(" --background {},{},{}", b.x, b.y, b.z);
        }
        eprintln!(
            "warning: {} cannot record that its splats were trained through {}: render it with {flags}",
            format.name(),
            trained.describe()
        );
    }
    let spz = SpzWriteOptions { version: args.spz_version, axes: args.read.spz_axes.into() };
    splat_io::write_scene(&args.output, &scene, spz)?;
    let size = |p: &PathBuf| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    eprintln!(
        "converted {} splats (SH degree {}) from {} to {}: {} → {} bytes",
        scene.particles.len(),
        scene.sh_degree,
        read.format.name(),
        format.name(),
        size(&args.input),
        size(&args.output)
    );
    Ok(())
}

/// Refuse an `output` that cannot be written or would write over `input`: the same file, or a
/// SOG `meta.json` in the folder of an input `meta.json`, whose images it would replace (both
/// name theirs alike).
fn refuse_overwriting_the_input(input: &Path, output: &Path) -> Result<()> {
    crate::args::check_outputs(&[("the output", output)], &[input])?;
    if let (Some(read), Some(written)) = (meta_folder(input), meta_folder(output))
        && crate::same_path(read, written)
    {
        bail!(
            "the output {} would write its images over those of the input {}: give another folder",
            output.display(),
            input.display()
        );
    }
    Ok(())
}

/// The folder of a SOG `meta.json` (its images lie beside it); `None` for other paths.
fn meta_folder(path: &Path) -> Option<&Path> {
    let bundle = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("sog"));
    (splat_io::sog::is_sog_path(path) && !bundle).then(|| splat_io::folder_of(path))
}
