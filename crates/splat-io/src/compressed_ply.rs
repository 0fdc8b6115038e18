//! PlayCanvas / SuperSplat compressed `.ply` (`*.compressed.ply`), read only.
//!
//! Binary little-endian, three elements:
//!
//! - `chunk`, one per 256 splats: `min_x … max_z`, `min_scale_x … max_scale_z` (log scales)
//!   and optionally `min_r … max_b` (colour bounds), all `float`;
//! - `vertex`: four `uint` per splat: `packed_position` (x 11, y 10, z 11 bits, from the high
//!   bits down, each a fraction of its chunk's range), `packed_rotation` (bits 30–31: which of
//!   w, x, y, z is largest and dropped; then three 10-bit components, (c/√½ + 1)/2),
//!   `packed_scale` (11-10-11 like the position, in log scale), `packed_color` (r, g, b, opacity,
//!   8 bits each from the high byte down; r, g, b are `SH_C0 · dc + ½` within the chunk's colour
//!   range, opacity is linear);
//! - optional `sh`: `uchar f_rest_0 …` (9, 24 or 45, channel-major as in the 3DGS `.ply`), each
//!   byte a coefficient in [−4, 4] (see `sh_byte`).
//!
//! The decoding follows splat-transform 3.7 (`readCompressedChunked`), which wrote the files.

use crate::ErrorKind;
use crate::ply::{Lines, Scalar};
use glam::{Quat, Vec3};
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::sh::SH_C0;
use splat_core::{Particle, Scene};

/// Splats per chunk.
pub const CHUNK: usize = 256;

fn error(message: impl Into<String>) -> ErrorKind {
    ErrorKind::CompressedPly(message.into())
}

/// One element of a PLY header: name, count and (type, name) properties.
#[derive(Debug)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) properties: Vec<(Scalar, String)>,
}

impl Element {
    fn stride(&self) -> usize {
        self.properties.iter().map(|(t, _)| t.size()).sum()
    }

    /// Byte offset of `name` in a record, if the element has it with type `ty`.
    fn offset(&self, name: &str, ty: Scalar) -> Result<usize, ErrorKind> {
        let mut at = 0;
        for (t, n) in &self.properties {
            if n == name {
                return if *t == ty {
                    Ok(at)
                } else {
                    Err(error(format!("property '{name}' of element '{}' is {t:?}, expected {ty:?}", self.name)))
                };
            }
            at += t.size();
        }
        Err(error(format!("element '{}' has no property '{name}'", self.name)))
    }
}

/// The elements of a binary little-endian PLY header and the offset of its body, or `None`
/// when the first element is not `chunk` (an ordinary `.ply`).
pub(crate) fn sniff(bytes: &[u8]) -> Result<Option<(Vec<Element>, usize)>, ErrorKind> {
    let mut lines = Lines::new(bytes, 0);
    if lines.next().is_none_or(|(_, first)| first.trim() != "ply") {
        return Ok(None);
    }
    let mut elements: Vec<Element> = Vec::new();
    let mut little_endian = false;
    let mut ended = false;
    while let Some((_, text)) = lines.next() {
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => {
                ended = true;
                break;
            }
            ["format", f, _] => little_endian = *f == "binary_little_endian",
            ["element", name, n] => {
                if elements.is_empty() && *name != "chunk" {
                    return Ok(None);
                }
                let count = n.parse().map_err(|_| error(format!("element '{name}' count '{n}' is not a number")))?;
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            ["property", ..] if elements.is_empty() => return Ok(None),
            ["property", ty, name] => {
                let ty = Scalar::from_name(ty).ok_or_else(|| error(format!("unknown property type '{ty}'")))?;
                let element = elements.last_mut().expect("an element is open");
                element.properties.push((ty, name.to_string()));
            }
            ["property", ..] => return Err(error("list properties are not part of the compressed format")),
            _ => {}
        }
        if lines.offset > 1 << 20 {
            break;
        }
    }
    if elements.is_empty() {
        return Ok(None);
    }
    if !ended {
        return Err(error("no end_header line within the first MiB"));
    }
    if !little_endian {
        return Err(error("the compressed format is binary_little_endian only"));
    }
    Ok(Some((elements, lines.offset)))
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// `value`'s low `bits` bits as a fraction in [0, 1].
fn unorm(value: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    (value & max) as f32 / max as f32
}

/// An 11-10-11 packed vector, each component a fraction.
fn unpack_111011(v: u32) -> Vec3 {
    Vec3::new(unorm(v >> 21, 11), unorm(v >> 11, 10), unorm(v, 11))
}

fn lerp(min: Vec3, max: Vec3, t: Vec3) -> Vec3 {
    min * (Vec3::ONE - t) + max * t
}

/// A packed rotation: the dropped (largest) component is √(1 − Σ others²).
fn unpack_rotation(v: u32) -> Quat {
    let norm = std::f32::consts::SQRT_2; // 1 / (√2 · ½)
    let c = [unorm(v >> 20, 10), unorm(v >> 10, 10), unorm(v, 10)].map(|t| (t - 0.5) * norm);
    let m = (1.0 - c.iter().map(|x| x * x).sum::<f32>()).max(0.0).sqrt();
    let [w, x, y, z] = match v >> 30 {
        0 => [m, c[0], c[1], c[2]],
        1 => [c[0], m, c[1], c[2]],
        2 => [c[0], c[1], m, c[2]],
        _ => [c[0], c[1], c[2], m],
    };
    Quat::from_xyzw(x, y, z, w).normalize()
}

/// An SH byte: 0 and 255 are the range's ends, others the centre of their 1/256 bin; the
/// coefficient is (t − ½) · 8.
fn sh_byte(b: u8) -> f32 {
    let t = match b {
        0 => 0.0,
        255 => 1.0,
        b => (f32::from(b) + 0.5) / 256.0,
    };
    (t - 0.5) * 8.0
}

/// Bounds of one chunk.
struct Bounds {
    position: (Vec3, Vec3),
    scale: (Vec3, Vec3),
    color: Option<(Vec3, Vec3)>,
}

const BOUND_NAMES: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];

