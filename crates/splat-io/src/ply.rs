//! INRIA 3DGS `.ply`: the `point_cloud.ply` written by 3DGS training and most tools after it.
//!
//! Vertex properties: `x y z` (mean), optional `nx ny nz` (unused), `f_dc_0..2` (SH DC),
//! `f_rest_*` (higher SH bands, channel-major: all red coefficients, then green, then blue; 0, 9,
//! 24 or 45 of them for degree 0–3), `opacity` (logit), `scale_0..2` (log), `rot_0..3`
//! (quaternion w, x, y, z, not necessarily normalised). Activations are applied on reading:
//! sigmoid, exp, normalisation.
//!
//! A Mip-Splatting capture adds `filter_3D`, the standard deviation σ_f of each Gaussian's 3D
//! smoothing filter (Mip-Splatting, Yu et al. 2024): the reader convolves the Gaussian with it,
//! Σ ← Σ + σ_f² I, whose axes keep the rotation with scales √(s_i² + σ_f²), and scales the
//! opacity by √(det Σ / det(Σ + σ_f² I)) = ∏ s_i / √(s_i² + σ_f²), as Mip-Splatting's
//! `get_scaling_with_3D_filter` and `get_opacity_with_3D_filter` do. The scene read is then
//! the Gaussians Mip-Splatting renders, in every renderer and every writer.
//!
//! The capture's screen-space filter ([`ScreenFilter`]) is read from the header: a file with
//! `filter_3D` is Mip-Splatting's (its 2D Mip filter); otherwise the last render-mode comment
//! decides, Brush's and gsplat's `comment SplatRenderMode: default | mip` (any case; `mip` is
//! gsplat's antialiased mode, an unknown mode is the default) or Postshot's
//! `comment antialiased 0 | 1`, as splat-transform reads them; without one, the 3DGS dilation.
//! The writer records it as splat-transform and Brush write it: `SplatRenderMode: mip` for the
//! antialiased mode, no comment for the default, and for Mip-Splatting's filter a `filter_3D`
//! of zeros (the 3D filter is already folded into the scales and opacities), which
//! Mip-Splatting's own loader reads too.
//!
//! A 2DGS capture (2D Gaussians: `SplatRenderMode: 2dgs`, or `scale_0`, `scale_1` without
//! `scale_2`) is read as flat 3D Gaussians whose third scale is
//! [`splat_core::particle::SURFEL_THICKNESS`] × the larger of the two (any stored `scale_2` is
//! ignored): the ray tracers then evaluate each surfel at its ray–splat intersection. A scene of
//! such surfels is written back as 2DGS writes it, without `scale_2` and with Brush's
//! `SplatRenderMode: 2dgs`.
//!
//! A file whose first element is `chunk` is a PlayCanvas compressed `.ply`, decoded by
//! [`crate::compressed_ply`].

use crate::{Error, ErrorKind, read_file};
use glam::{Quat, Vec3};
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count, surfel_thickness};
use splat_core::{Particle, ParticleError, Scene, ScreenFilter};
use std::path::Path;

/// Largest header accepted, in bytes; real headers are about 1.5 KiB.
const MAX_HEADER: usize = 1 << 20;

/// Options of the reader.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlyOptions {
    /// Skip vertex properties this reader does not know (e.g. Mip-Splatting's `filter_3D`)
    /// instead of refusing the file. [`crate::read_scene`] allows them and reports them; the
    /// default here is strict.
    pub allow_unknown_properties: bool,
}

/// Encoding of a PLY body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyFormat {
    /// Text, one vertex a line.
    Ascii,
    /// Little-endian binary (what 3DGS writes).
    BinaryLittleEndian,
    /// Big-endian binary.
    BinaryBigEndian,
}

/// Read a 3DGS `.ply` with default options.
pub fn read_ply(path: &Path) -> Result<Scene, Error> {
    read_ply_with(path, PlyOptions::default())
}

/// Read a 3DGS `.ply`.
pub fn read_ply_with(path: &Path, options: PlyOptions) -> Result<Scene, Error> {
    read_ply_report(path, options).map(|read| read.scene)
}

/// Parse the bytes of a 3DGS `.ply` (or a compressed `.ply`, see [`crate::compressed_ply`]).
pub fn parse_ply(bytes: &[u8], options: PlyOptions) -> Result<Scene, ErrorKind> {
    parse_ply_report(bytes, options).map(|read| read.scene)
}

