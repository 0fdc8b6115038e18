//! Image output chosen by extension: `.png` (8-bit), `.exr` (f32), `.npy` (f32, H × W × C).
//!
//! 3DGS colours are display-referred (trained on sRGB photographs), so values are written as
//! they are, with no transfer curve: a PNG stores round(clamp(v, 0, 1) × 255).

use crate::{Error, ErrorKind};
use splat_core::Image;
use splat_core::undistort::Photo;
use std::path::Path;

/// Image file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit PNG (grey, RGB or RGBA).
    Png,
    /// OpenEXR, 32-bit float channels.
    Exr,
    /// NumPy `.npy`, little-endian f32, shape (H, W, C).
    Npy,
}

impl ImageFormat {
    /// The format named by a path's extension.
    pub fn from_path(path: &Path) -> Result<Self, Error> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            Some("npy") => Ok(Self::Npy),
            _ => Err(Error::new(path, ErrorKind::UnknownExtension { expected: ".png, .exr or .npy" })),
        }
    }
}

/// What a one-channel image holds: it names the channel of an EXR file, by OpenEXR's
/// conventions (Z for depth, A for coverage, Y for a grey image).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Single {
    /// A grey image: channel `Y`.
    #[default]
    Luminance,
    /// A depth (distance along the ray): channel `Z`.
    Depth,
    /// Coverage 1 − T: channel `A`.
    Alpha,
}

impl Single {
    /// The EXR channel name.
    pub fn exr_channel(self) -> &'static str {
        match self {
            Single::Luminance => "Y",
            Single::Depth => "Z",
            Single::Alpha => "A",
        }
    }
}

/// Write an image, format chosen by extension (a one-channel image as a grey image).
pub fn write_image(path: &Path, image: &Image) -> Result<(), Error> {
    write_image_as(path, image, Single::Luminance)
}

/// Write an image, format chosen by extension; a one-channel image holds `single`, which names
/// its EXR channel.
pub fn write_image_as(path: &Path, image: &Image, single: Single) -> Result<(), Error> {
    let err = |m: String| Error::new(path, ErrorKind::Image(m));
    match ImageFormat::from_path(path)? {
        ImageFormat::Png => write_png(path, image),
        ImageFormat::Exr => write_exr(path, image, single).map_err(|e| err(e.to_string())),
        ImageFormat::Npy => std::fs::write(path, encode_npy(image)).map_err(|e| Error::new(path, ErrorKind::Io(e))),
    }
}

pub use splat_core::image::to_u8;

/// The 8-bit pixels of an image with 1, 3 or 4 channels.
pub fn to_rgba8(image: &Image) -> image::DynamicImage {
    let (w, h) = (image.width(), image.height());
    let bytes: Vec<u8> = image.data().iter().map(|&v| to_u8(v)).collect();
    match image.channels() {
        1 => image::DynamicImage::ImageLuma8(image::GrayImage::from_raw(w, h, bytes).expect("size checked by Image")),
        3 => image::DynamicImage::ImageRgb8(image::RgbImage::from_raw(w, h, bytes).expect("size checked by Image")),
        _ => image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(w, h, bytes).expect("size checked by Image")),
    }
}

fn write_png(path: &Path, image: &Image) -> Result<(), Error> {
    if ![1, 3, 4].contains(&image.channels()) {
        return Err(Error::new(
            path,
            ErrorKind::Image(format!("PNG needs 1, 3 or 4 channels, not {}", image.channels())),
        ));
    }
    to_rgba8(image)
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| Error::new(path, ErrorKind::Image(e.to_string())))
}

fn write_exr(path: &Path, image: &Image, single: Single) -> exr::error::Result<()> {
    use exr::prelude::*;
    let size = (image.width() as usize, image.height() as usize);
    let at = |p: Vec2<usize>, c: usize| image.pixel(p.0 as u32, p.1 as u32)[c];
    match image.channels() {
        1 => {
            let channels = SpecificChannels::build().with_channel(single.exr_channel()).with_pixel_fn(|p| (at(p, 0),));
            Image::from_channels(size, channels).write().to_file(path)
        }
        3 => write_rgb_file(path, size.0, size.1, |x, y| {
            let p = image.pixel(x as u32, y as u32);
            (p[0], p[1], p[2])
        }),
        4 => write_rgba_file(path, size.0, size.1, |x, y| {
            let p = image.pixel(x as u32, y as u32);
            (p[0], p[1], p[2], p[3])
        }),
        n => Err(exr::error::Error::Invalid(format!("{n} channels (expected 1, 3 or 4)").into())),
    }
}

/// Encode an image as NumPy `.npy` version 1.0: little-endian f32, C order, shape (H, W, C).
pub fn encode_npy(image: &Image) -> Vec<u8> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        image.height(),
        image.width(),
        image.channels()
    );
    // Magic (6) + version (2) + header length (2) + dict, padded with spaces to a multiple of 64
    // and ended by a newline.
    let unpadded = 10 + dict.len() + 1;
    let header = format!("{dict}{}\n", " ".repeat(unpadded.next_multiple_of(64) - unpadded));
    let mut out = Vec::with_capacity(10 + header.len() + 4 * image.data().len());
    out.extend(b"\x93NUMPY\x01\x00");
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.bytes());
    for v in image.data() {
        out.extend(v.to_le_bytes());
    }
    out
}