fn read_bounds(chunk: &Element, body: &[u8]) -> Result<Vec<Bounds>, ErrorKind> {
    let has_color = chunk.properties.iter().any(|(_, n)| n == "min_r");
    let names = if has_color { &BOUND_NAMES[..] } else { &BOUND_NAMES[..12] };
    let offsets = names.iter().map(|n| chunk.offset(n, Scalar::F32)).collect::<Result<Vec<_>, _>>()?;
    let stride = chunk.stride();
    (0..chunk.count as usize)
        .map(|c| {
            let record = &body[c * stride..(c + 1) * stride];
            let v: Vec<f32> = offsets.iter().map(|&o| f32_at(record, o)).collect();
            if let Some((k, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                return Err(error(format!("chunk {c}: {} is {x}, not a finite number", names[k])));
            }
            let vec = |i: usize| Vec3::new(v[i], v[i + 1], v[i + 2]);
            Ok(Bounds {
                position: (vec(0), vec(3)),
                scale: (vec(6), vec(9)),
                color: has_color.then(|| (vec(12), vec(15))),
            })
        })
        .collect()
}

/// Decode a compressed `.ply` whose header [`sniff`] returned.
pub(crate) fn parse(bytes: &[u8], elements: &[Element], body_offset: usize) -> Result<Scene, ErrorKind> {
    let find = |name: &str| elements.iter().find(|e| e.name == name);
    let chunk = find("chunk").ok_or_else(|| error("no 'chunk' element"))?;
    let vertex = find("vertex").ok_or_else(|| error("no 'vertex' element after 'chunk'"))?;
    let sh = find("sh");
    if let Some(other) = elements.iter().find(|e| !["chunk", "vertex", "sh"].contains(&e.name.as_str())) {
        return Err(error(format!("unexpected element '{}' (expected chunk, vertex and optionally sh)", other.name)));
    }
    let count = vertex.count as usize;
    if chunk.count as usize != count.div_ceil(CHUNK) {
        return Err(error(format!(
            "{} chunks for {count} splats: expected ⌈{count}/256⌉ = {}",
            chunk.count,
            count.div_ceil(CHUNK)
        )));
    }
    if let Some(e) = sh.filter(|e| e.count != vertex.count) {
        return Err(error(format!("{} SH records for {count} splats", e.count)));
    }
    let rest = sh.map_or(0, |e| e.properties.len());
    let sh_degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => return Err(error(format!("{n} SH properties: expected 9, 24 or 45"))),
    };
    // Element bodies follow one another in header order.
    let mut at = body_offset as u128;
    let mut starts = Vec::new();
    for e in elements {
        starts.push(at as usize);
        at += u128::from(e.count) * e.stride() as u128;
    }
    if at > bytes.len() as u128 {
        return Err(error(format!(
            "the header's elements need {} bytes after the header but only {} follow: the file is truncated",
            at - body_offset as u128,
            bytes.len() - body_offset
        )));
    }
    let body_of = |e: &Element| &bytes[starts[elements.iter().position(|x| x.name == e.name).expect("listed")]..];
    let bounds = read_bounds(chunk, body_of(chunk))?;
    let fields =
        ["packed_position", "packed_rotation", "packed_scale", "packed_color"].map(|n| vertex.offset(n, Scalar::U32));
    let [position, rotation, scale, color] = fields;
    let (position, rotation, scale, color) = (position?, rotation?, scale?, color?);
    let sh_offsets = match sh {
        Some(e) => (0..rest).map(|k| e.offset(&format!("f_rest_{k}"), Scalar::U8)).collect::<Result<Vec<_>, _>>()?,
        None => Vec::new(),
    };
    let (vertex_body, stride) = (body_of(vertex), vertex.stride());
    let per_channel = sh_coeff_count(sh_degree) - 1;
    let mut particles = Vec::with_capacity(count);
    for i in 0..count {
        let record = &vertex_body[i * stride..(i + 1) * stride];
        let b = &bounds[i / CHUNK];
        let mean = lerp(b.position.0, b.position.1, unpack_111011(u32_at(record, position)));
        let log_scale = lerp(b.scale.0, b.scale.1, unpack_111011(u32_at(record, scale)));
        let packed = u32_at(record, color);
        let rgb = Vec3::new(unorm(packed >> 24, 8), unorm(packed >> 16, 8), unorm(packed >> 8, 8));
        let rgb = b.color.map_or(rgb, |(min, max)| lerp(min, max, rgb));
        let mut coeffs = [Vec3::ZERO; SH_MAX_COEFFS];
        coeffs[0] = (rgb - Vec3::splat(0.5)) / SH_C0;
        if let Some(e) = sh {
            let record = &body_of(e)[i * e.stride()..(i + 1) * e.stride()];
            for (k, c) in coeffs[1..=per_channel].iter_mut().enumerate() {
                *c = Vec3::from_array([0, 1, 2].map(|ch| sh_byte(record[sh_offsets[ch * per_channel + k]])));
            }
        }
        let particle =
            Particle::new(mean, log_scale.exp(), unpack_rotation(u32_at(record, rotation)), unorm(packed, 8), coeffs)
                .map_err(|error| ErrorKind::Particle { index: i as u64, error })?;
        particles.push(particle);
    }
    Ok(Scene::new(particles, sh_degree))
}