/// A parsed `.ply` and what the reader made of it.
#[derive(Clone, Debug)]
pub struct PlyRead {
    /// The scene.
    pub scene: Scene,
    /// Vertex properties skipped as unknown (only when they are allowed).
    pub skipped: Vec<String>,
    /// Whether the file was a PlayCanvas compressed `.ply`.
    pub compressed: bool,
    /// Whether it carried Mip-Splatting's `filter_3D`, applied to the scene read.
    pub filter_3d: bool,
    /// Whether it was a 2DGS capture, read as surfels (see the module documentation).
    pub surfels: bool,
}

/// Parse the bytes of a `.ply`, reporting the properties it skipped.
pub fn parse_ply_report(bytes: &[u8], options: PlyOptions) -> Result<PlyRead, ErrorKind> {
    let mode = Mode::of_header(bytes);
    if let Some((elements, body)) = crate::compressed_ply::sniff(bytes)? {
        let screen_filter = match mode {
            Some(Mode::Filter(filter)) => filter,
            Some(Mode::Surfels) | None => ScreenFilter::Dilation,
        };
        let mut scene = Scene { screen_filter, ..crate::compressed_ply::parse(bytes, &elements, body)? };
        let surfels = mode == Some(Mode::Surfels);
        if surfels {
            for p in &mut scene.particles {
                p.scale.z = surfel_thickness(p.scale.x, p.scale.y);
            }
        }
        return Ok(PlyRead { scene, skipped: Vec::new(), compressed: true, filter_3d: false, surfels });
    }
    let header = Header::parse(bytes, options)?;
    let body = &bytes[header.body_offset..];
    let layout = Layout::of(&header, mode)?;
    let particles = match header.format {
        PlyFormat::Ascii => {
            let mut particles = Vec::with_capacity(capacity(header.count, body.len(), header.properties.len()));
            let mut values = vec![0.0f64; header.properties.len()];
            let mut lines = Lines::new(body, header.lines);
            let count = header.count;
            for index in 0..count {
                let (line_no, line) =
                    lines.next_nonblank().ok_or(ErrorKind::Truncated { index, line: lines.line, count })?;
                parse_ascii_vertex(index, line_no, line, &header.properties, &mut values)?;
                particles.push(layout.particle(index, &values, &header.properties)?);
            }
            particles
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            header.check_body(body.len() as u64)?;
            let mut particles = Vec::with_capacity(header.count as usize);
            decode_binary(&body[..header.body_len() as usize], 0, &header, &layout, &mut particles)?;
            particles
        }
    };
    Ok(header.read(particles, &layout, mode))
}

/// Read a 3DGS `.ply` file as [`parse_ply_report`] parses its bytes, a binary body streamed in
/// chunks of [`CHUNK_RECORDS`] vertices, each decoded in parallel: the file is never held
/// whole, so a load costs the particles and one chunk, and runs at the speed of the decode on
/// every core. ASCII and compressed `.ply` files are read whole.
pub fn read_ply_report(path: &Path, options: PlyOptions) -> Result<PlyRead, Error> {
    read_ply_progress(path, options, crate::Progress::default())
}

/// [`read_ply_report`], telling `progress` the bytes of the body read, chunk by chunk.
pub fn read_ply_progress(path: &Path, options: PlyOptions, progress: crate::Progress) -> Result<PlyRead, Error> {
    use std::io::{Read, Seek};
    let at = |kind: ErrorKind| Error::new(path, kind);
    let io = |e: std::io::Error| Error::new(path, ErrorKind::Io(e));
    let mut file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    let mut head = Vec::new();
    (&mut file).take((MAX_HEADER + 64) as u64).read_to_end(&mut head).map_err(io)?;
    let binary = |h: &Header| matches!(h.format, PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian);
    let header = match crate::compressed_ply::sniff(&head).map_err(at)? {
        None => Header::parse(&head, options).map_err(at)?,
        Some(_) => return parse_ply_report(&read_file(path)?, options).map_err(at),
    };
    if !binary(&header) {
        return parse_ply_report(&read_file(path)?, options).map_err(at);
    }
    let mode = Mode::of_header(&head);
    let layout = Layout::of(&header, mode).map_err(at)?;
    header.check_body(len - header.body_offset as u64).map_err(at)?;
    crate::memory::check_scene(header.count, layout.sh_degree, crate::memory::available()).map_err(at)?;
    let stride = header.stride();
    drop(head);
    let count = header.count;
    let chunk_bytes = |first: u64| (count - first).min(CHUNK_RECORDS) as usize * stride;
    let read_chunk = |file: &mut std::fs::File, buffer: &mut Vec<u8>, bytes: usize| {
        buffer.resize(bytes, 0);
        file.read_exact(buffer)
    };
    file.seek(std::io::SeekFrom::Start(header.body_offset as u64)).map_err(io)?;
    let (mut current, mut next) = (Vec::new(), Vec::new());
    read_chunk(&mut file, &mut current, chunk_bytes(0)).map_err(io)?;
    let mut particles = Vec::with_capacity(count as usize);
    let mut first = 0u64;
    progress.report(0, count * stride as u64);
    while first < count {
        // Decode this chunk on every core while the next one is read.
        let after = first + (current.len() / stride) as u64;
        let (decoded, read) = rayon::join(
            || decode_binary(&current, first, &header, &layout, &mut particles),
            || if after < count { read_chunk(&mut file, &mut next, chunk_bytes(after)) } else { Ok(()) },
        );
        decoded.map_err(at)?;
        read.map_err(io)?;
        std::mem::swap(&mut current, &mut next);
        first = after;
        progress.report(first * stride as u64, count * stride as u64);
    }
    Ok(header.read(particles, &layout, mode))
}

