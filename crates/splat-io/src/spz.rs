//! Niantic `.spz`: the compressed splat format of the spz library (nianticlabs/spz), versions 2,
//! 3 and 4, read and written.
//!
//! | version | container | rotation |
//! |---|---|---|
//! | 2 | gzip around a 16-byte header and the attribute arrays | x, y, z of q (w ≥ 0), 8 bits each |
//! | 3 | as 2 | "smallest three": index of the largest of x, y, z, w (2 bits), the other three as sign + 9 bits of \|c\|/√½ |
//! | 4 | 32-byte plain header, a table of contents, one zstd stream per attribute | as 3 |
//!
//! The attributes, in file order, per splat: position (3 × 24-bit signed fixed point with
//! `fractional_bits`), alpha (u8, opacity × 255), colour (3 × u8, SH DC × 0.15 × 255 + 127.5),
//! scale (3 × u8, (ln s + 10) × 16), rotation (3 or 4 bytes), higher SH bands (u8, x × 128 +
//! 128, coefficient-major with the three channels inner; the writer rounds band 1 to 5 bits and
//! bands 2–3 to 4 bits, the spz library's defaults).
//!
//! **Render mode.** Bit 0x1 of the header's flags byte (offset 14) marks an antialiased capture
//! (gsplat's antialiased mode, [`ScreenFilter::Antialiased`]); the reader sets the scene's
//! screen filter from it and the writer sets it for that filter. The format has no mark for
//! Mip-Splatting's 2D Mip filter: the writer marks such a scene antialiased, the nearest
//! filter it records ([`crate::SceneFormat::records`]).
//!
//! **Extensions.** With header flag 0x2 a file carries extension records (the spz library's
//! `extensions/`: a u32 type, a u32 byte length, the payload), in version 4 between the header
//! and the table of contents, in versions 2–3 after the attribute arrays. Adobe's
//! `SPZ_ADOBE_coordinate_system` (0xADBE0003) is honoured: data in any of spz's eight axis
//! systems that keep x, y, z in order (LDB … RUF; half turns and mirrors of a `.ply`'s RDF) are
//! converted to the scene's axes (mean, rotation S R S and SH parities), and it outranks
//! [`SpzAxes`]; the eight that swap y and z are refused by name. `SPZ_ADOBE_safe_orbit_camera`
//! and unknown types are skipped with a note ([`SpzRead::notes`]). The writer writes none.
//!
//! **SH degree 4** (spz allows it): read with band 4 dropped, and a note.
//!
//! **Axes.** The spz README says spz stores right-up-back (RUB) axes, but the library's default
//! options (`UNSPECIFIED`) convert nothing, and so do its `ply_to_spz`, PlayCanvas
//! splat-transform 3.7 and spz-js 1.2: files made from a 3DGS `.ply` by these tools hold the
//! `.ply`'s own (OpenCV, right-down-forward) axes. [`SpzAxes::AsStored`] (the default) reads
//! and writes those files unchanged; [`SpzAxes::Rub`] converts from and to RUB (y and z
//! flipped, the quaternion and SH coefficients with them), for captures exported in RUB.

use crate::placement::flip_axes;
use crate::{Error, ErrorKind, read_file};
use glam::{Quat, Vec3};
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::{Particle, Scene, ScreenFilter};
use std::io::Read;
use std::path::Path;

/// "NGSP", little-endian.
const MAGIC: u32 = 0x5053_474e;
/// Colour scale of the DC term.
const COLOR_SCALE: f32 = 0.15;
/// Bytes of the version 2–3 header (inside the gzip stream).
const LEGACY_HEADER: usize = 16;
/// Bytes of the version 4 header.
const HEADER_V4: usize = 32;
/// Largest SH degree the format stores (this reader keeps up to 3).
const SPZ_MAX_DEGREE: u8 = 4;
/// The header flag of an antialiased capture.
const FLAG_ANTIALIASED: u8 = 0x1;
/// The header flag of a file with extension records (nianticlabs/spz `extensions/`): in
/// version 4 between the header and the table of contents, in versions 2–3 after the attribute
/// arrays inside the gzip stream; each record a u32 type, a u32 byte length and the payload.
const FLAG_EXTENSIONS: u8 = 0x2;
/// Extension types (vendor 0xADBE, Adobe): the axes of the data (a u32, spz's
/// `CoordinateSystem`), and a viewer's safe orbit (three f32: elevation range, least radius).
const EXTENSION_COORDINATE_SYSTEM: u32 = 0xADBE_0003;
const EXTENSION_SAFE_ORBIT_CAMERA: u32 = 0xADBE_0002;
/// Most bytes of extension records read from a version 2–3 gzip stream.
const MAX_LEGACY_EXTENSIONS: usize = 1 << 20;
/// spz's `CoordinateSystem` values 1–8 (0 is unspecified): right or left, up or down, back or
/// front, in x, y, z order. Values 9–16 swap y and z (LBD …), which the reader refuses.
const COORDINATE_SYSTEMS: [&str; 17] = [
    "UNSPECIFIED",
    "LDB",
    "RDB",
    "LUB",
    "RUB",
    "LDF",
    "RDF",
    "LUF",
    "RUF",
    "LBD",
    "RBD",
    "LBU",
    "RBU",
    "LFD",
    "RFD",
    "LFU",
    "RFU",
];

