//! `splat-io`: reading and writing scenes, cameras and images for `splat`.
//!
//! - Scenes: INRIA 3DGS `.ply` (binary and ASCII, read and write) and antimatter15 `.splat`.
//! - Cameras: INRIA `cameras.json`.
//! - Meshes: Wavefront `.obj` and glTF 2.0 `.gltf` / `.glb` triangles ([`mesh`]).
//! - Worlds: splat sets, meshes, materials and lights in TOML ([`world`]).
//! - Images: `.png` (8-bit), `.exr` (f32), `.npy` (f32, H × W × C), chosen by extension.
//!
//! Every reader returns a typed [`Error`] naming the file and, where it applies, the element
//! index or byte offset and the problem; no input makes a reader panic.
//!
//! ```no_run
//! let scene = splat_io::read_scene("point_cloud.ply".as_ref())?;
//! println!("{} particles, SH degree {}", scene.particles.len(), scene.sh_degree);
//! # Ok::<(), splat_io::Error>(())
//! ```

pub mod cameras;
mod error;
pub mod image;
pub mod mesh;
pub mod ply;
pub mod splat;
pub mod world;

pub use error::{Error, ErrorKind};

use splat_core::Scene;
use std::path::Path;

/// Read a scene, choosing the format by extension (`.ply` or `.splat`).
pub fn read_scene(path: &Path) -> Result<Scene, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("ply") => ply::read_ply(path),
        Some("splat") => splat::read_splat(path),
        _ => Err(Error::new(path, ErrorKind::UnknownExtension { expected: ".ply or .splat" })),
    }
}

/// Read a whole file, with the path in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, Error> {
    std::fs::read(path).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}