/// Vertices a streamed binary body is read and decoded in at a time (4 MB of a 3DGS `.ply`
/// at SH degree 3).
pub const CHUNK_RECORDS: u64 = 1 << 14;

/// Append the particles of the binary vertex records `body` (whole records, the first of
/// index `first`) to `out`, decoded in parallel straight into its spare capacity; an error
/// names the lowest bad vertex, whatever the threads, and leaves `out` as it was.
fn decode_binary(
    body: &[u8],
    first: u64,
    header: &Header,
    layout: &Layout,
    out: &mut Vec<Particle>,
) -> Result<(), ErrorKind> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicBool, Ordering};
    let stride = header.stride().max(1);
    let big = header.format == PlyFormat::BinaryBigEndian;
    let properties = &header.properties;
    let decode = |(i, record): (usize, &[u8])| layout.particle_of_record(first + i as u64, record, big, properties);
    let failed = AtomicBool::new(false);
    let stand_in = Particle::new(Vec3::ZERO, Vec3::ONE, Quat::IDENTITY, 0.0, [Vec3::ZERO; SH_MAX_COEFFS])
        .expect("a valid particle");
    let before = out.len();
    out.par_extend(body.par_chunks_exact(stride).enumerate().map(|r| {
        decode(r).unwrap_or_else(|_| {
            failed.store(true, Ordering::Relaxed);
            stand_in.clone()
        })
    }));
    if failed.into_inner() {
        out.truncate(before);
        return Err(body.chunks_exact(stride).enumerate().find_map(|r| decode(r).err()).expect("a record failed"));
    }
    Ok(())
}

/// A render mode a header comment names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Filter(ScreenFilter),
    /// 2D Gaussians (2DGS).
    Surfels,
}

impl Mode {
    /// The mode of a comment's text: Brush's and gsplat's `SplatRenderMode: default | mip | 2dgs`
    /// (any case and spacing; an unknown mode is the default) or Postshot's `antialiased 0 | 1`;
    /// `None` for any other comment.
    fn of_comment(text: &str) -> Option<Mode> {
        let text = text.trim().to_ascii_lowercase();
        if let Some(mode) = text.strip_prefix("splatrendermode:") {
            return Some(match mode.trim() {
                "mip" => Mode::Filter(ScreenFilter::Antialiased),
                "2dgs" => Mode::Surfels,
                _ => Mode::Filter(ScreenFilter::Dilation),
            });
        }
        match text.split_ascii_whitespace().collect::<Vec<_>>().as_slice() {
            ["antialiased", "1"] => Some(Mode::Filter(ScreenFilter::Antialiased)),
            ["antialiased", "0"] => Some(Mode::Filter(ScreenFilter::Dilation)),
            _ => None,
        }
    }

    /// The last render-mode comment of a `.ply` header (plain or compressed).
    fn of_header(bytes: &[u8]) -> Option<Mode> {
        let mut lines = Lines::new(bytes, 0);
        let mut mode = None;
        while let Some((_, text)) = lines.next().filter(|_| lines.offset <= MAX_HEADER) {
            match text.trim_start().strip_prefix("comment") {
                Some(comment) => mode = Mode::of_comment(comment).or(mode),
                None if text.trim() == "end_header" => break,
                None => {}
            }
        }
        mode
    }

    /// The comment the writer records (Brush's spelling), if any: `2dgs` for surfels, `mip`
    /// for the antialiased filter.
    fn comment(written: &Written, filter: ScreenFilter) -> Option<&'static str> {
        if written.surfels {
            return Some("SplatRenderMode: 2dgs");
        }
        (filter == ScreenFilter::Antialiased).then_some("SplatRenderMode: mip")
    }
}

