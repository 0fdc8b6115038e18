//! Accumulation files (`.acc`): one share of a run's frames, as `splat render --frames a..b`
//! writes it for `splat merge` ([`splat_core::frame::Accumulation`]).
//!
//! The file is a line of JSON, then the data:
//!
//! ```text
//! {"format":"splat-accumulation","version":1,"width":W,"height":H,"first":a,"count":n,"render":"…"}\n
//! W × H pixels, rows top to bottom, each 7 little-endian f32: mean R G B, variance R G B, alpha
//! ```
//!
//! `render` describes everything that decides the frames besides their range (the method and
//! its parameters, the settings, the camera, the scene, the seed and generator): shares merge
//! only when it is the same.

use crate::{Error, ErrorKind, read_file};
use serde::{Deserialize, Serialize};
use splat_core::Image;
use splat_core::frame::Accumulation;
use std::path::Path;

/// The format's name in the header.
const FORMAT: &str = "splat-accumulation";
/// Its version.
const VERSION: u32 = 1;
/// Values a pixel: mean RGB, variance RGB, alpha.
const VALUES: usize = 7;

/// The header line.
#[derive(Serialize, Deserialize)]
struct Header {
    format: String,
    version: u32,
    width: u32,
    height: u32,
    first: u32,
    count: u32,
    render: String,
}

/// A share and the description of the render it belongs to.
#[derive(Clone, Debug, PartialEq)]
pub struct Share {
    /// Its frames' statistics.
    pub accumulation: Accumulation,
    /// What decides the frames besides their range; equal for shares of one run.
    pub render: String,
}

/// Write `share` to `path`.
pub fn write(path: &Path, share: &Share) -> Result<(), Error> {
    let a = &share.accumulation;
    let header = Header {
        format: FORMAT.into(),
        version: VERSION,
        width: a.mean.width(),
        height: a.mean.height(),
        first: a.first,
        count: a.count,
        render: share.render.clone(),
    };
    let mut bytes = serde_json::to_vec(&header).map_err(|e| Error::new(path, ErrorKind::Json(e)))?;
    bytes.push(b'\n');
    let pixels = a.alpha.data().len();
    bytes.reserve(pixels * VALUES * 4);
    for i in 0..pixels {
        let values = a.mean.data()[3 * i..3 * i + 3].iter().chain(&a.variance.data()[3 * i..3 * i + 3]);
        for v in values.chain(std::iter::once(&a.alpha.data()[i])) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).map_err(|e| Error::new(path, ErrorKind::Io(e)))
}

/// Read a share from `path`, refusing a file that is not one ([`parse`]).
pub fn read(path: &Path) -> Result<Share, Error> {
    parse(&read_file(path)?).map_err(|message| Error::new(path, ErrorKind::Accumulation(message)))
}

/// A share from the bytes of an accumulation file, refusing what is not one, another version,
/// and data that does not match the header or is not finite.
pub fn parse(bytes: &[u8]) -> Result<Share, String> {
    let end = bytes.iter().position(|&b| b == b'\n').ok_or("no header line")?;
    let header: Header =
        serde_json::from_slice(&bytes[..end]).map_err(|e| format!("the header is not an accumulation header ({e})"))?;
    if header.format != FORMAT {
        return Err(format!("format '{}', expected '{FORMAT}'", header.format));
    }
    if header.version != VERSION {
        return Err(format!("version {}, this reader reads version {VERSION}", header.version));
    }
    if header.count == 0 {
        return Err("it holds no frames (count 0)".into());
    }
    let data = &bytes[end + 1..];
    let pixels = u64::from(header.width) * u64::from(header.height);
    let expected = pixels.checked_mul(VALUES as u64 * 4).ok_or_else(|| format!("{pixels} pixels is not a size"))?;
    if data.len() as u64 != expected {
        let (w, h) = (header.width, header.height);
        return Err(format!("{w}×{h} pixels need {expected} bytes of data; the file holds {}", data.len()));
    }
    let values: Vec<f32> = data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!("it holds {v}: every value must be finite"));
    }
    let (w, h) = (header.width, header.height);
    let channel =
        |range: std::ops::Range<usize>| values.chunks_exact(VALUES).flat_map(|p| p[range.clone()].to_vec()).collect();
    let image = |c: u32, data: Vec<f32>| Image::from_data(w, h, c, data).expect("sized from the header");
    let accumulation = Accumulation {
        first: header.first,
        count: header.count,
        mean: image(3, channel(0..3)),
        variance: image(3, channel(3..6)),
        alpha: image(1, channel(6..7)),
    };
    Ok(Share { accumulation, render: header.render })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn share() -> Share {
        let image = |c: u32, v: f32| Image::filled(3, 2, c, v);
        let accumulation =
            Accumulation { first: 4, count: 8, mean: image(3, 0.25), variance: image(3, 0.5), alpha: image(1, 0.75) };
        Share { accumulation, render: "stochastic, seed 1".into() }
    }

    #[test]
    fn a_share_reads_back_as_written() {
        let dir = std::env::temp_dir().join(format!("acc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("part.acc");
        let mut written = share();
        written.accumulation.mean.data_mut()[4] = 0.125;
        write(&path, &written).unwrap();
        assert_eq!(read(&path).unwrap(), written);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let error = read(&path).unwrap_err().to_string();
        assert!(error.contains("3×2 pixels need 168 bytes of data; the file holds 165"), "{error}");
        std::fs::write(&path, b"{\"format\":\"other\"}\n").unwrap();
        assert!(read(&path).unwrap_err().to_string().contains("not an accumulation header"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
