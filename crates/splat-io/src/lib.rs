//! `splat-io`: reading and writing scenes, cameras and images for `splat`.
//!
//! - Scenes (read and write unless noted): INRIA 3DGS `.ply` (binary and ASCII), PlayCanvas
//!   compressed `.ply` (read), antimatter15 `.splat`, Niantic `.spz` (versions 2–4), glTF
//!   `.glb` / `.gltf` with `KHR_gaussian_splatting` ([`gltf_splats`]), PlayCanvas SOG (`.sog`
//!   bundles and `meta.json` folders, [`sog`]), GaussianSplats3D `.ksplat` (read, [`ksplat`]),
//!   OpenUSD `ParticleField3DGaussianSplat` in `.usda` layers ([`usd`]); see [`SceneFormat`].
//! - Cameras: INRIA `cameras.json`, COLMAP `cameras`/`images` `.bin` and `.txt` ([`colmap`]).
//! - Meshes: Wavefront `.obj` and glTF 2.0 `.gltf` / `.glb` triangles ([`mesh`]).
//! - Worlds: splat sets, meshes, materials and lights in TOML ([`world`]).
//! - Images: `.png` (8-bit), `.exr` (f32), `.npy` (f32, H × W × C), chosen by extension.
//! - What a front end opens ([`world::open_world`]) and the `x,y,z` options it reads ([`text`]).
//!
//! Every reader returns a typed [`Error`] naming the file and, where it applies, the element
//! index or byte offset and the problem; no input makes a reader panic.
//!
//! ```no_run
//! let scene = splat_io::read_scene("point_cloud.ply".as_ref())?;
//! println!("{} particles, SH degree {}", scene.particles.len(), scene.sh_degree);
//! # Ok::<(), splat_io::Error>(())
//! ```

pub mod accumulation;
pub mod cameras;
pub mod colmap;
pub mod compressed_ply;
mod error;
pub mod gltf_splats;
pub mod gsplat_world;
pub mod image;
pub mod ksplat;
pub mod memory;
pub mod mesh;
mod pickle;
mod placement;
pub mod ply;
pub mod run;
pub mod similarity;
pub mod sog;
pub mod splat;
pub mod spz;
pub mod text;
pub mod torch;
pub mod transforms;
pub mod usd;
pub mod world;
mod zip;

pub use error::{Error, ErrorKind};

use splat_core::{Scene, ScreenFilter};
use std::path::Path;

/// The scene formats, by what the file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// INRIA 3DGS `.ply`: f32 properties, SH up to degree 3, lossless.
    Ply,
    /// PlayCanvas / SuperSplat `.compressed.ply`: 256-splat chunks, quantised (read only).
    CompressedPly,
    /// antimatter15 `.splat`: 32 bytes a splat, colour without view dependence.
    Splat,
    /// Niantic `.spz`: quantised, gzip (versions 2, 3) or zstd (version 4).
    Spz,
    /// glTF 2.0 `.glb` / `.gltf` with `KHR_gaussian_splatting`: f32 attributes, SH up to
    /// degree 3, lossless ([`gltf_splats`]).
    Gltf,
    /// PlayCanvas SOG: `meta.json` and WebP images, bundled (`.sog`) or as a folder; codebooks
    /// and an SH palette ([`sog`]).
    Sog,
    /// mkkellogg's GaussianSplats3D `.ksplat`: f32, or f16 with 16-bit bucket-relative
    /// positions, 8-bit colour, SH up to degree 2 (read only, [`ksplat`]).
    Ksplat,
    /// OpenUSD `.usda` with `ParticleField3DGaussianSplat` prims: f32 text, lossless; read
    /// placed by their `xformOp`s ([`usd`]).
    Usd,
    /// A trainer's checkpoint (3DGS's `.pth`, gsplat's and 3DGRUT's `.pt`, Nerfstudio
    /// splatfacto's `.ckpt`: `torch.save`'s zip of its parameters), lossless (read only,
    /// [`torch`]).
    Checkpoint(torch::Trainer),
}