/// Vec capacity for `count` vertices that cannot exceed what the body could hold.
fn capacity(count: u64, body_len: usize, properties: usize) -> usize {
    (count as usize).min(body_len / (2 * properties.max(1)) + 1)
}

fn parse_ascii_vertex(
    index: u64,
    line: usize,
    text: &str,
    properties: &[Property],
    values: &mut [f64],
) -> Result<(), ErrorKind> {
    let mut tokens = text.split_ascii_whitespace();
    let found = text.split_ascii_whitespace().count();
    if found != properties.len() {
        return Err(ErrorKind::ValueCount { index, line, found, expected: properties.len() });
    }
    for (v, p) in values.iter_mut().zip(properties) {
        let token = tokens.next().unwrap_or_default();
        *v = p.ty.parse(token).ok_or_else(|| ErrorKind::Parse {
            index,
            property: p.name.clone(),
            line,
            token: token.chars().take(40).collect(),
        })?;
    }
    Ok(())
}

/// Scalar types of the PLY format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    pub(crate) fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    pub(crate) fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// Decode one value from exactly `size()` bytes.
    fn read(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:literal) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(b);
                f64::from(if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) })
            }};
        }
        match self {
            Self::I8 => f64::from(b[0] as i8),
            Self::U8 => f64::from(b[0]),
            Self::I16 => num!(i16, 2),
            Self::U16 => num!(u16, 2),
            Self::I32 => num!(i32, 4),
            Self::U32 => num!(u32, 4),
            Self::F32 => num!(f32, 4),
            Self::F64 => num!(f64, 8),
        }
    }

    fn parse(self, token: &str) -> Option<f64> {
        match self {
            Self::F32 | Self::F64 => token.parse::<f64>().ok(),
            _ => token.parse::<i64>().ok().map(|v| v as f64),
        }
    }
}

/// What a vertex property means to a particle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    Position(usize),
    Dc(usize),
    Rest(usize),
    Opacity,
    Scale(usize),
    Rotation(usize),
    /// Mip-Splatting's 3D smoothing filter σ_f.
    Filter3d,
    Ignored,
}

impl Slot {
    /// Where the value goes among a particle's [`SLOTS`] values; `None` for an ignored property.
    fn index(self) -> Option<usize> {
        Some(match self {
            Self::Position(i) => i,
            Self::Dc(i) => 3 + i,
            Self::Rest(i) => 6 + i,
            Self::Opacity => 51,
            Self::Scale(i) => 52 + i,
            Self::Rotation(i) => 55 + i,
            Self::Filter3d => 59,
            Self::Ignored => return None,
        })
    }

    fn from_name(name: &str) -> Option<Self> {
        let indexed = |prefix: &str, n: usize| name.strip_prefix(prefix)?.parse::<usize>().ok().filter(|&i| i < n);
        Some(match name {
            "x" => Self::Position(0),
            "y" => Self::Position(1),
            "z" => Self::Position(2),
            "nx" | "ny" | "nz" => Self::Ignored,
            "opacity" => Self::Opacity,
            "filter_3D" | "filter_3d" => Self::Filter3d,
            _ => {
                if let Some(i) = indexed("f_dc_", 3) {
                    Self::Dc(i)
                } else if let Some(i) = indexed("f_rest_", 45) {
                    Self::Rest(i)
                } else if let Some(i) = indexed("scale_", 3) {
                    Self::Scale(i)
                } else if let Some(i) = indexed("rot_", 4) {
                    Self::Rotation(i)
                } else {
                    return None;
                }
            }
        })
    }
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    ty: Scalar,
    slot: Slot,
    /// Not a 3DGS property: skipped because the options allow it.
    unknown: bool,
}

struct Header {
    format: PlyFormat,
    count: u64,
    properties: Vec<Property>,
    body_offset: usize,
    lines: usize,
}

