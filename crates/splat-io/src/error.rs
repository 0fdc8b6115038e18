//! The error type of every reader and writer.

use std::path::{Path, PathBuf};
use thiserror::Error;

/// An I/O error naming the file and the problem.
#[derive(Debug, Error)]
#[error("{}: {kind}", path.display())]
pub struct Error {
    /// The file (or a stand-in name for in-memory input).
    pub path: PathBuf,
    /// What went wrong.
    pub kind: ErrorKind,
}

impl Error {
    /// An error about `path`.
    pub fn new(path: impl AsRef<Path>, kind: ErrorKind) -> Self {
        Self { path: path.as_ref().to_path_buf(), kind }
    }
}

/// What went wrong, with the element index or byte offset where it applies.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The operating system refused the read or write.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The extension names no supported format.
    #[error("unsupported file extension (expected {expected})")]
    UnknownExtension {
        /// What is supported.
        expected: &'static str,
    },
    /// The PLY header is malformed.
    #[error("PLY header line {line}: {message}")]
    Header {
        /// 1-based header line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A property of the vertex element is not one this reader knows.
    #[error(
        "PLY header line {line}: unknown vertex property '{name}' (refused by the strict reader; the default one skips it with a warning)"
    )]
    UnknownProperty {
        /// 1-based header line.
        line: usize,
        /// Property name.
        name: String,
    },
    /// A required vertex property is absent.
    #[error("PLY vertex element has no '{0}' property")]
    MissingProperty(String),
    /// The vertex count cannot fit in the bytes that follow the header.
    #[error(
        "header declares {count} vertices of {stride} bytes ({needed} bytes) but only {available} bytes follow the header at offset {body_offset}: the body is truncated or the count is wrong (vertex {first_incomplete} is the first incomplete one, at byte offset {first_incomplete_offset})"
    )]
    CountTooLarge {
        /// Declared vertex count.
        count: u64,
        /// Bytes per vertex.
        stride: u64,
        /// Bytes the count needs.
        needed: u128,
        /// Bytes present after the header.
        available: u64,
        /// Byte offset of the body.
        body_offset: u64,
        /// Index of the first vertex that is not complete.
        first_incomplete: u64,
        /// Its byte offset in the file.
        first_incomplete_offset: u64,
    },
    /// The scene's particles would not fit in the memory this machine has available.
    #[error(
        "holding its {count} splats needs about {:.1} GB, more than the {:.1} GB this machine has available: nothing was read (this renderer holds a scene in memory; render it on a machine with more, or decimate it first)",
        *needed as f64 / 1e9, *available as f64 / 1e9
    )]
    TooLarge {
        /// Splats in the file.
        count: u64,
        /// Bytes they would take.
        needed: u64,
        /// Bytes available.
        available: u64,
    },
    /// An ASCII body ends before the declared count.
    #[error("body is truncated: vertex {index} (line {line}) is missing; the header declares {count}")]
    Truncated {
        /// Missing vertex.
        index: u64,
        /// 1-based line where it should be.
        line: usize,
        /// Declared count.
        count: u64,
    },
    /// A value cannot be parsed.
    #[error("vertex {index}, property '{property}' (line {line}): cannot parse '{token}'")]
    Parse {
        /// Vertex index.
        index: u64,
        /// Property name.
        property: String,
        /// 1-based line.
        line: usize,
        /// The text.
        token: String,
    },
    /// A line of an ASCII body has the wrong number of values.
    #[error("vertex {index} (line {line}) has {found} values, expected {expected}")]
    ValueCount {
        /// Vertex index.
        index: u64,
        /// 1-based line.
        line: usize,
        /// Values found.
        found: usize,
        /// Values expected.
        expected: usize,
    },
    /// A value is NaN or infinite.
    #[error("vertex {index}: property '{property}' is {value}, not a finite number")]
    NonFinite {
        /// Vertex index.
        index: u64,
        /// Property name.
        property: String,
        /// The value.
        value: f64,
    },
    /// All quaternion components are zero.
    #[error("vertex {index}: rotation quaternion is zero and defines no rotation")]
    ZeroQuaternion {
        /// Vertex index.
        index: u64,
    },
    /// A scale is not positive (after exp for .ply) or its inverse overflows.
    #[error("vertex {index}: {detail}")]
    BadScale {
        /// Vertex index.
        index: u64,
        /// The field, raw and resulting values.
        detail: String,
    },
    /// Any other invalid particle.
    #[error("vertex {index}: {error}")]
    Particle {
        /// Vertex index.
        index: u64,
        /// What is wrong.
        error: splat_core::ParticleError,
    },
    /// A `.splat` file's length is not a multiple of its 32-byte record.
    #[error(
        "length {len} is not a multiple of 32 bytes: splat {index} at byte offset {offset} is truncated ({remainder} of 32 bytes)"
    )]
    SplatLength {
        /// File length.
        len: u64,
        /// Index of the incomplete splat.
        index: u64,
        /// Its byte offset.
        offset: u64,
        /// Its bytes present.
        remainder: u64,
    },
    /// A `.spz` file is malformed or uses what this reader does not support.
    #[error("spz: {0}")]
    Spz(String),
    /// A PlayCanvas SOG file (bundle, `meta.json` or image) is malformed or uses what this
    /// reader does not support.
    #[error("SOG: {0}")]
    Sog(String),
    /// A PyTorch checkpoint that is not one of gsplat's or splatfacto's, or is malformed ([`crate::torch`]).
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// A `.ksplat` file (GaussianSplats3D) is malformed or uses what this reader does not
    /// support.
    #[error(".ksplat: {0}")]
    Ksplat(String),
    /// An OpenUSD layer is malformed, or holds what this reader does not read.
    #[error("USD: {0}")]
    Usd(String),
    /// A compressed `.ply` (PlayCanvas / SuperSplat) is malformed.
    #[error("compressed PLY: {0}")]
    CompressedPly(String),
    /// A COLMAP model is malformed or uses a camera model this reader does not render.
    #[error("COLMAP: {0}")]
    Colmap(String),
    /// The camera file is malformed.
    #[error("camera {index}: {message}")]
    Camera {
        /// Entry index (0-based) in the file.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// The JSON is malformed.
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// A file given as cameras is neither a cameras.json, a COLMAP model nor a transforms.json.
    #[error(
        "not a camera file: cameras are an INRIA cameras.json, a COLMAP model (a sparse/0 folder, or its images.bin / images.txt) or a transforms.json (NeRF-synthetic, Nerfstudio); as JSON: {0}"
    )]
    NotCameras(serde_json::Error),
    /// A Nerfstudio `dataparser_transforms.json` is malformed or cannot apply to the cameras.
    #[error("Nerfstudio dataparser transforms: {0}")]
    Dataparser(String),
    /// gsplat's normalised world cannot be found for the cameras and splats given.
    #[error("gsplat's normalised world: {0}")]
    GsplatWorld(String),
    /// A world transform file is not a similarity matrix, or cannot apply to the cameras.
    #[error("world transform: {0}")]
    WorldTransform(String),
    /// A trainer's split does not apply to the views.
    #[error("split: {0}")]
    Split(String),
    /// An image cannot be written or read.
    #[error("image: {0}")]
    Image(String),
    /// A world file is malformed or names something invalid.
    #[error("world: {0}")]
    World(String),
    /// A glTF file's `KHR_gaussian_splatting` splats are malformed or use what this reader
    /// does not decode.
    #[error("glTF: {0}")]
    Gltf(String),
    /// A mesh file (OBJ, glTF) is malformed or holds no triangles.
    #[error("mesh: {0}")]
    Mesh(String),
    /// An accumulation file (`.acc`, [`crate::accumulation`]) is malformed.
    #[error("accumulation: {0}")]
    Accumulation(String),
    /// The file reads but holds neither splats nor meshes.
    #[error("holds no splats and no meshes: nothing to render")]
    Empty,
}
