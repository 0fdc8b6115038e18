//! `splat merge`: the shares of a run (`splat render --frames A..B -o PART.acc`) into the
//! images of the whole run.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::frame::Accumulation;
use splat_io::accumulation::Share;
use splat_io::image::{ImageFormat, Single, write_image, write_image_as};
use std::path::PathBuf;

/// Arguments of `splat merge`.
#[derive(Args)]
pub struct MergeArgs {
    /// The shares' accumulation files, in any order; their frames must follow on (0..64,
    /// 64..128, …) and their renders be the same but for the frames.
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// The merged mean (.png, .exr, .npy), or the merged accumulation (.acc) to merge again.
    #[arg(short, long, default_value = "render.png")]
    pub output: PathBuf,
    /// Also write the per-frame variance of the merged run (.exr or .npy).
    #[arg(long)]
    pub variance: Option<PathBuf>,
    /// Also write the coverage 1 − T.
    #[arg(long)]
    pub alpha: Option<PathBuf>,
}

/// Run `splat merge`.
pub fn run(args: MergeArgs) -> Result<()> {
    let to_acc = splat_io::extension(&args.output).as_deref() == Some("acc");
    if !to_acc {
        ImageFormat::from_path(&args.output)?;
    }
    let outputs =
        [("-o", Some(&args.output)), ("--variance", args.variance.as_ref()), ("--alpha", args.alpha.as_ref())];
    let outputs: Vec<_> = outputs.into_iter().filter_map(|(flag, p)| Some((flag, p?.as_path()))).collect();
    let parts: Vec<_> = args.parts.iter().map(PathBuf::as_path).collect();
    crate::args::check_outputs(&outputs, &parts)?;
    let shares = args
        .parts
        .iter()
        .map(|p| splat_io::accumulation::read(p).with_context(|| format!("reading the share {}", p.display())))
        .collect::<Result<Vec<Share>>>()?;
    let merged = merge(&shares, &args.parts)?;
    let a = &merged.accumulation;
    if to_acc {
        splat_io::accumulation::write(&args.output, &merged)?;
    } else {
        write_image(&args.output, &a.mean)?;
    }
    if let Some(path) = &args.variance {
        write_image(path, &a.variance)?;
    }
    if let Some(path) = &args.alpha {
        write_image_as(path, &a.alpha, Single::Alpha)?;
    }
    eprintln!(
        "merged {}: frames {}..{} → {}",
        crate::counted(shares.len(), "share"),
        a.first,
        u64::from(a.first) + u64::from(a.count),
        args.output.display()
    );
    Ok(())
}

/// The shares merged, refusing shares of different renders (named by their files).
pub fn merge(shares: &[Share], names: &[PathBuf]) -> Result<Share> {
    let Some(first) = shares.first() else { bail!("no share to merge") };
    if let Some(i) = shares.iter().position(|s| s.render != first.render) {
        bail!(
            "{} and {} are shares of different renders (method, settings, camera, scene or seed differ):\n  {}\n  {}",
            names[0].display(),
            names[i].display(),
            first.render,
            shares[i].render
        );
    }
    let parts: Vec<Accumulation> = shares.iter().map(|s| s.accumulation.clone()).collect();
    let accumulation = Accumulation::merge(&parts)?;
    Ok(Share { accumulation, render: first.render.clone() })
}