impl Header {
    fn parse(bytes: &[u8], options: PlyOptions) -> Result<Self, ErrorKind> {
        let err = |line: usize, message: String| ErrorKind::Header { line, message };
        let mut lines = Lines::new(bytes, 0);
        let mut format = None;
        let mut count = None;
        let mut properties: Vec<Property> = Vec::new();
        let mut in_vertex = false;
        loop {
            if lines.offset > MAX_HEADER {
                return Err(err(lines.line, format!("no end_header within the first {MAX_HEADER} bytes")));
            }
            let (line, text) = lines.next().ok_or_else(|| err(lines.line + 1, "file ends before end_header".into()))?;
            let words: Vec<&str> = text.split_ascii_whitespace().collect();
            if line == 1 {
                if text.trim() != "ply" {
                    return Err(err(1, "not a PLY file: the first line must be 'ply'".into()));
                }
                continue;
            }
            match words.as_slice() {
                [] => {}
                ["comment" | "obj_info", ..] => {}
                ["format", f, version] => {
                    if *version != "1.0" {
                        return Err(err(line, format!("unsupported PLY version {version}")));
                    }
                    format = Some(match *f {
                        "ascii" => PlyFormat::Ascii,
                        "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                        "binary_big_endian" => PlyFormat::BinaryBigEndian,
                        other => return Err(err(line, format!("unknown format '{other}'"))),
                    });
                }
                ["element", name, n] => {
                    if count.is_some() {
                        in_vertex = false; // elements after the vertices are never read
                        continue;
                    }
                    if *name != "vertex" {
                        return Err(err(line, format!("element '{name}' before 'vertex' is not supported")));
                    }
                    count =
                        Some(n.parse::<u64>().map_err(|_| err(line, format!("vertex count '{n}' is not a number")))?);
                    in_vertex = true;
                }
                ["property", "list", ..] if in_vertex => {
                    return Err(err(line, "list properties in the vertex element are not supported".into()));
                }
                ["property", ty, name] if in_vertex => {
                    let ty = Scalar::from_name(ty).ok_or_else(|| err(line, format!("unknown property type '{ty}'")))?;
                    if properties.iter().any(|p| p.name == *name) {
                        return Err(err(line, format!("property '{name}' is declared twice")));
                    }
                    let slot = match Slot::from_name(name) {
                        Some(slot) => slot,
                        None if options.allow_unknown_properties => Slot::Ignored,
                        None => {
                            return Err(ErrorKind::UnknownProperty { line, name: name.to_string() });
                        }
                    };
                    let unknown = Slot::from_name(name).is_none();
                    properties.push(Property { name: name.to_string(), ty, slot, unknown });
                }
                ["property", ..] if count.is_none() => {
                    return Err(err(line, "property before any element".into()));
                }
                ["property", ..] => {}
                ["end_header"] => break,
                _ => {
                    return Err(err(line, format!("cannot parse '{}'", text.chars().take(60).collect::<String>())));
                }
            }
        }
        let format = format.ok_or_else(|| err(lines.line, "no 'format' line".into()))?;
        let count = count.ok_or_else(|| err(lines.line, "no 'element vertex' line".into()))?;
        Ok(Self { format, count, properties, body_offset: lines.offset, lines: lines.line })
    }

    /// Bytes of a binary vertex record.
    fn stride(&self) -> usize {
        self.properties.iter().map(|p| p.ty.size()).sum()
    }

    /// Bytes of the binary vertex records (checked by [`Header::check_body`] to fit).
    fn body_len(&self) -> u64 {
        self.count * self.stride() as u64
    }

    /// Whether the `available` bytes after the header hold the declared vertices.
    fn check_body(&self, available: u64) -> Result<(), ErrorKind> {
        let stride = self.stride();
        let needed = u128::from(self.count) * stride as u128;
        if needed <= u128::from(available) {
            return Ok(());
        }
        let complete = available / stride.max(1) as u64;
        Err(ErrorKind::CountTooLarge {
            count: self.count,
            stride: stride as u64,
            needed,
            available,
            body_offset: self.body_offset as u64,
            first_incomplete: complete,
            first_incomplete_offset: self.body_offset as u64 + complete * stride as u64,
        })
    }

    /// The scene and report of `particles` read under this header.
    fn read(&self, particles: Vec<Particle>, layout: &Layout, mode: Option<Mode>) -> PlyRead {
        let has = |slot: Slot| self.properties.iter().any(|p| p.slot == slot);
        let skipped = self.properties.iter().filter(|p| p.unknown).map(|p| p.name.clone()).collect();
        let filter_3d = has(Slot::Filter3d);
        let screen_filter = match mode {
            _ if filter_3d => ScreenFilter::Mip,
            Some(Mode::Filter(filter)) => filter,
            Some(Mode::Surfels) | None => ScreenFilter::Dilation,
        };
        let scene = Scene { screen_filter, ..Scene::new(particles, layout.sh_degree) };
        PlyRead { scene, skipped, compressed: false, filter_3d, surfels: layout.surfels }
    }
}

/// Where each particle field comes from, checked once per file.
struct Layout {
    sh_degree: u8,
    /// 2DGS surfels: two scales, the third [`surfel_thickness`].
    surfels: bool,
    /// The properties a binary record's decode reads.
    fields: Vec<Field>,
    /// Whether they are all f32.
    all_f32: bool,
}