impl SceneFormat {
    /// The format an output path asks for, by extension (`.ply`, `.splat`, `.spz`, `.glb`,
    /// `.gltf`, `.sog`, or a name ending in `meta.json`: SOG's unbundled form).
    pub fn for_output(path: &Path) -> Result<Self, Error> {
        if sog::is_sog_path(path) {
            return Ok(Self::Sog);
        }
        match extension(path).as_deref() {
            Some("ply") if path.to_string_lossy().to_ascii_lowercase().ends_with(".compressed.ply") => {
                Err(Error::new(path, ErrorKind::UnknownExtension { expected: WRITTEN_EXTENSIONS_READ_ONLY }))
            }
            Some("ksplat" | "pt" | "pth" | "ckpt") => {
                Err(Error::new(path, ErrorKind::UnknownExtension { expected: WRITTEN_EXTENSIONS_READ_ONLY }))
            }
            Some("ply") => Ok(Self::Ply),
            Some("splat") => Ok(Self::Splat),
            Some("spz") => Ok(Self::Spz),
            Some("glb" | "gltf") => Ok(Self::Gltf),
            Some("usda") => Ok(Self::Usd),
            _ => Err(Error::new(path, ErrorKind::UnknownExtension { expected: WRITTEN_EXTENSIONS })),
        }
    }

    /// The screen filter a file of this format records for a scene of `filter`: the filter
    /// itself where the format can say it, else the nearest it can (`.spz` marks Mip-Splatting's
    /// filter antialiased, the other compensated filter) or none (`.splat` and glTF have no
    /// mode: the 3DGS dilation, the extension's `ellipse` kernel). A writer that records another
    /// filter than the scene's changes how the capture renders, so front ends say so.
    pub fn records(self, filter: ScreenFilter) -> ScreenFilter {
        match (self, filter) {
            (Self::Ply | Self::CompressedPly, filter) => filter,
            (Self::Spz | Self::Sog, ScreenFilter::Mip) => ScreenFilter::Antialiased,
            (Self::Spz | Self::Sog, filter) => filter,
            (Self::Splat | Self::Gltf | Self::Ksplat | Self::Usd | Self::Checkpoint(_), _) => ScreenFilter::Dilation,
        }
    }

    /// Its name as users know it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ply => ".ply",
            Self::CompressedPly => "compressed .ply",
            Self::Splat => ".splat",
            Self::Spz => ".spz",
            Self::Gltf => "glTF (KHR_gaussian_splatting)",
            Self::Sog => "PlayCanvas SOG",
            Self::Ksplat => "GaussianSplats3D .ksplat",
            Self::Usd => "OpenUSD ParticleField3DGaussianSplat",
            Self::Checkpoint(trainer) => trainer.checkpoint_name(),
        }
    }
}

/// The extensions the writers take, as errors list them.
const WRITTEN_EXTENSIONS: &str = ".ply, .splat, .spz, .glb, .gltf, .sog, meta.json or .usda";
const WRITTEN_EXTENSIONS_READ_ONLY: &str = ".ply, .splat, .spz, .glb, .gltf, .sog, meta.json or .usda (compressed \
                                            .ply, .ksplat and trainers' .pt and .ckpt checkpoints are read only)";
/// The extensions the readers take.
const READ_EXTENSIONS: &str = ".ply, .splat, .spz, .glb, .gltf, .sog, meta.json, .ksplat, .usda, .usd, .pt (a gsplat or \
                               3DGRUT checkpoint), .pth (a 3DGS checkpoint) or .ckpt (a Nerfstudio splatfacto \
                               checkpoint)";

