//! `splat undistort`: a capture's photographs as a trainer undistorts them, the ground truth its
//! evaluation compares renders against.

use anyhow::{Context, Result, bail};
use clap::Args;
use splat_core::undistort::Undistortion;
use splat_io::cameras::{Split, ViewOptions};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `splat undistort`.
#[derive(Args)]
pub struct UndistortArgs {
    /// Cameras: a COLMAP model (a sparse/0 folder, or its images.bin / images.txt), a
    /// transforms.json (the file or its folder) or a cameras.json, whose views name the
    /// photographs.
    #[arg(long)]
    pub camera: PathBuf,
    /// The trainer whose undistortion to reproduce: the photos resampled as it calls OpenCV
    /// (bilinear), to the pinhole that `splat render --undistort` renders through.
    #[arg(long, value_parser = splat_view::undistort_parser())]
    pub undistort: Undistortion,
    /// The folder the views' image names are relative to [default: a transforms.json's own
    /// folder; for a COLMAP model, images/ beside its sparse/ folder].
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Keep only a trainer's split of the views (its held-out views, the ones it scores).
    #[arg(long, value_parser = splat_view::split_parser())]
    pub split: Option<Split>,
    /// The photographs are the trainer's images_F/ (gsplat's --data_factor, Nerfstudio's
    /// downscale factor): each camera takes K / F and its sides floored before it is
    /// undistorted, as they do.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub data_factor: Option<u32>,
    /// The photographs' width: each camera scaled to it (after --data-factor) before it is
    /// undistorted, as gsplat scales K to the photographs it finds.
    #[arg(long, value_parser = crate::args::parse_side, allow_negative_numbers = true)]
    pub width: Option<u32>,
    /// The photographs' height (see --width).
    #[arg(long, value_parser = crate::args::parse_side, allow_negative_numbers = true)]
    pub height: Option<u32>,
    /// The folder to write the undistorted photographs into, as NAME.png (NAME: the image's
    /// name without folders and extension, as `splat render --all-cameras` names its views, so
    /// that `splat compare` pairs them).
    #[arg(short, long)]
    pub output: PathBuf,
    /// A folder to write, as NAME.png, the mask of each view whose trainer masks pixels
    /// (gsplat's fisheye: white where its sample lies inside the photo, black where its loss
    /// leaves the pixel out and its evaluation renders it black).
    #[arg(long, value_name = "DIR")]
    pub masks: Option<PathBuf>,
}

/// Where the photographs of camera file `camera` lie by the trainers' layouts: a
/// transforms.json's folder (its file paths are relative to it); the folder holding a COLMAP
/// model's sparse/ folder, whose images/ folder holds them.
pub(crate) fn default_images(camera: &Path) -> Option<PathBuf> {
    if splat_io::colmap::is_colmap(camera) {
        let sparse = camera.ancestors().find(|a| a.file_name().is_some_and(|n| n == "sparse"))?;
        return Some(sparse.parent()?.join("images"));
    }
    let file = splat_io::transforms::in_folder(camera).unwrap_or_else(|| camera.to_path_buf());
    Some(file.parent()?.to_path_buf())
}

/// The photograph of view `name` in `images`: the first that exists of the name as it is
/// relative to `images`, its file name alone in `images` (Nerfstudio's `images_F/` holds
/// `frame.png` for `images/frame.png`), and each of those with a usual photograph extension in
/// place of its own (a cameras.json's names have none; gsplat's `images_F_png/` holds
/// `NAME.png` for COLMAP's `NAME.JPG`); the name as it is where none exists.
pub(crate) fn photo_path(images: &Path, name: &str) -> PathBuf {
    let path = images.join(name);
    let flat = Path::new(name).file_name().map(|f| images.join(f));
    let places = std::iter::once(path.clone()).chain(flat);
    let extensions = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];
    let candidates = places.flat_map(|p| std::iter::once(p.clone()).chain(extensions.map(|e| p.with_extension(e))));
    candidates.into_iter().find(|p| p.is_file()).unwrap_or(path)
}

/// Refuse to write the undistorted photographs or the `masks` where they would replace the
/// photographs in `images` or each other (all are named `NAME.png`).
fn refuse_overwriting(images: &Path, output: &Path, masks: Option<&Path>) -> Result<()> {
    let photos = "the photographs it reads";
    let mut clashes = vec![("-o", output, images, photos)];
    if let Some(masks) = masks {
        clashes.push(("--masks", masks, images, photos));
        clashes.push(("--masks", masks, output, "the undistorted photographs (-o)"));
    }
    for (flag, folder, other, what) in clashes {
        if crate::same_path(folder, other) {
            bail!(
                "{flag} {} is the folder of {what}: writing NAME.png there would replace them; give another folder",
                folder.display()
            );
        }
    }
    Ok(())
}

/// `splat undistort`: each view's photograph, read from --images, undistorted as --undistort's
/// trainer does it, into -o.
pub fn run(args: UndistortArgs) -> Result<()> {
    let options = ViewOptions {
        split: args.split,
        factor: args.data_factor,
        size: (args.width, args.height),
        ..Default::default()
    };
    let views = crate::args::load_cameras(&args.camera, options)?;
    let images = match &args.images {
        Some(images) => images.clone(),
        None => default_images(&args.camera).with_context(|| {
            format!("no photographs' folder follows from {}: give it with --images", args.camera.display())
        })?,
    };
    if !images.is_dir() {
        bail!("{} is not a folder of photographs: give the views' folder with --images", images.display());
    }
    refuse_overwriting(&images, &args.output, args.masks.as_deref())?;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let start = Instant::now();
    let (mut resampled, mut masks) = (0, 0);
    let mut undistortions = splat_core::undistort::Undistortions::new(args.undistort);
    for (index, (name, camera)) in views.iter().enumerate() {
        let view = format!("view {index} ({name})");
        let source = photo_path(&images, name);
        let photo = splat_io::image::read_photo(&source)
            .with_context(|| format!("{view}: its photograph (the image names are relative to --images)"))?;
        if (photo.width, photo.height) != (camera.width, camera.height) {
            bail!(
                "{view}: the photograph is {} × {} and the camera {} × {}: give the trainer's --data-factor, or \
                 the photographs' --width and --height, to scale the cameras to them",
                photo.width,
                photo.height,
                camera.width,
                camera.height
            );
        }
        let undistorting = undistortions.of(camera).context(view.clone())?;
        let out = undistorting.photo(&photo).context(view.clone())?;
        resampled += usize::from(out != photo);
        let file = format!("{}.png", crate::render::view_stem(name, index));
        splat_io::image::write_photo(&args.output.join(&file), &out)?;
        if let Some(folder) = &args.masks
            && let Some(mask) = undistortions.mask(camera).context(view)?
        {
            std::fs::create_dir_all(folder).with_context(|| format!("creating {}", folder.display()))?;
            splat_io::image::write_photo(&folder.join(&file), mask)?;
            masks += 1;
        }
    }
    eprintln!(
        "wrote {} ({} resampled through {}'s undistortion, the others as they are) in {:.2} s → {}",
        crate::counted(views.len(), "photograph"),
        resampled,
        args.undistort.name(),
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    if let Some(folder) = &args.masks {
        eprintln!(
            "{} of pixels {} leaves out → {}",
            crate::counted(masks, "mask"),
            args.undistort.name(),
            folder.display()
        );
    }
    Ok(())
}