impl Layout {
    /// The layout of `header`'s vertices: 2DGS surfels where the render-mode comment says so
    /// or the vertices have two scales.
    fn of(header: &Header, mode: Option<Mode>) -> Result<Self, ErrorKind> {
        let has = |slot: Slot| header.properties.iter().any(|p| p.slot == slot);
        let surfels =
            mode == Some(Mode::Surfels) || (has(Slot::Scale(0)) && has(Slot::Scale(1)) && !has(Slot::Scale(2)));
        Self::new(&header.properties, surfels)
    }

    fn new(properties: &[Property], surfels: bool) -> Result<Self, ErrorKind> {
        let has = |slot: Slot| properties.iter().any(|p| p.slot == slot);
        let required = [
            ("x", Slot::Position(0)),
            ("y", Slot::Position(1)),
            ("z", Slot::Position(2)),
            ("f_dc_0", Slot::Dc(0)),
            ("f_dc_1", Slot::Dc(1)),
            ("f_dc_2", Slot::Dc(2)),
            ("opacity", Slot::Opacity),
            ("scale_0", Slot::Scale(0)),
            ("scale_1", Slot::Scale(1)),
            ("scale_2", Slot::Scale(2)),
            ("rot_0", Slot::Rotation(0)),
            ("rot_1", Slot::Rotation(1)),
            ("rot_2", Slot::Rotation(2)),
            ("rot_3", Slot::Rotation(3)),
        ];
        // A surfel has no third scale to read.
        let optional = |slot: Slot| surfels && slot == Slot::Scale(2);
        for (name, slot) in required {
            if !has(slot) && !optional(slot) {
                return Err(ErrorKind::MissingProperty(name.into()));
            }
        }
        let rest = properties.iter().filter(|p| matches!(p.slot, Slot::Rest(_))).count();
        let sh_degree = match rest {
            0 => 0,
            9 => 1,
            24 => 2,
            45 => 3,
            n => {
                return Err(ErrorKind::Header {
                    line: 0,
                    message: format!("{n} f_rest_* properties: expected 0, 9, 24 or 45 (SH degree 0–3)"),
                });
            }
        };
        if let Some(missing) = (0..rest).find(|&i| !has(Slot::Rest(i))) {
            return Err(ErrorKind::MissingProperty(format!("f_rest_{missing}")));
        }
        let mut fields = Vec::new();
        let mut offset = 0;
        for p in properties {
            if let Some(slot) = p.slot.index() {
                fields.push(Field { offset, ty: p.ty, slot });
            }
            offset += p.ty.size();
        }
        let all_f32 = fields.iter().all(|f| f.ty == Scalar::F32);
        Ok(Self { sh_degree, surfels, fields, all_f32 })
    }

    /// Build one particle from its property values (one per property, in header order),
    /// applying the 3DGS activations.
    fn particle(&self, index: u64, values: &[f64], properties: &[Property]) -> Result<Particle, ErrorKind> {
        let mut slots = [0.0f64; SLOTS];
        for (&v, p) in values.iter().zip(properties) {
            if let Some(at) = p.slot.index() {
                slots[at] = v;
            }
        }
        self.particle_of(index, &slots, properties)
    }

    /// Build one particle from the binary vertex `record`.
    fn particle_of_record(
        &self,
        index: u64,
        record: &[u8],
        big: bool,
        properties: &[Property],
    ) -> Result<Particle, ErrorKind> {
        let mut slots = [0.0f64; SLOTS];
        if self.all_f32 && !big {
            // Every 3DGS trainer's layout: one branch a record, not one a property.
            for f in &self.fields {
                let b = &record[f.offset..f.offset + 4];
                slots[f.slot] = f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            }
        } else {
            for f in &self.fields {
                slots[f.slot] = f.ty.read(&record[f.offset..f.offset + f.ty.size()], big);
            }
        }
        self.particle_of(index, &slots, properties)
    }