/// Which axes the file's data are in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpzAxes {
    /// The scene's own axes, unconverted (what the spz tools write from a `.ply`).
    #[default]
    AsStored,
    /// Right-up-back: y and z flipped with respect to the 3DGS (OpenCV) axes.
    Rub,
}

/// Options of the writer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzWriteOptions {
    /// Format version, 2, 3 or 4.
    pub version: u32,
    /// Axes to store.
    pub axes: SpzAxes,
}

impl Default for SpzWriteOptions {
    /// Version 3 (gzip, read by every spz reader since 2025), the scene's own axes.
    fn default() -> Self {
        Self { version: 3, axes: SpzAxes::AsStored }
    }
}

fn spz_error(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Spz(message.into())
}

/// Read a `.spz` file.
pub fn read_spz(path: &Path, axes: SpzAxes) -> Result<Scene, Error> {
    let bytes = read_file(path)?;
    parse_spz(&bytes, axes).map_err(|kind| Error::new(path, kind))
}

/// Read a `.spz` file, with what it held beside the splats.
pub fn read_spz_report(path: &Path, axes: SpzAxes) -> Result<SpzRead, Error> {
    let bytes = read_file(path)?;
    parse_spz_report(&bytes, axes).map_err(|kind| Error::new(path, kind))
}

/// Write a scene as `.spz`.
pub fn write_spz(path: &Path, scene: &Scene, options: SpzWriteOptions) -> Result<(), Error> {
    let bytes = encode_spz(scene, options).map_err(|kind| Error::new(path, kind))?;
    std::fs::write(path, bytes).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}

/// The fields of either header.
#[derive(Clone, Copy, Debug)]
struct Header {
    version: u32,
    count: u32,
    sh_degree: u8,
    fractional_bits: u8,
    /// Bit 0x1: antialiased.
    flags: u8,
}

impl Header {
    /// The fields of the first 16 bytes of either header.
    fn at(b: &[u8]) -> Self {
        Header { version: u32_at(b, 4), count: u32_at(b, 8), sh_degree: b[12], fractional_bits: b[13], flags: b[14] }
    }

    fn check(self) -> Result<Self, ErrorKind> {
        if !(2..=4).contains(&self.version) {
            return Err(spz_error(format!(
                "version {} is not supported (this reader handles versions 2, 3 and 4)",
                self.version
            )));
        }
        if self.sh_degree > SPZ_MAX_DEGREE {
            return Err(spz_error(format!("SH degree {} is out of range 0–4", self.sh_degree)));
        }
        if self.fractional_bits > 23 {
            return Err(spz_error(format!("{} fractional bits do not fit 24-bit positions", self.fractional_bits)));
        }
        Ok(self)
    }

    /// Bytes of a rotation.
    fn rotation_bytes(self) -> usize {
        if self.version >= 3 { 4 } else { 3 }
    }

