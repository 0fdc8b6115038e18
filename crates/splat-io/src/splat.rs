//! antimatter15 `.splat`: 32 bytes a splat, little-endian, no header.
//!
//! | bytes | content |
//! |---|---|
//! | 0..12 | position, 3 × f32 |
//! | 12..24 | scale, 3 × f32, linear (not log) |
//! | 24..28 | RGBA, 4 × u8: the final colour (SH already evaluated) and linear opacity |
//! | 28..32 | quaternion w, x, y, z, 4 × u8, component = (b − 128) / 128 |
//!
//! Its RGB is stored here as SH degree 0, so that the degree-0 colour equals it.

use crate::{Error, ErrorKind, read_file};
use glam::{Quat, Vec3};
use splat_core::particle::SH_MAX_COEFFS;
use splat_core::sh::rgb_to_dc;
use splat_core::{Particle, Scene};
use std::path::Path;

/// Bytes per splat.
pub const RECORD: usize = 32;

/// Read an antimatter15 `.splat` file.
pub fn read_splat(path: &Path) -> Result<Scene, Error> {
    let bytes = read_file(path)?;
    parse_splat(&bytes).map_err(|kind| Error::new(path, kind))
}

/// Parse the bytes of an antimatter15 `.splat` file.
pub fn parse_splat(bytes: &[u8]) -> Result<Scene, ErrorKind> {
    if !bytes.len().is_multiple_of(RECORD) {
        let index = (bytes.len() / RECORD) as u64;
        return Err(ErrorKind::SplatLength {
            len: bytes.len() as u64,
            index,
            offset: index * RECORD as u64,
            remainder: (bytes.len() % RECORD) as u64,
        });
    }
    let particles = bytes
        .chunks_exact(RECORD)
        .enumerate()
        .map(|(i, record)| decode(i as u64, record))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Scene::new(particles, 0))
}

fn f32_at(record: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([record[4 * i], record[4 * i + 1], record[4 * i + 2], record[4 * i + 3]])
}

fn decode(index: u64, record: &[u8]) -> Result<Particle, ErrorKind> {
    let names = ["x", "y", "z", "scale_0", "scale_1", "scale_2"];
    let mut v = [0.0f32; 6];
    for (k, (value, name)) in v.iter_mut().zip(names).enumerate() {
        *value = f32_at(record, k);
        if !value.is_finite() {
            return Err(ErrorKind::NonFinite { index, property: name.into(), value: f64::from(*value) });
        }
    }
    let scale = Vec3::new(v[3], v[4], v[5]);
    for (axis, s) in scale.to_array().into_iter().enumerate() {
        if !(s > 0.0 && (1.0 / (s * s)).is_finite()) {
            return Err(ErrorKind::BadScale {
                index,
                detail: format!("scale_{axis} = {s} is not a usable positive scale"),
            });
        }
    }
    let q = record[28..32].iter().map(|&b| (f32::from(b) - 128.0) / 128.0).collect::<Vec<_>>();
    if q.iter().all(|&c| c == 0.0) {
        return Err(ErrorKind::ZeroQuaternion { index });
    }
    let rotation = Quat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
    let rgb = Vec3::new(f32::from(record[24]), f32::from(record[25]), f32::from(record[26])) / 255.0;
    let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
    sh[0] = rgb_to_dc(rgb);
    let opacity = f32::from(record[27]) / 255.0;
    Particle::new(Vec3::new(v[0], v[1], v[2]), scale, rotation, opacity, sh)
        .map_err(|error| ErrorKind::Particle { index, error })
}

/// Encode a scene as `.splat`: colour is the SH degree-0 colour (higher bands are dropped, as
/// the format has no view dependence), opacity and colour are quantised to 8 bits.
pub fn encode_splat(scene: &Scene) -> Vec<u8> {
    let mut out = Vec::with_capacity(scene.particles.len() * RECORD);
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    for p in &scene.particles {
        for v in p.mean.to_array().into_iter().chain(p.scale.to_array()) {
            out.extend(v.to_le_bytes());
        }
        let rgb = p.sh[0] * splat_core::sh::SH_C0 + Vec3::splat(0.5);
        out.extend([to_u8(rgb.x), to_u8(rgb.y), to_u8(rgb.z), to_u8(p.opacity)]);
        let q = p.rotation.normalize();
        for c in [q.w, q.x, q.y, q.z] {
            out.push((c * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8);
        }
    }
    out
}

/// Write a scene as `.splat` (see [`encode_splat`]).
pub fn write_splat(path: &Path, scene: &Scene) -> Result<(), Error> {
    std::fs::write(path, encode_splat(scene)).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}