    /// Build one particle from its values by slot ([`Slot::index`]).
    fn particle_of(&self, index: u64, slots: &[f64; SLOTS], properties: &[Property]) -> Result<Particle, ErrorKind> {
        if let Some(bad) = slots.iter().position(|v| !v.is_finite()) {
            let p = properties.iter().find(|p| p.slot.index() == Some(bad)).expect("only read slots are set");
            return Err(ErrorKind::NonFinite { index, property: p.name.clone(), value: slots[bad] });
        }
        let position = [slots[0], slots[1], slots[2]];
        let dc = [slots[3], slots[4], slots[5]];
        let rest = &slots[6..51];
        let opacity = slots[51];
        let scale = [slots[52], slots[53], slots[54]];
        let rotation = [slots[55], slots[56], slots[57], slots[58]];
        let filter = slots[59];
        let mut linear_scale = [0.0f32; 3];
        for (axis, (&raw, s)) in scale.iter().zip(&mut linear_scale).enumerate() {
            if self.surfels && axis == 2 {
                continue;
            }
            *s = scale_from_log(raw).ok_or_else(|| {
                let detail = format!(
                    "scale_{axis} = {raw} gives exp(scale_{axis}) = {}, which is not a usable positive scale",
                    raw.exp() as f32
                );
                ErrorKind::BadScale { index, detail }
            })?;
        }
        let q = unit_quaternion(rotation).ok_or(ErrorKind::ZeroQuaternion { index })?;
        let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
        sh[0] = vec3(dc);
        let per_channel = sh_coeff_count(self.sh_degree) - 1;
        for (k, c) in sh.iter_mut().enumerate().skip(1).take(per_channel) {
            *c = Vec3::new(rest[k - 1] as f32, rest[per_channel + k - 1] as f32, rest[2 * per_channel + k - 1] as f32);
        }
        let opacity = opacity_from_logit(opacity);
        if self.surfels {
            linear_scale[2] = surfel_thickness(linear_scale[0], linear_scale[1]);
        }
        let (linear_scale, opacity) = smoothed(linear_scale, opacity, filter);
        let particle =
            Particle::new(vec3(position), Vec3::from(linear_scale), q, opacity, sh).map_err(|error| match error {
                ParticleError::ZeroQuaternion => ErrorKind::ZeroQuaternion { index },
                error => ErrorKind::Particle { index, error },
            })?;
        Ok(particle)
    }
}

/// Values a particle is built from, by [`Slot::index`]: position 0–2, DC 3–5, the 45 SH rest
/// coefficients 6–50, opacity 51, log scales 52–54, rotation 55–58, Mip-Splatting's σ_f 59.
const SLOTS: usize = 60;

/// A property a binary record's decode reads: its byte offset, type and slot.
struct Field {
    offset: usize,
    ty: Scalar,
    slot: usize,
}

/// The linear scale of a stored log scale (3DGS's exp activation, in f64 and then rounded),
/// `None` where it is not a usable positive scale (zero, infinite, or so small that 1/s²
/// overflows).
pub fn scale_from_log(raw: f64) -> Option<f32> {
    let s = raw.exp() as f32;
    (s > 0.0 && s.is_finite() && (1.0 / (s * s)).is_finite()).then_some(s)
}

/// The opacity of a stored logit (3DGS's sigmoid activation), in f64.
pub fn opacity_from_logit(logit: f64) -> f64 {
    1.0 / (1.0 + (-logit).exp())
}

/// The unit quaternion of stored w, x, y, z (normalised in f64, as 3DGS normalises its
/// rotations), `None` where it has no usable length.
pub fn unit_quaternion([w, x, y, z]: [f64; 4]) -> Option<Quat> {
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    (norm != 0.0 && norm.is_normal())
        .then(|| Quat::from_xyzw((x / norm) as f32, (y / norm) as f32, (z / norm) as f32, (w / norm) as f32))
}

/// The scales and opacity of a Gaussian of `scale` and `opacity` convolved with Mip-Splatting's
/// 3D filter of standard deviation `sigma` (0: none): √(s_i² + σ²), and the opacity times
/// ∏ s_i / √(s_i² + σ²), the ratio of the determinants' square roots.
fn smoothed(scale: [f32; 3], opacity: f64, sigma: f64) -> ([f32; 3], f32) {
    if sigma == 0.0 {
        return (scale, opacity as f32);
    }
    let mut coefficient = 1.0;
    let scale = scale.map(|s| {
        let (s2, f2) = (f64::from(s) * f64::from(s), sigma * sigma);
        coefficient *= (s2 / (s2 + f2)).sqrt();
        (s2 + f2).sqrt() as f32
    });
    (scale, (opacity * coefficient) as f32)
}

fn vec3(v: [f64; 3]) -> Vec3 {
    Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32)
}