/// Options of [`read_scene_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Refuse `.ply` vertex properties this reader does not know, instead of skipping them.
    pub strict: bool,
    /// The axes of `.spz` data.
    pub spz_axes: spz::SpzAxes,
    /// The screen filter the capture was trained with, overriding what the file says (its
    /// render-mode comment, its `filter_3D`, its `.spz` flag) or does not say.
    pub screen_filter: Option<ScreenFilter>,
    /// Told how far a long read has come (binary `.ply` bodies, chunk by chunk).
    pub progress: Progress,
}

/// A callback told the bytes read of a file's total, for a front end's progress display;
/// `Progress::default()` tells nobody. Two are equal whatever they call: progress does not
/// change what is read.
#[derive(Clone, Copy, Default)]
pub struct Progress(pub Option<&'static (dyn Fn(u64, u64) + Sync)>);

impl Progress {
    /// Tell the callback, if any, that `done` bytes of `total` are read.
    pub fn report(self, done: u64, total: u64) {
        if let Some(f) = self.0 {
            f(done, total);
        }
    }
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() { "Progress(reported)" } else { "Progress(none)" })
    }
}

impl PartialEq for Progress {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Eq for Progress {}

/// A scene read from a file, with what the reader made of it.
#[derive(Clone, Debug)]
pub struct SceneRead {
    /// The scene.
    pub scene: Scene,
    /// The format found.
    pub format: SceneFormat,
    /// `.ply` vertex properties skipped as unknown.
    pub skipped_properties: Vec<String>,
    /// Whether the file carried Mip-Splatting's 3D smoothing filter (`filter_3D`), applied to
    /// the scene read ([`ply`]).
    pub filter_3d: bool,
    /// Whether the file held 2D Gaussians (2DGS surfels), read as flat Gaussians ([`ply`]).
    pub surfels: bool,
    /// The screen filter the file names (by its render-mode comment, `filter_3D` or `.spz`
    /// flag; the 3DGS dilation where it names none). The scene's is this unless
    /// [`ReadOptions::screen_filter`] overrides it.
    pub file_filter: ScreenFilter,
    /// The format's version and container where the format has several (SOG's, `.spz`'s,
    /// `.ksplat`'s compression level),
    /// for `splat info`; empty otherwise.
    pub detail: String,
    /// What the reader did that the user should hear of (an `.spz` extension skipped or
    /// honoured, an SH band dropped); front ends print each.
    pub notes: Vec<String>,
}

/// A path's extension in lower case, `None` without one.
pub fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

/// A path's file name, as messages show it (the whole path where it has none).
pub(crate) fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// Read a scene, choosing the format by extension (`.ply`, including compressed ones, `.splat`,
/// `.spz`, `.glb`, `.gltf`, `.sog`, a name ending in `meta.json`, `.ksplat`, `.usda`, `.usd`) with
/// default options:
/// unknown `.ply` properties are skipped.
pub fn read_scene(path: &Path) -> Result<Scene, Error> {
    read_scene_with(path, ReadOptions::default()).map(|read| read.scene)
}

/// What to tell the user of the `.ply` vertex properties a reader skipped (`PATH: skipped
/// unknown vertex properties a, b`), or `None` when it skipped none. Front ends add how to
/// refuse them instead (the CLI's `--strict`).
pub fn skipped_properties_warning(path: &Path, skipped: &[String]) -> Option<String> {
    (!skipped.is_empty())
        .then(|| format!("{}: skipped unknown vertex properties {}", path.display(), skipped.join(", ")))
}

/// The folder `path` lies in: its parent, `.` for a bare file name (whose parent is empty).
pub fn folder_of(path: &Path) -> &Path {
    path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// A reader's note on the file at `path` as front ends show it: `PATH: note`.
pub fn file_note(path: &Path, note: &str) -> String {
    format!("{}: {note}", path.display())
}

/// Read a scene, choosing the format by extension, and report what was skipped.
pub fn read_scene_with(path: &Path, options: ReadOptions) -> Result<SceneRead, Error> {
    let read = |format, scene: Scene| SceneRead {
        file_filter: scene.screen_filter,
        scene,
        format,
        skipped_properties: Vec::new(),
        filter_3d: false,
        surfels: false,
        detail: String::new(),
        notes: Vec::new(),
    };
    let mut read = match extension(path).as_deref() {
        _ if sog::is_sog_path(path) => {
            let (scene, info) = sog::read_sog(path)?;
            SceneRead { detail: info.describe(), ..read(SceneFormat::Sog, scene) }
        }
        Some("ply") => {
            let plain = ply::PlyOptions { allow_unknown_properties: !options.strict };
            let ply = ply::read_ply_progress(path, plain, options.progress)?;
            let format = if ply.compressed { SceneFormat::CompressedPly } else { SceneFormat::Ply };
            let (skipped_properties, filter_3d, surfels) = (ply.skipped, ply.filter_3d, ply.surfels);
            let mut read = SceneRead { skipped_properties, filter_3d, surfels, ..read(format, ply.scene) };
            if format == SceneFormat::Ply {
                run::read_beside(path, torch::Trainer::Inria, &mut read.scene, &mut read.notes);
            }
            read
        }
        Some("splat") => read(SceneFormat::Splat, splat::read_splat(path)?),
        Some("spz") => {
            let spz = spz::read_spz_report(path, options.spz_axes)?;
            SceneRead {
                detail: format!("version {}", spz.version),
                notes: spz.notes,
                ..read(SceneFormat::Spz, spz.scene)
            }
        }
        Some("glb" | "gltf") => read(SceneFormat::Gltf, gltf_splats::read_gltf_splats(path)?),
        Some("ksplat") => {
            let ksplat = ksplat::read_ksplat(path)?;
            SceneRead { detail: ksplat.describe(), notes: ksplat.notes, ..read(SceneFormat::Ksplat, ksplat.scene) }
        }
        Some("usda" | "usd" | "usdc" | "usdz") => {
            let usd = usd::read_usd(path)?;
            SceneRead { detail: usd.describe(), notes: usd.notes, ..read(SceneFormat::Usd, usd.scene) }
        }
        Some("pt" | "pth" | "ckpt") => {
            let (scene, info) = torch::read_checkpoint(path)?;
            SceneRead {
                detail: info.describe(),
                notes: info.notes,
                ..read(SceneFormat::Checkpoint(info.trainer), scene)
            }
        }
        _ => return Err(Error::new(path, ErrorKind::UnknownExtension { expected: READ_EXTENSIONS })),
    };
    if let Some(filter) = options.screen_filter {
        read.scene.screen_filter = filter;
    }
    Ok(read)
}

/// Write a scene in the format its extension names (`.ply`: binary little-endian f32;
/// `.splat`; `.spz` with `spz` options; `.glb` / `.gltf` with `KHR_gaussian_splatting`; `.sog`
/// or a `meta.json` and its images: PlayCanvas SOG version 2; `.usda`: OpenUSD).
pub fn write_scene(path: &Path, scene: &Scene, spz: spz::SpzWriteOptions) -> Result<SceneFormat, Error> {
    let format = SceneFormat::for_output(path)?;
    match format {
        SceneFormat::Ply => ply::write_ply(path, scene, ply::PlyFormat::BinaryLittleEndian)?,
        SceneFormat::Splat => splat::write_splat(path, scene)?,
        SceneFormat::Spz => spz::write_spz(path, scene, spz)?,
        SceneFormat::Gltf => gltf_splats::write_gltf_splats(path, scene)?,
        SceneFormat::Sog => sog::write_sog(path, scene)?,
        SceneFormat::Usd => usd::write_usda(path, scene)?,
        SceneFormat::CompressedPly | SceneFormat::Ksplat | SceneFormat::Checkpoint(_) => {
            unreachable!("for_output refuses them")
        }
    }
    Ok(format)
}

/// Read a whole file, with the path in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, Error> {
    std::fs::read(path).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}
