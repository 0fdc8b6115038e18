//! mkkellogg's `.ksplat`: the `SplatBuffer` of GaussianSplats3D (version 0.1, what its
//! `util/create-ksplat.js` and `SplatBufferGenerator` write), read.
//!
//! All values little-endian. A 4096-byte header, then one 1024-byte header per section (up to
//! the header's section capacity), then each section's data in turn.
//!
//! | header offset | content |
//! |---|---|
//! | 0, 1 | version major, minor (u8: 0, 1) |
//! | 4, 8 | section capacity, sections (u32) |
//! | 12, 16 | splat capacity, splats (u32) |
//! | 20 | compression level (u16: 0, 1 or 2) |
//! | 24 | scene centre (3 × f32; not needed to decode) |
//! | 36, 40 | SH range of level 2, min and max (f32; 0 stands for ∓1.5) |
//!
//! | section header offset | content |
//! |---|---|
//! | 0, 4 | splats, splat capacity (u32) |
//! | 8, 12 | bucket capacity, buckets (u32) |
//! | 16 | bucket block size (f32) |
//! | 20 | bytes per bucket (u16: 12, its centre as 3 × f32) |
//! | 24 | position range R (u32; 0 stands for the level's 1 or 32767) |
//! | 32, 36 | full buckets, partly filled buckets (u32) |
//! | 40 | SH degree (u16: 0–2) |
//!
//! A section's data: the sizes of its partly filled buckets (u32 each), the bucket centres,
//! then `capacity` splats of a fixed size. Splats fill the full buckets in order (bucket
//! capacity each), then the partly filled ones by their sizes.
//!
//! | per splat | level 0 | levels 1, 2 |
//! |---|---|---|
//! | position | 3 × f32 | 3 × u16 u: (u − R) · (block / 2) / R + the bucket centre |
//! | scale (linear) | 3 × f32 | 3 × f16 |
//! | rotation w, x, y, z | 4 × f32 | 4 × f16 |
//! | colour, opacity | 4 × u8: ⌊255 (½ + C₀ f_dc)⌋, ⌊255 α⌋ | the same |
//! | SH bands 1–2 | f32 | f16 (level 1); u8 v: min + v/255 (max − min) (level 2) |
//!
//! The SH components go band by band, channel-major within a band: band 1 as the three
//! coefficients of red, green, then blue (9 values), band 2 likewise (15). The format has no
//! band 3 (GaussianSplats3D 0.4.7 writes at most degree 2), no render mode (scenes read use the
//! 3DGS dilation) and keeps the `.ply`'s axes.
//!
//! The reference writer rounds f16 by three.js's `toHalfFloat`, which truncates the mantissa
//! (up to an ulp, 2⁻¹⁰ relative, where rounding would cost half), and floors colour, opacity and
//! 8-bit SH. Decoding follows the reference reader's arithmetic (GaussianSplats3D's `SplatBuffer`):
//! colour c/255 and opacity a/255 (the writer's floor costs up to one step of 1/255), SH level 2
//! min + v/255 (max − min) (its floor costs up to one step). A scale that is 0 in the file (a
//! log scale under about −17 underflows f16) is read as the least positive f16, 2⁻²⁴, with a
//! note: the Gaussian needs a positive scale, and this is the nearest the file can say.

use crate::{Error, ErrorKind, read_file};
use glam::{Quat, Vec3};
use splat_core::particle::SH_MAX_COEFFS;
use splat_core::sh::rgb_to_dc;
use splat_core::{Particle, Scene};
use std::path::Path;

/// Bytes of the file header.
const HEADER: usize = 4096;
/// Bytes of a section header.
const SECTION_HEADER: usize = 1024;
/// Bytes of a bucket's stored centre.
const BUCKET_CENTRE: usize = 12;
/// The SH range of level 2 when the header stores 0: ±3 / 2 (the reference's
/// `SphericalHarmonics8BitCompressionRange` halved).
const DEFAULT_SH_HALF_RANGE: f32 = 1.5;
/// The least positive f16, what a scale the file stores as 0 is read as.
const LEAST_F16: f32 = 5.960_464_5e-8;
/// The largest SH degree the format defines.
const MAX_DEGREE: u8 = 2;