/// Read an image, format chosen by extension: `.npy` and `.exr` as f32 (an EXR's R, G, B and,
/// when present, A; else its first channel), `.png` and `.jpg` (photographs, read only) as 8-bit
/// values / 255.
pub fn read_image(path: &Path) -> Result<Image, Error> {
    if is_jpeg(path) {
        return read_8bit(path);
    }
    let format = ImageFormat::from_path(path)
        .map_err(|_| Error::new(path, ErrorKind::UnknownExtension { expected: ".png, .jpg, .exr or .npy" }))?;
    match format {
        ImageFormat::Npy => read_npy(path),
        ImageFormat::Exr => read_exr(path).map_err(|m| Error::new(path, ErrorKind::Image(m))),
        ImageFormat::Png => read_8bit(path),
    }
}

/// Whether `path` names a JPEG (`.jpg`, `.jpeg`, any case), which is read but never written.
pub fn is_jpeg(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("jpg" | "jpeg"))
}

/// Whether `path` names an 8-bit image (PNG, JPEG), which [`read_image`] reads as values / 255.
pub fn is_eight_bit(path: &Path) -> bool {
    is_jpeg(path) || matches!(ImageFormat::from_path(path), Ok(ImageFormat::Png))
}

/// An 8-bit PNG or JPEG as values / 255: three channels (grey repeated), four where it has alpha.
fn read_8bit(path: &Path) -> Result<Image, Error> {
    let decoded = image::open(path).map_err(|e| Error::new(path, ErrorKind::Image(e.to_string())))?;
    let rgba = decoded.color().has_alpha();
    let (w, h) = (decoded.width(), decoded.height());
    let (c, bytes) = if rgba { (4, decoded.into_rgba8().into_raw()) } else { (3, decoded.into_rgb8().into_raw()) };
    let data = bytes.into_iter().map(|b| f32::from(b) / 255.0).collect();
    Image::from_data(w, h, c, data).ok_or_else(|| Error::new(path, ErrorKind::Image("size mismatch".into())))
}

/// An 8-bit PNG or JPEG photograph as it is: its grey, grey + alpha, RGB or RGBA values, as
/// OpenCV and PIL read it for a trainer (for [`splat_core::Camera::undistort_photo`]). A photo
/// of 16 bits or floats is refused: the trainers read 8-bit photographs.
pub fn read_photo(path: &Path) -> Result<Photo, Error> {
    let decoded = image::open(path).map_err(|e| Error::new(path, ErrorKind::Image(e.to_string())))?;
    let (width, height) = (decoded.width(), decoded.height());
    let (channels, data) = match decoded {
        image::DynamicImage::ImageLuma8(i) => (1, i.into_raw()),
        image::DynamicImage::ImageLumaA8(i) => (2, i.into_raw()),
        image::DynamicImage::ImageRgb8(i) => (3, i.into_raw()),
        image::DynamicImage::ImageRgba8(i) => (4, i.into_raw()),
        other => {
            let why = format!(
                "a photograph of {:?} values, where the trainers read 8-bit photographs; convert it to 8 bits",
                other.color()
            );
            return Err(Error::new(path, ErrorKind::Image(why)));
        }
    };
    Ok(Photo { width, height, channels, data })
}

/// Write an 8-bit photograph as a PNG of its channels.
pub fn write_photo(path: &Path, photo: &Photo) -> Result<(), Error> {
    let color = match photo.channels {
        1 => image::ExtendedColorType::L8,
        2 => image::ExtendedColorType::La8,
        3 => image::ExtendedColorType::Rgb8,
        _ => image::ExtendedColorType::Rgba8,
    };
    image::save_buffer_with_format(path, &photo.data, photo.width, photo.height, color, image::ImageFormat::Png)
        .map_err(|e| Error::new(path, ErrorKind::Image(e.to_string())))
}

fn read_exr(path: &Path) -> Result<Image, String> {
    use exr::prelude::*;
    let read = read_first_flat_layer_from_file(path).map_err(|e| e.to_string())?;
    let layer = &read.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let channels = &layer.channel_data.list;
    let find = |name: &str| channels.iter().find(|c| c.name.eq(name));
    let picked: Vec<_> = match (find("R"), find("G"), find("B")) {
        (Some(r), Some(g), Some(b)) => [Some(r), Some(g), Some(b), find("A")].into_iter().flatten().collect(),
        _ => channels.first().into_iter().collect(),
    };
    if picked.is_empty() {
        return Err("the EXR layer has no channel".into());
    }
    let values: Vec<Vec<f32>> = picked.iter().map(|c| c.sample_data.values_as_f32().collect()).collect();
    let n = w * h;
    let data = (0..n).flat_map(|i| values.iter().map(move |v| v[i])).collect();
    let size = |v: usize| u32::try_from(v).map_err(|_| "image too large".to_string());
    splat_core::Image::from_data(size(w)?, size(h)?, picked.len() as u32, data).ok_or_else(|| "size mismatch".into())
}