/// Lines of a byte buffer with their 1-based numbers and the byte offset after each.
pub(crate) struct Lines<'a> {
    bytes: &'a [u8],
    pub(crate) offset: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    pub(crate) fn new(bytes: &'a [u8], line: usize) -> Self {
        Self { bytes, offset: 0, line }
    }

    pub(crate) fn next(&mut self) -> Option<(usize, &'a str)> {
        if self.offset >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.offset..];
        let end = rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |i| i + 1);
        self.offset += end;
        self.line += 1;
        let text = std::str::from_utf8(&rest[..end]).unwrap_or("\u{fffd}");
        Some((self.line, text.trim_end_matches(['\n', '\r'])))
    }

    fn next_nonblank(&mut self) -> Option<(usize, &'a str)> {
        loop {
            let (line, text) = self.next()?;
            if !text.trim().is_empty() {
                return Some((line, text));
            }
        }
    }
}

/// What the writer stores of a scene, decided once for the file.
struct Written {
    sh_degree: u8,
    /// 2DGS surfels: two scales and no `scale_2`.
    surfels: bool,
    /// Mip-Splatting's filter: a `filter_3D` of zeros.
    filter_3d: bool,
}

impl Written {
    fn of(scene: &Scene) -> Self {
        let (surfels, filter_3d) = (scene.is_surfels(), scene.screen_filter == ScreenFilter::Mip);
        Self { sh_degree: scene.sh_degree, surfels, filter_3d }
    }

    /// The scales stored: two for surfels, else three.
    fn scales(&self) -> usize {
        if self.surfels { 2 } else { 3 }
    }
}

/// The PLY property names 3DGS writes, in its order, with Mip-Splatting's `filter_3D` last
/// where the scene's filter is Mip-Splatting's.
fn property_names(written: &Written) -> Vec<String> {
    let mut names: Vec<String> =
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"].map(String::from).to_vec();
    names.extend((0..3 * (sh_coeff_count(written.sh_degree) - 1)).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..written.scales()).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    if written.filter_3d {
        names.push("filter_3D".into());
    }
    names
}

/// Stored (pre-activation) values of a particle, in [`property_names`] order.
fn stored_values(p: &Particle, written: &Written) -> Vec<f32> {
    let per_channel = sh_coeff_count(written.sh_degree) - 1;
    let mut v = vec![p.mean.x, p.mean.y, p.mean.z, 0.0, 0.0, 0.0, p.sh[0].x, p.sh[0].y, p.sh[0].z];
    for channel in 0..3 {
        v.extend((1..=per_channel).map(|k| p.sh[k][channel]));
    }
    // Opacity 0 and 1 have infinite logits: store the nearest finite ones.
    let o = f64::from(p.opacity).clamp(1e-7, 1.0 - 1e-7);
    v.push((o / (1.0 - o)).ln() as f32);
    v.extend(p.scale.to_array()[..written.scales()].iter().map(|s| s.ln()));
    v.extend([p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z]);
    if written.filter_3d {
        v.push(0.0); // filter_3D: already applied
    }
    v
}

/// Encode a scene as a 3DGS `.ply` (all properties `float`), with its screen filter as the
/// module documentation says. Opacities of exactly 0 or 1 are stored as logit(1e-7) and
/// logit(1 − 1e-7), the nearest finite values.
pub fn encode_ply(scene: &Scene, format: PlyFormat) -> Vec<u8> {
    let written = Written::of(scene);
    let names = property_names(&written);
    let format_name = match format {
        PlyFormat::Ascii => "ascii",
        PlyFormat::BinaryLittleEndian => "binary_little_endian",
        PlyFormat::BinaryBigEndian => "binary_big_endian",
    };
    let mut out = format!("ply\nformat {format_name} 1.0\n");
    if let Some(comment) = Mode::comment(&written, scene.screen_filter) {
        out += &format!("comment {comment}\n");
    }
    out += &format!("element vertex {}\n", scene.particles.len());
    for name in &names {
        out += &format!("property float {name}\n");
    }
    out += "end_header\n";
    let mut bytes = out.into_bytes();
    for p in &scene.particles {
        let values = stored_values(p, &written);
        match format {
            PlyFormat::Ascii => {
                let line: Vec<String> = values.iter().map(|v| v.to_string()).collect();
                bytes.extend(line.join(" ").bytes());
                bytes.push(b'\n');
            }
            PlyFormat::BinaryLittleEndian => values.iter().for_each(|v| bytes.extend(v.to_le_bytes())),
            PlyFormat::BinaryBigEndian => values.iter().for_each(|v| bytes.extend(v.to_be_bytes())),
        }
    }
    bytes
}

/// Write a scene as a 3DGS `.ply`.
pub fn write_ply(path: &Path, scene: &Scene, format: PlyFormat) -> Result<(), Error> {
    std::fs::write(path, encode_ply(scene, format)).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}