/// What the reader made of a `.ksplat` file.
#[derive(Clone, Debug)]
pub struct KsplatRead {
    /// The scene.
    pub scene: Scene,
    /// The compression level: 0 (f32), 1 (f16, 16-bit positions) or 2 (level 1 with 8-bit SH).
    pub compression_level: u8,
    /// Sections in the file.
    pub sections: usize,
    /// What the user should hear of (scales read as the least f16).
    pub notes: Vec<String>,
}

impl KsplatRead {
    /// The format detail `splat info` prints.
    pub fn describe(&self) -> String {
        let what = ["f32", "f16", "f16, 8-bit SH"][usize::from(self.compression_level)];
        format!("version 0.1, compression level {} ({what}), {} section(s)", self.compression_level, self.sections)
    }
}

fn bad(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Ksplat(message.into())
}

/// Read a `.ksplat` file.
pub fn read_ksplat(path: &Path) -> Result<KsplatRead, Error> {
    parse_ksplat(&read_file(path)?).map_err(|kind| Error::new(path, kind))
}

/// Little-endian fields at byte offsets of a slice the caller has bounds-checked.
struct Fields<'a>(&'a [u8]);

impl Fields<'_> {
    fn u16(&self, at: usize) -> u16 {
        u16::from_le_bytes([self.0[at], self.0[at + 1]])
    }
    fn u32(&self, at: usize) -> u32 {
        u32::from_le_bytes([self.0[at], self.0[at + 1], self.0[at + 2], self.0[at + 3]])
    }
    fn f32(&self, at: usize) -> f32 {
        f32::from_bits(self.u32(at))
    }
    fn f16(&self, at: usize) -> f32 {
        half::f16::from_bits(self.u16(at)).to_f32()
    }
}

/// The per-level layout of a splat.
#[derive(Clone, Copy)]
struct Level {
    level: u8,
    /// Bytes of a position, scale and rotation component (f32 at level 0, u16/f16 above).
    component: usize,
    /// Bytes of an SH component.
    sh_component: usize,
    /// The position range R when a section stores 0.
    default_range: u32,
}

impl Level {
    fn new(level: u16) -> Result<Self, ErrorKind> {
        match level {
            0 => Ok(Self { level: 0, component: 4, sh_component: 4, default_range: 1 }),
            1 => Ok(Self { level: 1, component: 2, sh_component: 2, default_range: 32767 }),
            2 => Ok(Self { level: 2, component: 2, sh_component: 1, default_range: 32767 }),
            _ => Err(bad(format!("compression level {level} is not one of the format's 0, 1, 2"))),
        }
    }

    /// Bytes of one splat at SH degree `degree`: position, scale, rotation, RGBA, SH.
    fn bytes_per_splat(self, degree: u8) -> usize {
        10 * self.component + 4 + sh_components(degree) * self.sh_component
    }

    /// A position, scale or rotation component `k` of the splat at `at`.
    fn float(self, data: &Fields, at: usize, k: usize) -> f32 {
        if self.level == 0 { data.f32(at + 4 * k) } else { data.f16(at + 2 * k) }
    }
}

/// SH components a splat stores at `degree`: 3 ((d + 1)² − 1).
fn sh_components(degree: u8) -> usize {
    3 * ((usize::from(degree) + 1).pow(2) - 1)
}

/// The SH coefficient (1-based within the 16, DC being 0) and channel of stored component `k`:
/// band by band, channel-major within a band.
fn sh_slot(k: usize) -> (usize, usize) {
    if k < 9 { (1 + k % 3, k / 3) } else { (4 + (k - 9) % 5, (k - 9) / 5) }
}