    /// Bytes per splat of each attribute stream, in file order.
    fn stream_strides(self) -> [(&'static str, usize); 6] {
        let sh = 3 * (sh_coeff_count(self.sh_degree) - 1);
        [
            ("positions", 9),
            ("alphas", 1),
            ("colors", 3),
            ("scales", 3),
            ("rotations", self.rotation_bytes()),
            ("sh", sh),
        ]
    }
}

/// The attribute arrays, as stored.
struct Packed {
    header: Header,
    /// positions, alphas, colors, scales, rotations, sh.
    streams: [Vec<u8>; 6],
    /// The extension records' bytes (empty without the flag).
    extensions: Vec<u8>,
}

/// What a `.spz` file held beside its splats.
#[derive(Clone, Debug, PartialEq)]
pub struct SpzRead {
    /// The splats, in the scene's axes: converted from the axes the coordinate-system extension
    /// names, else as [`SpzAxes`] says.
    pub scene: Scene,
    /// The format version.
    pub version: u32,
    /// Notes on the file: the axes an extension named (and the conversion made), extensions
    /// skipped, SH band 4 dropped.
    pub notes: Vec<String>,
}

/// Parse the bytes of a `.spz` file, with what it held beside the splats.
pub fn parse_spz_report(bytes: &[u8], axes: SpzAxes) -> Result<SpzRead, ErrorKind> {
    let packed = match bytes {
        [0x1f, 0x8b, ..] => unpack_legacy(bytes)?,
        [b'N', b'G', b'S', b'P', ..] => unpack_v4(bytes)?,
        _ => return Err(spz_error("not an spz file: neither gzip (1f 8b) nor 'NGSP' at byte 0")),
    };
    let (system, mut notes) = parse_extensions(&packed.extensions)?;
    let signs = match system {
        Some(system) => {
            let signs = axis_signs(system)?;
            notes.push(format!(
                "SPZ_ADOBE_coordinate_system: {} axes, converted to the scene's (RDF, a .ply's)",
                COORDINATE_SYSTEMS[system as usize]
            ));
            signs
        }
        None if axes == SpzAxes::Rub => Vec3::new(1.0, -1.0, -1.0),
        None => Vec3::ONE,
    };
    if packed.header.sh_degree > splat_core::particle::SH_MAX_DEGREE {
        notes.push("SH band 4 dropped (splats here carry degree ≤ 3)".into());
    }
    let scene = decode(&packed, signs)?;
    Ok(SpzRead { scene, version: packed.header.version, notes })
}

/// The coordinate system an extension names, and notes on the records skipped.
fn parse_extensions(mut bytes: &[u8]) -> Result<(Option<u32>, Vec<String>), ErrorKind> {
    let (mut system, mut notes) = (None, Vec::new());
    while !bytes.is_empty() {
        if bytes.len() < 8 {
            return Err(spz_error(format!("{} stray bytes after the extension records", bytes.len())));
        }
        let (kind, len) = (u32_at(bytes, 0), u32_at(bytes, 4) as usize);
        let payload = bytes.get(8..8 + len).ok_or_else(|| {
            spz_error(format!("extension record {kind:#010x} of {len} bytes runs past the {} left", bytes.len() - 8))
        })?;
        match (kind, len) {
            (EXTENSION_COORDINATE_SYSTEM, 4) if system.is_none() => {
                let value = u32_at(payload, 0);
                if value as usize >= COORDINATE_SYSTEMS.len() {
                    return Err(spz_error(format!("coordinate system {value} is not one of spz's 0–16")));
                }
                system = (value != 0).then_some(value);
            }
            (EXTENSION_COORDINATE_SYSTEM, _) => {
                return Err(spz_error("a second or malformed SPZ_ADOBE_coordinate_system record (4 bytes, once)"));
            }
            (EXTENSION_SAFE_ORBIT_CAMERA, 12) => {
                let f = |k: usize| f32::from_le_bytes(payload[4 * k..4 * k + 4].try_into().expect("4 bytes"));
                notes.push(format!(
                    "SPZ_ADOBE_safe_orbit_camera (elevation {}–{}, radius ≥ {}) not used",
                    f(0),
                    f(1),
                    f(2)
                ));
            }
            _ => notes.push(format!("extension {kind:#010x} ({len} bytes) skipped: not known here")),
        }
        bytes = &bytes[8 + len..];
    }
    Ok((system, notes))
}

/// The signs (x, y, z) that take data in spz coordinate system `system` (1–8) to the scene's
/// right-down-front axes (a `.ply`'s): −1 for left, up, back.
fn axis_signs(system: u32) -> Result<Vec3, ErrorKind> {
    let name = COORDINATE_SYSTEMS[system as usize].as_bytes();
    if system > 8 {
        return Err(spz_error(format!(
            "coordinate system {} swaps the y and z axes, which this reader does not convert: convert the \
             file to RDF (a .ply's axes) with the spz library first",
            COORDINATE_SYSTEMS[system as usize]
        )));
    }
    let sign = |b: u8, minus: u8| if b == minus { -1.0 } else { 1.0 };
    Ok(Vec3::new(sign(name[0], b'L'), sign(name[1], b'U'), sign(name[2], b'B')))
}

/// Parse the bytes of a `.spz` file (versions 2, 3: gzip; 4: zstd streams).
pub fn parse_spz(bytes: &[u8], axes: SpzAxes) -> Result<Scene, ErrorKind> {
    parse_spz_report(bytes, axes).map(|read| read.scene)
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// Read exactly `len` bytes of `reader` into a buffer that grows only as data arrive, so that a
/// header claiming billions of splats costs no memory before the data run out.
fn read_stream(reader: impl Read, len: usize, name: &str, count: u32) -> Result<Vec<u8>, ErrorKind> {
    let mut out = Vec::with_capacity(len.min(1 << 24));
    reader
        .take(len as u64)
        .read_to_end(&mut out)
        .map_err(|e| spz_error(format!("decompressing the {name} stream: {e}")))?;
    if out.len() < len {
        return Err(spz_error(format!(
            "the {name} stream ends after {} of {len} bytes: the file is truncated or the header's count \
             ({count} splats) is wrong",
            out.len()
        )));
    }
    Ok(out)
}

fn unpack_legacy(bytes: &[u8]) -> Result<Packed, ErrorKind> {
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let head = read_stream(&mut gz, LEGACY_HEADER, "header", 0)?;
    if u32_at(&head, 0) != MAGIC {
        return Err(spz_error(format!("bad magic {:#010x} in the gzip stream (expected 'NGSP')", u32_at(&head, 0))));
    }
    let header = Header::at(&head).check()?;
    if header.version == 4 {
        return Err(spz_error("version 4 inside a gzip stream: version 4 files start with a plain 'NGSP' header"));
    }
    let mut streams: [Vec<u8>; 6] = Default::default();
    for (stream, (name, stride)) in streams.iter_mut().zip(header.stream_strides()) {
        *stream = read_stream(&mut gz, stride * header.count as usize, name, header.count)?;
    }
    let mut extensions = Vec::new();
    if header.flags & FLAG_EXTENSIONS != 0 {
        gz.take(MAX_LEGACY_EXTENSIONS as u64 + 1)
            .read_to_end(&mut extensions)
            .map_err(|e| spz_error(format!("decompressing the extension records: {e}")))?;
        if extensions.len() > MAX_LEGACY_EXTENSIONS {
            return Err(spz_error(format!("more than {MAX_LEGACY_EXTENSIONS} bytes of extension records")));
        }
    }
    Ok(Packed { header, streams, extensions })
}

fn unpack_v4(bytes: &[u8]) -> Result<Packed, ErrorKind> {
    if bytes.len() < HEADER_V4 {
        return Err(spz_error(format!("{} bytes: shorter than the 32-byte version 4 header", bytes.len())));
    }
    let header = Header::at(bytes).check()?;
    if header.version != 4 {
        return Err(spz_error(format!(
            "a plain 'NGSP' header says version {}: only version 4 is stored so",
            header.version
        )));
    }
    let stream_count = usize::from(bytes[15]);
    let toc = u32_at(bytes, 16) as usize;
    let lengths = header.stream_strides().map(|(name, stride)| (name, stride * header.count as usize));
    let present = lengths.iter().filter(|&&(_, len)| len > 0).count();
    if stream_count != present {
        return Err(spz_error(format!(
            "{stream_count} attribute streams, expected {present} for {} splats of SH degree {}",
            header.count, header.sh_degree
        )));
    }
    let toc_end = toc.checked_add(16 * stream_count).filter(|&e| toc >= HEADER_V4 && e <= bytes.len());
    let Some(mut at) = toc_end else {
        return Err(spz_error(format!("table of contents at byte {toc} lies outside the {}-byte file", bytes.len())));
    };
    let mut streams: [Vec<u8>; 6] = Default::default();
    let entries = (0..stream_count).map(|i| (u64_at(bytes, toc + 16 * i), u64_at(bytes, toc + 16 * i + 8)));
    let wanted = streams.iter_mut().zip(lengths).filter(|(_, (_, len))| *len > 0);
    for ((stream, (name, len)), (compressed, uncompressed)) in wanted.zip(entries) {
        if uncompressed != len as u64 {
            return Err(spz_error(format!(
                "the {name} stream holds {uncompressed} bytes, expected {len} for {} splats",
                header.count
            )));
        }
        let end = (at as u64).checked_add(compressed).filter(|&e| e <= bytes.len() as u64).ok_or_else(|| {
            spz_error(format!("the {name} stream ({compressed} bytes at offset {at}) runs past the end of the file"))
        })? as usize;
        let decoder = ruzstd::decoding::StreamingDecoder::new(&bytes[at..end])
            .map_err(|e| spz_error(format!("the {name} stream is not a zstd frame: {e}")))?;
        *stream = read_stream(decoder, len, name, header.count)?;
        at = end;
    }
    let extensions = if header.flags & FLAG_EXTENSIONS != 0 { bytes[HEADER_V4..toc].to_vec() } else { Vec::new() };
    Ok(Packed { header, streams, extensions })
}

/// RUB's axis signs against a `.ply`'s (y and z flipped: a half turn about x).
const RUB: Vec3 = Vec3::new(1.0, -1.0, -1.0);

/// The splats of `packed`, converted by the axis flips `signs` ([`flip_axes`]); SH bands above
/// degree 3 are dropped.
fn decode(packed: &Packed, signs: Vec3) -> Result<Scene, ErrorKind> {
    let h = packed.header;
    let [positions, alphas, colors, scales, rotations, sh] = &packed.streams;
    let stored = sh_coeff_count(h.sh_degree) - 1;
    let degree = h.sh_degree.min(splat_core::particle::SH_MAX_DEGREE);
    let rest = sh_coeff_count(degree) - 1;
    let unit = 1.0 / (1u32 << h.fractional_bits) as f32;
    let rb = h.rotation_bytes();
    let mut particles = Vec::with_capacity(h.count as usize);
    for i in 0..h.count as usize {
        let fixed = |k: usize| {
            let b = &positions[9 * i + 3 * k..9 * i + 3 * k + 3];
            // Sign-extend 24 bits: place them high in an i32, shift back arithmetically.
            (i32::from_le_bytes([0, b[0], b[1], b[2]]) >> 8) as f32 * unit
        };
        let mean = Vec3::new(fixed(0), fixed(1), fixed(2));
        let scale = Vec3::from_array([0, 1, 2].map(|k| (f32::from(scales[3 * i + k]) / 16.0 - 10.0).exp()));
        let r = &rotations[rb * i..rb * (i + 1)];
        let rotation = if rb == 4 { smallest_three(u32_at(r, 0)) } else { first_three([r[0], r[1], r[2]]) };
        let opacity = f32::from(alphas[i]) / 255.0;
        let mut coeffs = [Vec3::ZERO; SH_MAX_COEFFS];
        coeffs[0] = Vec3::from_array([0, 1, 2].map(|k| (f32::from(colors[3 * i + k]) / 255.0 - 0.5) / COLOR_SCALE));
        for (k, c) in coeffs[1..=rest].iter_mut().enumerate() {
            let at = 3 * (stored * i + k);
            *c = Vec3::from_array([0, 1, 2].map(|ch| (f32::from(sh[at + ch]) - 128.0) / 128.0));
        }
        let mut p = Particle::new(mean, scale, rotation, opacity, coeffs)
            .map_err(|error| ErrorKind::Particle { index: i as u64, error })?;
        flip_axes(&mut p, signs);
        particles.push(p);
    }
    let screen_filter =
        if h.flags & FLAG_ANTIALIASED != 0 { ScreenFilter::Antialiased } else { ScreenFilter::Dilation };
    Ok(Scene { screen_filter, ..Scene::new(particles, degree) })
}

/// Version 2 rotation: x, y, z as (c + 1) × 127.5, w = √(1 − |xyz|²) ≥ 0.
fn first_three(r: [u8; 3]) -> Quat {
    let xyz = Vec3::from_array(r.map(|b| f32::from(b) / 127.5 - 1.0));
    let w = (1.0 - xyz.length_squared()).max(0.0).sqrt();
    Quat::from_xyzw(xyz.x, xyz.y, xyz.z, w).normalize()
}

/// Versions 3–4 rotation: bits 30–31 index the largest of (x, y, z, w) (stored positive); the
/// other three, from the last down, each a sign bit and 9 bits of |c| / √½.
fn smallest_three(mut comp: u32) -> Quat {
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev().filter(|&i| i != largest) {
        let magnitude = (comp & 0x1ff) as f32 / 511.0 * std::f32::consts::FRAC_1_SQRT_2;
        q[i] = if comp & 0x200 != 0 { -magnitude } else { magnitude };
        sum += q[i] * q[i];
        comp >>= 10;
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    Quat::from_array(q).normalize()
}

/// Largest fractional-bit count (≤ 12, the spz library's choice) whose 24-bit range holds every
/// coordinate.
fn fractional_bits(scene: &Scene) -> Result<u8, ErrorKind> {
    let extent = scene.particles.iter().map(|p| p.mean.abs().max_element()).fold(0.0f32, f32::max);
    (0..=12u8)
        .rev()
        .find(|&bits| (extent * (1u32 << bits) as f32).round() < (1 << 23) as f32)
        .ok_or_else(|| spz_error(format!("a coordinate of magnitude {extent} exceeds the 24-bit range (±8,388,607)")))
}

fn to_u8(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// The spz library's SH quantisation: 8 bits, rounded to the centre of a bucket of
/// 2^(8 − bits) steps.
fn quantize_sh(x: f32, bits: u32) -> u8 {
    let bucket = 1i32 << (8 - bits);
    let q = (x * 128.0).round() as i32 + 128;
    ((q + bucket / 2) / bucket * bucket).clamp(0, 255) as u8
}

fn pack_first_three(q: Quat) -> [u8; 3] {
    let q = if q.w < 0.0 { -q } else { q };
    [q.x, q.y, q.z].map(|c| to_u8(c * 127.5 + 127.5))
}

fn pack_smallest_three(q: Quat) -> [u8; 4] {
    let q = q.to_array();
    let largest = (1..4).fold(0, |l, i| if q[i].abs() > q[l].abs() { i } else { l });
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (_, &c) in q.iter().enumerate().filter(|&(i, _)| i != largest) {
        let sign = u32::from((c < 0.0) != negate);
        let magnitude = (511.0 * (c.abs() / std::f32::consts::FRAC_1_SQRT_2) + 0.5) as u32;
        comp = (comp << 10) | (sign << 9) | magnitude.min(511);
    }
    comp.to_le_bytes()
}

/// Encode a scene as `.spz` (see the module documentation for the quantisation).
pub fn encode_spz(scene: &Scene, options: SpzWriteOptions) -> Result<Vec<u8>, ErrorKind> {
    if !(2..=4).contains(&options.version) {
        return Err(spz_error(format!("cannot write version {} (choose 2, 3 or 4)", options.version)));
    }
    let count = u32::try_from(scene.particles.len())
        .map_err(|_| spz_error(format!("{} splats exceed the format's 32-bit count", scene.particles.len())))?;
    let flags = match crate::SceneFormat::Spz.records(scene.screen_filter) {
        ScreenFilter::Antialiased => FLAG_ANTIALIASED,
        _ => 0,
    };
    let fractional_bits = fractional_bits(scene)?;
    let header = Header { version: options.version, count, sh_degree: scene.sh_degree, fractional_bits, flags };
    let streams = pack(scene, header, options.axes);
    Ok(if options.version == 4 { container_v4(header, &streams) } else { container_legacy(header, &streams) })
}

fn pack(scene: &Scene, h: Header, axes: SpzAxes) -> [Vec<u8>; 6] {
    let rest = sh_coeff_count(h.sh_degree) - 1;
    let mut s: [Vec<u8>; 6] = Default::default();
    let unit = (1u32 << h.fractional_bits) as f32;
    for p in &scene.particles {
        let mut p = p.clone();
        if axes == SpzAxes::Rub {
            flip_axes(&mut p, RUB);
        }
        for c in p.mean.to_array() {
            s[0].extend_from_slice(&((c * unit).round() as i32).to_le_bytes()[..3]);
        }
        s[1].push(to_u8(p.opacity * 255.0));
        s[2].extend(p.sh[0].to_array().map(|c| to_u8(c * COLOR_SCALE * 255.0 + 127.5)));
        s[3].extend(p.scale.to_array().map(|v| to_u8((v.ln() + 10.0) * 16.0)));
        let q = p.rotation.normalize();
        if h.version >= 3 {
            s[4].extend(pack_smallest_three(q));
        } else {
            s[4].extend(pack_first_three(q));
        }
        for (k, c) in (1..=rest).map(|k| p.sh[k]).enumerate() {
            let bits = if k < 3 { 5 } else { 4 };
            s[5].extend(c.to_array().map(|v| quantize_sh(v, bits)));
        }
    }
    s
}

fn container_legacy(h: Header, streams: &[Vec<u8>; 6]) -> Vec<u8> {
    let mut raw = Vec::with_capacity(LEGACY_HEADER + streams.iter().map(Vec::len).sum::<usize>());
    raw.extend(MAGIC.to_le_bytes());
    raw.extend(h.version.to_le_bytes());
    raw.extend(h.count.to_le_bytes());
    raw.extend([h.sh_degree, h.fractional_bits, h.flags, 0]);
    streams.iter().for_each(|s| raw.extend(s));
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut gz, &raw).expect("writing to memory");
    gz.finish().expect("writing to memory")
}

/// The zstd level of the v4 streams: splat-transform's, whose v4 file of the interop fixture's
/// splats (target/interop) this writer reproduces byte for byte at it (85,708 bytes;
/// `spz_v4_is_the_reference_writers_file`), where ruzstd's encoder (its one level, about
/// zstd's 1) wrote 116,268 and libzstd's default level 3 would write 88,457.
const SPZ_ZSTD_LEVEL: i32 = 12;

fn container_v4(h: Header, streams: &[Vec<u8>; 6]) -> Vec<u8> {
    let present: Vec<&Vec<u8>> = streams.iter().filter(|s| !s.is_empty()).collect();
    let compressed: Vec<Vec<u8>> = present
        .iter()
        .map(|s| zstd::bulk::compress(s.as_slice(), SPZ_ZSTD_LEVEL).expect("compressing in memory"))
        .collect();
    let mut out = Vec::new();
    out.extend(MAGIC.to_le_bytes());
    out.extend(h.version.to_le_bytes());
    out.extend(h.count.to_le_bytes());
    out.extend([h.sh_degree, h.fractional_bits, h.flags, present.len() as u8]);
    out.extend((HEADER_V4 as u32).to_le_bytes());
    out.extend([0u8; 12]);
    for (raw, packed) in present.iter().zip(&compressed) {
        out.extend((packed.len() as u64).to_le_bytes());
        out.extend((raw.len() as u64).to_le_bytes());
    }
    compressed.iter().for_each(|c| out.extend(c));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smallest_three_round_trips_within_its_step() {
        for (i, axis) in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(1.0, -2.0, 0.5).normalize()].into_iter().enumerate() {
            for angle in [0.0f32, 0.3, -1.2, 2.9, 3.1] {
                let q = Quat::from_axis_angle(axis, angle + i as f32 * 0.1);
                let back = smallest_three(u32::from_le_bytes(pack_smallest_three(q)));
                assert!(q.dot(back).abs() > 1.0 - 1e-5, "{q:?} → {back:?}");
                // Version 2 loses w near 0 (tests/tests/formats.rs derives the 0.234 rad bound).
                let back2 = first_three(pack_first_three(q));
                assert!(2.0 * q.dot(back2).abs().min(1.0).acos() < 0.234, "{q:?} → {back2:?}");
            }
        }
    }

    #[test]
    fn sh_quantisation_matches_the_spz_library() {
        // quantizeSH(x, bucket): round(x·128) + 128, then to the bucket's centre.
        assert_eq!(quantize_sh(0.0, 5), 128);
        assert_eq!(quantize_sh(0.0, 4), 128);
        assert_eq!(quantize_sh(0.1, 8), 141);
        assert_eq!(quantize_sh(0.1, 5), 144);
        assert_eq!(quantize_sh(-1.0, 4), 0);
        assert_eq!(quantize_sh(1.0, 4), 255);
    }

    /// Every axis flip of spz's coordinate systems 1–8 (half turns and mirrors) maps the mean,
    /// the covariance and the radiance of a particle as the flip matrix S maps space
    /// ([`crate::placement::check::assert_placed`]).
    #[test]
    fn axis_flips_map_mean_covariance_and_radiance() {
        let p = crate::placement::check::particle();
        for system in 1..=8u32 {
            let s = axis_signs(system).unwrap();
            let mut flipped = p.clone();
            flip_axes(&mut flipped, s);
            let m = glam::Mat4::from_scale(s);
            crate::placement::check::assert_placed(&p, &flipped, m, 1e-5, COORDINATE_SYSTEMS[system as usize]);
        }
        assert_eq!(axis_signs(4).unwrap(), RUB);
        assert!(axis_signs(9).unwrap_err().to_string().contains("LBD"));
    }
}