/// Read a `.npy` written by [`encode_npy`] (or NumPy: `<f4`, C order, 2 or 3 dimensions).
pub fn read_npy(path: &Path) -> Result<Image, Error> {
    let bytes = crate::read_file(path)?;
    decode_npy(&bytes).map_err(|m| Error::new(path, ErrorKind::Image(m)))
}

/// Decode the bytes of a `.npy` holding f32 (H, W) or (H, W, C) data.
pub fn decode_npy(bytes: &[u8]) -> Result<Image, String> {
    let (header, body) = npy_header(bytes)?;
    if !header.contains("'descr': '<f4'") || !header.contains("'fortran_order': False") {
        return Err(format!("only little-endian f32 in C order is supported, header: {}", header.trim()));
    }
    let shape = header.split("'shape': (").nth(1).and_then(|s| s.split(')').next()).ok_or("no shape in .npy header")?;
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| "bad .npy shape")?;
    let (h, w, c) = match dims.as_slice() {
        [h, w] => (*h, *w, 1),
        [h, w, c] => (*h, *w, *c),
        _ => return Err(format!("expected 2 or 3 dimensions, found {}", dims.len())),
    };
    let n = h.checked_mul(w).and_then(|v| v.checked_mul(c)).ok_or("shape overflows")?;
    if body.len() != n.checked_mul(4).ok_or("shape overflows")? {
        return Err(format!("body has {} bytes, shape ({h}, {w}, {c}) needs {}", body.len(), 4 * n));
    }
    let data = body.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    let (w, h, c) = (u32::try_from(w), u32::try_from(h), u32::try_from(c));
    match (w, h, c) {
        (Ok(w), Ok(h), Ok(c)) => Image::from_data(w, h, c, data).ok_or_else(|| "size mismatch".into()),
        _ => Err("shape too large".into()),
    }
}

/// A `.npy` file's header (its Python dictionary's text) and the data after it.
pub(crate) fn npy_header(bytes: &[u8]) -> Result<(&str, &[u8]), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file".into());
    }
    let (len, start) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let header = bytes.get(start..start + len).ok_or("truncated .npy header")?;
    let header = std::str::from_utf8(header).map_err(|_| "non-text .npy header")?;
    Ok((header, &bytes[start + len..]))
}

/// A depth image for viewing: near is bright, far is dark, normalised over the finite depths;
/// pixels with no depth (NaN) are black.
pub fn depth_for_display(depth: &Image) -> Image {
    let finite = depth.data().iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let range = (hi - lo).max(1e-12);
    let data = depth.data().iter().map(|&v| if v.is_finite() { 1.0 - 0.8 * (v - lo) / range } else { 0.0 }).collect();
    Image::from_data(depth.width(), depth.height(), depth.channels(), data).expect("same size")
}

/// A normal image for viewing: n × 0.5 + 0.5 where a normal exists, black elsewhere.
pub fn normal_for_display(normal: &Image) -> Image {
    let mut out = normal.clone();
    for y in 0..normal.height() {
        for x in 0..normal.width() {
            let n = normal.pixel(x, y);
            let empty = n.iter().all(|&v| v == 0.0);
            for (o, &v) in out.pixel_mut(x, y).iter_mut().zip(n) {
                *o = if empty { 0.0 } else { 0.5 * v + 0.5 };
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The channel names of an EXR file.
    fn exr_channels(path: &Path) -> Vec<String> {
        let meta = exr::meta::MetaData::read_from_file(path, false).expect("EXR header");
        meta.headers[0].channels.list.iter().map(|c| c.name.to_string()).collect()
    }

    /// A depth EXR holds channel Z, an alpha EXR channel A, a grey one Y, colour R G B (the
    /// names other tools look for), each with its values.
    #[test]
    fn exr_channels_are_named_by_what_they_hold() {
        let dir = std::env::temp_dir().join(format!("splat-io-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let one = Image::from_data(2, 1, 1, vec![1.5, 2.5]).unwrap();
        for (single, name) in [(Single::Depth, "Z"), (Single::Alpha, "A"), (Single::Luminance, "Y")] {
            let path = dir.join(format!("{name}.exr"));
            write_image_as(&path, &one, single).unwrap();
            assert_eq!(exr_channels(&path), vec![name.to_string()]);
            let read = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
            let values: Vec<f32> = read.layer_data.channel_data.list[0].sample_data.values_as_f32().collect();
            assert_eq!(values, vec![1.5, 2.5], "{name}");
        }
        let rgb = Image::filled(2, 2, 3, 0.25);
        let path = dir.join("rgb.exr");
        write_image(&path, &rgb).unwrap();
        let mut names = exr_channels(&path);
        names.sort();
        assert_eq!(names, ["B", "G", "R"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