/// A section header, checked against the file.
struct Section {
    splats: usize,
    capacity: usize,
    degree: u8,
    bucket_capacity: usize,
    full_buckets: usize,
    /// Sizes of the partly filled buckets, in order.
    partial_sizes: Vec<usize>,
    /// Bucket centres.
    centres: Vec<Vec3>,
    /// (block size / 2) / R and R.
    step: f32,
    range: f32,
    /// Byte offset of the first splat.
    data: usize,
    /// Bytes of this section's data (buckets and splats).
    size: usize,
}

fn section(bytes: &[u8], index: usize, at: usize, base: usize, level: Level) -> Result<Section, ErrorKind> {
    let h = Fields(&bytes[at..at + SECTION_HEADER]);
    let named = |message: String| bad(format!("section {index}: {message}"));
    let (splats, capacity) = (h.u32(0) as usize, h.u32(4) as usize);
    if splats > capacity {
        return Err(named(format!("holds {splats} splats but has room for {capacity}")));
    }
    let degree = u8::try_from(h.u16(40)).unwrap_or(u8::MAX);
    if degree > MAX_DEGREE {
        return Err(named(format!(
            "SH degree {} is beyond the format's {MAX_DEGREE} (GaussianSplats3D writes bands 1 and 2 only)",
            h.u16(40)
        )));
    }
    let (bucket_capacity, buckets, block) = (h.u32(8) as usize, h.u32(12) as usize, h.f32(16));
    let (full_buckets, partial) = (h.u32(32) as usize, h.u32(36) as usize);
    let bucket_bytes = usize::from(h.u16(20));
    let range = match h.u32(24) {
        0 => level.default_range,
        r => r,
    };
    // The layout as the reference computes it, whatever the level: the partly filled buckets'
    // sizes, the bucket records, the splats.
    let buckets_size = 4 * partial as u128 + (bucket_bytes as u128) * (buckets as u128);
    let size = buckets_size + (level.bytes_per_splat(degree) as u128) * (capacity as u128);
    if base as u128 + size > bytes.len() as u128 {
        return Err(named(format!(
            "its {size} bytes of data at offset {base} run past the end of the file ({} bytes): the file is truncated",
            bytes.len()
        )));
    }
    let (size, data) = (size as usize, base + buckets_size as usize);
    let mut centres = Vec::new();
    let mut partial_sizes = Vec::new();
    if level.level > 0 && splats > 0 {
        if bucket_bytes != BUCKET_CENTRE {
            return Err(named(format!("{bucket_bytes} bytes a bucket; the format stores a centre in {BUCKET_CENTRE}")));
        }
        if !(block.is_finite() && block > 0.0) {
            return Err(named(format!("bucket block size {block} is not a positive number")));
        }
        if full_buckets.checked_add(partial) != Some(buckets) {
            return Err(named(format!("{buckets} buckets, but {full_buckets} full and {partial} partly filled ones")));
        }
        let d = Fields(bytes);
        partial_sizes = (0..partial).map(|b| d.u32(base + 4 * b) as usize).collect();
        let at = base + 4 * partial;
        centres = (0..buckets)
            .map(|b| Vec3::new(d.f32(at + 12 * b), d.f32(at + 12 * b + 4), d.f32(at + 12 * b + 8)))
            .collect();
        let held =
            (full_buckets as u128) * (bucket_capacity as u128) + partial_sizes.iter().map(|&s| s as u128).sum::<u128>();
        if held < splats as u128 {
            return Err(named(format!("its buckets hold {held} splats, fewer than its {splats}")));
        }
        if let Some(b) = centres.iter().position(|c| !c.is_finite()) {
            return Err(named(format!("bucket {b}'s centre {:?} is not finite", centres[b])));
        }
    }
    let (step, range) = (block / 2.0 / range as f32, range as f32);
    Ok(Section {
        splats,
        capacity,
        degree,
        bucket_capacity,
        full_buckets,
        partial_sizes,
        centres,
        step,
        range,
        data,
        size,
    })
}

impl Section {
    /// The bucket of each splat, in order (empty at level 0).
    fn buckets(&self) -> Vec<usize> {
        if self.centres.is_empty() {
            return Vec::new();
        }
        let full = self.full_buckets * self.bucket_capacity;
        let mut out = Vec::with_capacity(self.splats);
        out.extend((0..self.splats.min(full)).map(|i| i / self.bucket_capacity.max(1)));
        for (b, &size) in self.partial_sizes.iter().enumerate() {
            let room = self.splats.saturating_sub(out.len());
            out.extend(std::iter::repeat_n(self.full_buckets + b, size.min(room)));
        }
        out
    }
}

/// Parse the bytes of a `.ksplat` file.
pub fn parse_ksplat(bytes: &[u8]) -> Result<KsplatRead, ErrorKind> {
    if bytes.len() < HEADER {
        return Err(bad(format!(
            "{} bytes is shorter than the format's {HEADER}-byte header: not a .ksplat file, or truncated",
            bytes.len()
        )));
    }
    let h = Fields(&bytes[..HEADER]);
    let (major, minor) = (bytes[0], bytes[1]);
    if major != 0 || minor < 1 {
        return Err(bad(format!(
            "version {major}.{minor}; this reader reads version 0.1, what GaussianSplats3D writes (re-export it with its create-ksplat.js)"
        )));
    }
    let (section_capacity, splats) = (h.u32(4) as usize, h.u32(16) as usize);
    let level = Level::new(h.u16(20))?;
    let sh_min = match h.f32(36) {
        0.0 => -DEFAULT_SH_HALF_RANGE,
        v => v,
    };
    let sh_max = match h.f32(40) {
        0.0 => DEFAULT_SH_HALF_RANGE,
        v => v,
    };
    if level.level == 2 && !(sh_min.is_finite() && sh_max.is_finite() && sh_min < sh_max) {
        return Err(bad(format!("the 8-bit SH range [{sh_min}, {sh_max}] is not an interval")));
    }
    let headers_end = HEADER as u128 + (section_capacity as u128) * SECTION_HEADER as u128;
    if headers_end > bytes.len() as u128 {
        return Err(bad(format!(
            "the header declares {section_capacity} sections whose headers end at byte {headers_end}, past the end of the file ({} bytes)",
            bytes.len()
        )));
    }
    let mut sections = Vec::with_capacity(section_capacity);
    let mut base = headers_end as usize;
    for index in 0..section_capacity {
        let s = section(bytes, index, HEADER + index * SECTION_HEADER, base, level)?;
        base += s.size;
        sections.push(s);
    }
    let total: u128 = sections.iter().map(|s| s.splats as u128).sum();
    if total != splats as u128 {
        return Err(bad(format!("the header declares {splats} splats but its sections hold {total}")));
    }
    if splats == 0 {
        return Err(bad("the file holds no splats"));
    }
    let degree = sections.iter().map(|s| s.degree).max().unwrap_or(0);
    let mut particles = Vec::with_capacity(splats);
    let mut underflows = 0usize;
    let sh = ShDecode { level, min: sh_min, max: sh_max };
    for s in &sections {
        let buckets = s.buckets();
        let stride = level.bytes_per_splat(s.degree);
        for i in 0..s.splats.min(s.capacity) {
            let index = particles.len() as u64;
            let at = s.data + i * stride;
            let (p, zeros) = decode(bytes, at, level, s, buckets.get(i).copied(), sh, index)?;
            underflows += zeros;
            particles.push(p);
        }
    }
    let mut notes = Vec::new();
    if underflows > 0 {
        notes.push(format!(
            "{underflows} scale component(s) stored as 0 (f16 underflow) read as the least positive f16, {LEAST_F16:e}"
        ));
    }
    Ok(KsplatRead {
        scene: Scene::new(particles, degree),
        compression_level: level.level,
        sections: sections.iter().filter(|s| s.splats > 0).count(),
        notes,
    })
}

/// How a level stores SH components.
#[derive(Clone, Copy)]
struct ShDecode {
    level: Level,
    min: f32,
    max: f32,
}

impl ShDecode {
    fn value(self, d: &Fields, at: usize) -> f32 {
        match self.level.level {
            0 => d.f32(at),
            1 => d.f16(at),
            _ => self.min + f32::from(d.0[at]) / 255.0 * (self.max - self.min),
        }
    }
}

/// Decode splat `index` at byte `at`; also the number of its scale components stored as 0.
fn decode(
    bytes: &[u8],
    at: usize,
    level: Level,
    s: &Section,
    bucket: Option<usize>,
    sh_decode: ShDecode,
    index: u64,
) -> Result<(Particle, usize), ErrorKind> {
    let d = Fields(bytes);
    let c = level.component;
    let mean = if level.level == 0 {
        Vec3::new(d.f32(at), d.f32(at + 4), d.f32(at + 8))
    } else {
        let u = Vec3::new(f32::from(d.u16(at)), f32::from(d.u16(at + 2)), f32::from(d.u16(at + 4)));
        (u - Vec3::splat(s.range)) * s.step + bucket.map_or(Vec3::ZERO, |b| s.centres[b])
    };
    let mut zeros = 0;
    let mut scale = Vec3::ZERO;
    for (k, names) in ["scale_0", "scale_1", "scale_2"].into_iter().enumerate() {
        let v = level.float(&d, at + 3 * c, k);
        if !v.is_finite() {
            return Err(ErrorKind::NonFinite { index, property: names.into(), value: f64::from(v) });
        }
        scale[k] = match v {
            0.0 => {
                zeros += 1;
                LEAST_F16
            }
            v => v,
        };
    }
    let q: [f32; 4] = std::array::from_fn(|k| level.float(&d, at + 6 * c, k));
    if q.iter().any(|v| !v.is_finite()) {
        return Err(ErrorKind::NonFinite { index, property: "rotation".into(), value: f64::NAN });
    }
    if q.iter().all(|&v| v == 0.0) {
        return Err(ErrorKind::ZeroQuaternion { index });
    }
    let rgba = &bytes[at + 10 * c..at + 10 * c + 4];
    let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
    sh[0] = rgb_to_dc(Vec3::new(f32::from(rgba[0]), f32::from(rgba[1]), f32::from(rgba[2])) / 255.0);
    let sh_at = at + 10 * c + 4;
    for k in 0..sh_components(s.degree) {
        let (coefficient, channel) = sh_slot(k);
        let v = sh_decode.value(&d, sh_at + k * level.sh_component);
        if !v.is_finite() {
            return Err(ErrorKind::NonFinite { index, property: format!("SH component {k}"), value: f64::from(v) });
        }
        sh[coefficient][channel] = v;
    }
    let rotation = Quat::from_xyzw(q[1], q[2], q[3], q[0]);
    let opacity = f32::from(rgba[3]) / 255.0;
    let p = Particle::new(mean, scale, rotation, opacity, sh).map_err(|error| ErrorKind::Particle { index, error })?;
    Ok((p, zeros))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sh_components_go_band_by_band_channel_major() {
        // Band 1: red 1–3, green 1–3, blue 1–3; band 2: red 4–8, green 4–8, blue 4–8.
        let slots: Vec<_> = (0..24).map(sh_slot).collect();
        assert_eq!(&slots[..4], &[(1, 0), (2, 0), (3, 0), (1, 1)]);
        assert_eq!(slots[8], (3, 2));
        assert_eq!(&slots[9..11], &[(4, 0), (5, 0)]);
        assert_eq!(slots[14], (4, 1));
        assert_eq!(slots[23], (8, 2));
        let mut seen = slots.clone();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), 24, "every (coefficient, channel) of bands 1–2 once");
    }

    #[test]
    fn bytes_per_splat_match_the_reference_table() {
        // GaussianSplats3D's SplatBuffer.CompressionLevels[level].SphericalHarmonicsDegrees.
        let table = [[44, 80, 140], [24, 42, 72], [24, 33, 48]];
        for (level, row) in table.iter().enumerate() {
            let l = Level::new(level as u16).unwrap();
            for (degree, &bytes) in row.iter().enumerate() {
                assert_eq!(l.bytes_per_splat(degree as u8), bytes, "level {level}, degree {degree}");
            }
        }
    }
}
