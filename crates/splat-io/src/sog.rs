//! PlayCanvas SOG ("spatially ordered Gaussians"), the format SuperSplat publishes and
//! splat-transform writes: a `meta.json` and lossless WebP images whose texel i holds splat i,
//! either bundled in one zip file (`.sog`; the crate's `zip` module) or as a folder (`meta.json` beside
//! the images). Read (versions 1 and 2) and written (version 2, the current one).
//!
//! Version 2, per splat (texel), as splat-transform 3.7's `writeSogSource` writes it:
//!
//! | image | texel |
//! |---|---|
//! | `means_l`, `means_u` | low and high bytes of x, y, z as 16-bit steps between `means.mins` and `.maxs` of l(p) = sign(p) ln(1 + \|p\|) |
//! | `quats` | the quaternion's three smaller components × √2, each (v + 1) / 2 × 255, and 252 + the index (w, x, y, z) of the dropped largest one |
//! | `scales` | three indices into `scales.codebook`, 256 log scales |
//! | `sh0` | three indices into `sh0.codebook`, 256 DC coefficients; alpha: the opacity × 255 |
//! | `shN_labels` | a 16-bit index into the SH palette (red low byte, green high) |
//! | `shN_centroids` | per palette entry (64 a row), one texel per coefficient of bands 1–`shN.bands`: three indices into `shN.codebook` (red, green, blue channels) |
//!
//! Version 1 (no `version` field) stores scales, DC colours and a logit opacity, and the SH
//! palette, as 8-bit steps between per-attribute `mins` and `maxs` instead of codebooks.
//!
//! **Colour.** The DC codebook holds SH coefficients, as a `.ply`'s `f_dc` does: radiance is
//! 0.5 + C₀ · DC, in the display (sRGB-encoded) values 3DGS trains on. PlayCanvas reads it as
//! sRGB (engine #8324); so does every renderer here, which composites those values as stored.
//!
//! **Render mode.** `meta.json`'s `"model": "antialiased"` marks gsplat's antialiased capture
//! ([`ScreenFilter::Antialiased`]), read and written; Mip-Splatting's filter is written as
//! antialiased, the nearest the format records ([`crate::SceneFormat::records`]). 2DGS files
//! (`"model": "2dgs"`) are refused by name.

use crate::zip;
use crate::{Error, ErrorKind, read_file};
use glam::{Quat, Vec3};
use serde_json::{Value, json};
use splat_core::particle::{SH_MAX_COEFFS, sh_coeff_count};
use splat_core::{Particle, Scene, ScreenFilter};
use std::io::Cursor;
use std::path::{Path, PathBuf};

/// The version the writer writes.
pub const SOG_VERSION: u32 = 2;
/// WebP's largest side, in texels.
const MAX_SIDE: u32 = 16_383;
/// Entries of every codebook.
const CODEBOOK: usize = 256;
/// Palette entries a row of `shN_centroids`.
const PALETTE_ROW: usize = 64;
/// Largest SH palette the writer fits (splat-transform's is up to 65,536 entries, fitted on a
/// GPU; at most 4096 here keeps the CPU's k-means to seconds a million splats).
const MAX_PALETTE: usize = 4096;
/// Splats the SH palette's k-means is fitted on (every splat is then labelled).
const PALETTE_SAMPLE: usize = 65_536;
/// Iterations of the palette's k-means and of the 1D codebooks'.
const KMEANS_ITERATIONS: usize = 12;
const CODEBOOK_ITERATIONS: usize = 30;

/// Files of a SOG encoding: (name, contents).
pub type SogFiles = Vec<(String, Vec<u8>)>;

/// Per axis, the least and the greatest l(p) of the positions.
type Bounds = ([f32; 3], [f32; 3]);

/// Writes bands 1 and up of splat i ([`Fields::sh_rest`]).
type ShRest<'a> = Box<dyn Fn(usize, &mut [Vec3]) + 'a>;

fn sog_error(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Sog(message.into())
}

/// How a SOG file was stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SogInfo {
    /// `meta.json`'s version (1 when it names none).
    pub version: u32,
    /// A `.sog` zip bundle rather than a folder.
    pub bundled: bool,
}

impl SogInfo {
    /// What `splat info` prints.
    pub fn describe(self) -> String {
        let container = if self.bundled { "bundled .sog" } else { "meta.json and images" };
        format!("version {}, {container}", self.version)
    }
}

/// Whether `path` names a SOG file: a `.sog` bundle or a `meta.json`.
pub fn is_sog_path(path: &Path) -> bool {
    crate::extension(path).as_deref() == Some("sog")
        || path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.to_ascii_lowercase().ends_with("meta.json"))
}

/// Read a `.sog` bundle, or a `meta.json` with its images beside it.
pub fn read_sog(path: &Path) -> Result<(Scene, SogInfo), Error> {
    let bytes = read_file(path)?;
    if crate::extension(path).as_deref() == Some("sog") {
        return parse_sog_bundle(&bytes).map_err(|kind| Error::new(path, kind));
    }
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let load = |name: &str| -> Result<Vec<u8>, ErrorKind> {
        let file = texture_path(&dir, name)?;
        std::fs::read(&file).map_err(|e| sog_error(format!("{}: {e}", file.display())))
    };
    let (scene, version) = parse_sog(&bytes, &load).map_err(|kind| Error::new(path, kind))?;
    Ok((scene, SogInfo { version, bundled: false }))
}

/// An image named in `meta.json`, beside it: a plain file name (no directory, no `..`), so
/// that a file cannot make the reader open anything else.
fn texture_path(dir: &Path, name: &str) -> Result<PathBuf, ErrorKind> {
    let plain = !name.is_empty() && name != ".." && !name.contains(['/', '\\']) && name != ".";
    if !plain {
        return Err(sog_error(format!("image name {name:?} is not a file name beside meta.json")));
    }
    Ok(dir.join(name))
}

/// Parse a `.sog` bundle (a zip of `meta.json` and the images).
pub fn parse_sog_bundle(bytes: &[u8]) -> Result<(Scene, SogInfo), ErrorKind> {
    let entries = zip::read_entries(bytes).map_err(ErrorKind::Sog)?;
    let find = |name: &str| entries.iter().find(|(n, _)| n == name).map(|(_, data)| data);
    let meta = find("meta.json").ok_or_else(|| sog_error("the bundle has no meta.json"))?;
    let load = |name: &str| find(name).cloned().ok_or_else(|| sog_error(format!("the bundle has no {name}")));
    let (scene, version) = parse_sog(meta, &load)?;
    Ok((scene, SogInfo { version, bundled: true }))
}

/// Parse `meta.json` and decode the images `load` gives by name; returns the scene and the
/// version.
pub fn parse_sog(meta: &[u8], load: &dyn Fn(&str) -> Result<Vec<u8>, ErrorKind>) -> Result<(Scene, u32), ErrorKind> {
    let meta: Value = serde_json::from_slice(meta).map_err(|e| sog_error(format!("meta.json: {e}")))?;
    let version = match meta.get("version") {
        None => 1,
        Some(v) => match v.as_u64() {
            Some(v @ 1..=2) => v as u32,
            _ => return Err(sog_error(format!("meta.json version {v} is not supported (versions 1 and 2 are)"))),
        },
    };
    let filter = match meta.get("model").and_then(Value::as_str) {
        None | Some("default") => ScreenFilter::Dilation,
        Some("antialiased") => ScreenFilter::Antialiased,
        Some("2dgs") => return Err(sog_error("2DGS (\"model\": \"2dgs\") SOG files are not read; convert the .ply")),
        Some(other) => return Err(sog_error(format!("unknown \"model\" {other:?} in meta.json"))),
    };
    let fields = Fields { meta: &meta, version, load };
    let mut scene = fields.decode()?;
    scene.screen_filter = filter;
    Ok((scene, version))
}

/// An RGBA image.
struct Texture {
    width: u32,
    rgba: Vec<u8>,
}

impl Texture {
    /// The four bytes of texel `i`.
    fn texel(&self, i: usize) -> [u8; 4] {
        let at = 4 * i;
        [self.rgba[at], self.rgba[at + 1], self.rgba[at + 2], self.rgba[at + 3]]
    }

    fn texels(&self) -> usize {
        self.rgba.len() / 4
    }
}

/// Decode a WebP image to RGBA (the alpha 255 where it has none).
fn decode_webp(name: &str, bytes: &[u8]) -> Result<Texture, ErrorKind> {
    let bad = |e: image_webp::DecodingError| sog_error(format!("{name}: {e}"));
    let mut decoder = image_webp::WebPDecoder::new(Cursor::new(bytes)).map_err(bad)?;
    if decoder.is_animated() {
        return Err(sog_error(format!("{name} is an animation, not an image")));
    }
    let (width, height) = decoder.dimensions();
    let size = decoder.output_buffer_size().ok_or_else(|| sog_error(format!("{name} is too large")))?;
    let mut pixels = vec![0u8; size];
    decoder.read_image(&mut pixels).map_err(bad)?;
    let rgba = if decoder.has_alpha() {
        pixels
    } else {
        pixels.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect()
    };
    debug_assert_eq!(rgba.len(), 4 * (width as usize) * (height as usize));
    Ok(Texture { width, rgba })
}

/// `meta.json` and the images it names.
struct Fields<'a> {
    meta: &'a Value,
    version: u32,
    load: &'a dyn Fn(&str) -> Result<Vec<u8>, ErrorKind>,
}

impl Fields<'_> {
    /// `meta[attribute][key]`, or an error naming it.
    fn get(&self, attribute: &str, key: &str) -> Result<&Value, ErrorKind> {
        self.meta
            .get(attribute)
            .and_then(|a| a.get(key))
            .ok_or_else(|| sog_error(format!("meta.json has no {attribute}.{key}")))
    }

    /// `meta[attribute][key]` as `n` numbers.
    fn numbers(&self, attribute: &str, key: &str, n: usize) -> Result<Vec<f32>, ErrorKind> {
        let bad = || sog_error(format!("meta.json {attribute}.{key} is not {n} finite numbers"));
        let values = self.get(attribute, key)?.as_array().ok_or_else(bad)?;
        let numbers: Option<Vec<f32>> =
            values.iter().map(|v| v.as_f64().map(|x| x as f32).filter(|x| x.is_finite())).collect();
        numbers.filter(|v| v.len() == n).ok_or_else(bad)
    }

    /// `meta[attribute][key]` as one number.
    fn number(&self, attribute: &str, key: &str) -> Result<f32, ErrorKind> {
        self.get(attribute, key)?
            .as_f64()
            .map(|x| x as f32)
            .filter(|x| x.is_finite())
            .ok_or_else(|| sog_error(format!("meta.json {attribute}.{key} is not a finite number")))
    }

    /// A codebook: 256 numbers, where −∞ (JSON null, splat-transform's sentinel for empty
    /// entries) is kept as −∞ for the reader to refuse where a splat uses it.
    fn codebook(&self, attribute: &str) -> Result<Vec<f32>, ErrorKind> {
        let bad = || sog_error(format!("meta.json {attribute}.codebook is not {CODEBOOK} numbers"));
        let values = self.get(attribute, "codebook")?.as_array().ok_or_else(bad)?;
        let book: Option<Vec<f32>> = values
            .iter()
            .map(|v| if v.is_null() { Some(f32::NEG_INFINITY) } else { v.as_f64().map(|x| x as f32) })
            .collect();
        book.filter(|b| b.len() == CODEBOOK).ok_or_else(bad)
    }

    /// Image `index` of `attribute.files`, decoded, with at least `count` texels.
    fn texture(&self, attribute: &str, index: usize, count: usize) -> Result<Texture, ErrorKind> {
        let name = self
            .get(attribute, "files")?
            .get(index)
            .and_then(Value::as_str)
            .ok_or_else(|| sog_error(format!("meta.json {attribute}.files has no image {index}")))?;
        let texture = decode_webp(name, &(self.load)(name)?)?;
        if texture.texels() < count {
            return Err(sog_error(format!("{name} has {} texels for {count} splats", texture.texels())));
        }
        Ok(texture)
    }

    fn count(&self) -> Result<usize, ErrorKind> {
        let count = match self.version {
            1 => self.get("means", "shape")?.get(0).and_then(Value::as_u64),
            _ => self.meta.get("count").and_then(Value::as_u64),
        };
        let count = count.ok_or_else(|| sog_error("meta.json has no splat count"))?;
        let most = u64::from(MAX_SIDE) * u64::from(MAX_SIDE);
        if count > most {
            return Err(sog_error(format!("meta.json says {count} splats, more than WebP images can hold ({most})")));
        }
        Ok(count as usize)
    }

    fn decode(&self) -> Result<Scene, ErrorKind> {
        let count = self.count()?;
        let means = self.means(count)?;
        let quats = self.texture("quats", 0, count)?;
        let (scales, colours) = match self.version {
            1 => (self.ranged_scales(count)?, self.ranged_colours(count)?),
            _ => (self.coded_scales(count)?, self.coded_colours(count)?),
        };
        let (degree, rest) = self.sh_rest(count)?;
        let mut particles = Vec::with_capacity(count);
        for i in 0..count {
            let mut sh = [Vec3::ZERO; SH_MAX_COEFFS];
            sh[0] = colours[i].0;
            if let Some(rest) = &rest {
                rest(i, &mut sh[1..sh_coeff_count(degree)]);
            }
            let p = Particle::new(means[i], scales[i], unpack_quat(quats.texel(i)), colours[i].1, sh)
                .map_err(|error| ErrorKind::Particle { index: i as u64, error })?;
            particles.push(p);
        }
        Ok(Scene::new(particles, degree))
    }

    /// Positions: 16 bits between the bounds of l(p) = sign(p) ln(1 + |p|), inverted.
    fn means(&self, count: usize) -> Result<Vec<Vec3>, ErrorKind> {
        let (mins, maxs) = (self.numbers("means", "mins", 3)?, self.numbers("means", "maxs", 3)?);
        let (low, high) = (self.texture("means", 0, count)?, self.texture("means", 1, count)?);
        let axis = |a: usize, step: u16| {
            let span = if maxs[a] == mins[a] { 1.0 } else { maxs[a] - mins[a] };
            inverse_log_transform(mins[a] + span * f32::from(step) / 65535.0)
        };
        Ok((0..count)
            .map(|i| {
                let (l, h) = (low.texel(i), high.texel(i));
                Vec3::from_array(std::array::from_fn(|a| axis(a, u16::from_le_bytes([l[a], h[a]]))))
            })
            .collect())
    }

    /// Version 2 scales: codebook indices of log scales.
    fn coded_scales(&self, count: usize) -> Result<Vec<Vec3>, ErrorKind> {
        let book = self.codebook("scales")?;
        let texture = self.texture("scales", 0, count)?;
        Ok((0..count)
            .map(|i| Vec3::from_array(std::array::from_fn(|a| book[usize::from(texture.texel(i)[a])].exp())))
            .collect())
    }

    /// Version 2 DC and opacity: codebook indices, and the opacity × 255 in alpha.
    fn coded_colours(&self, count: usize) -> Result<Vec<(Vec3, f32)>, ErrorKind> {
        let book = self.codebook("sh0")?;
        let texture = self.texture("sh0", 0, count)?;
        let colour = |t: [u8; 4]| Vec3::from_array(std::array::from_fn(|c| book[usize::from(t[c])]));
        Ok((0..count).map(|i| texture.texel(i)).map(|t| (colour(t), f32::from(t[3]) / 255.0)).collect())
    }

    /// Version 1 scales: 8-bit steps of log scales between per-axis bounds.
    fn ranged_scales(&self, count: usize) -> Result<Vec<Vec3>, ErrorKind> {
        let (mins, maxs) = (self.numbers("scales", "mins", 3)?, self.numbers("scales", "maxs", 3)?);
        let texture = self.texture("scales", 0, count)?;
        let step = |a: usize, b: u8| (mins[a] + (maxs[a] - mins[a]) * f32::from(b) / 255.0).exp();
        Ok((0..count).map(|i| Vec3::from_array(std::array::from_fn(|a| step(a, texture.texel(i)[a])))).collect())
    }

    /// Version 1 DC and opacity: 8-bit steps between bounds, the opacity a logit.
    fn ranged_colours(&self, count: usize) -> Result<Vec<(Vec3, f32)>, ErrorKind> {
        let (mins, maxs) = (self.numbers("sh0", "mins", 4)?, self.numbers("sh0", "maxs", 4)?);
        let texture = self.texture("sh0", 0, count)?;
        let step = |c: usize, b: u8| mins[c] + (maxs[c] - mins[c]) * f32::from(b) / 255.0;
        Ok((0..count)
            .map(|i| texture.texel(i))
            .map(|t| {
                let opacity = crate::ply::opacity_from_logit(f64::from(step(3, t[3]))) as f32;
                (Vec3::from_array(std::array::from_fn(|c| step(c, t[c]))), opacity)
            })
            .collect())
    }

    /// The SH degree and, where it is above 0, a function writing splat i's bands 1 and up
    /// (coefficient j of channel c from palette texel j of its label).
    fn sh_rest(&self, count: usize) -> Result<(u8, Option<ShRest<'_>>), ErrorKind> {
        if self.meta.get("shN").is_none() {
            return Ok((0, None));
        }
        let centroids = self.texture("shN", 0, 0)?;
        let labels = self.texture("shN", 1, count)?;
        let degree = match self.version {
            1 => match centroids.width {
                192 => 1,
                512 => 2,
                960 => 3,
                w => return Err(sog_error(format!("shN_centroids is {w} texels wide, not 192, 512 or 960"))),
            },
            _ => match self.get("shN", "bands")?.as_u64() {
                Some(b @ 1..=3) => b as u8,
                _ => return Err(sog_error("meta.json shN.bands is not 1, 2 or 3")),
            },
        };
        let coeffs = sh_coeff_count(degree) - 1;
        if centroids.width as usize != PALETTE_ROW * coeffs {
            return Err(sog_error(format!(
                "shN_centroids is {} texels wide, not {} for SH degree {degree}",
                centroids.width,
                PALETTE_ROW * coeffs
            )));
        }
        let value: Box<dyn Fn(u8) -> f32> = match self.version {
            1 => {
                let (min, max) = (self.number("shN", "mins")?, self.number("shN", "maxs")?);
                Box::new(move |b| min + (max - min) * f32::from(b) / 255.0)
            }
            _ => {
                let book = self.codebook("shN")?;
                Box::new(move |b| book[usize::from(b)])
            }
        };
        let palette = centroids.texels() / coeffs;
        for i in 0..count {
            let t = labels.texel(i);
            let label = usize::from(u16::from_le_bytes([t[0], t[1]]));
            if label >= palette {
                return Err(sog_error(format!("splat {i}: SH palette entry {label} of {palette}")));
            }
        }
        let rest = move |i: usize, out: &mut [Vec3]| {
            let t = labels.texel(i);
            let label = usize::from(u16::from_le_bytes([t[0], t[1]]));
            for (j, c) in out.iter_mut().enumerate() {
                let p = centroids.texel(label * coeffs + j);
                *c = Vec3::new(value(p[0]), value(p[1]), value(p[2]));
            }
        };
        Ok((degree, Some(Box::new(rest))))
    }
}

/// l(p) = sign(p) ln(1 + |p|), the positions' transform.
fn log_transform(p: f32) -> f32 {
    p.signum() * p.abs().ln_1p()
}

/// The inverse of [`log_transform`].
fn inverse_log_transform(l: f32) -> f32 {
    l.signum() * l.abs().exp_m1()
}

/// The components of a quaternion in SOG's order: w, x, y, z.
fn wxyz(q: Quat) -> [f32; 4] {
    [q.w, q.x, q.y, q.z]
}

/// The three components kept when component `largest` (of w, x, y, z) is dropped.
const KEPT: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];

/// Decode a "smallest three" texel (an invalid tag gives the identity, as splat-transform reads
/// it).
fn unpack_quat(t: [u8; 4]) -> Quat {
    if t[3] < 252 {
        return Quat::IDENTITY;
    }
    let largest = usize::from(t[3] - 252);
    let mut q = [0.0f64; 4];
    for (k, &c) in KEPT[largest].iter().enumerate() {
        q[c] = (f64::from(t[k]) / 255.0 * 2.0 - 1.0) / std::f64::consts::SQRT_2;
    }
    q[largest] = (1.0 - q.iter().map(|v| v * v).sum::<f64>()).max(0.0).sqrt();
    crate::ply::unit_quaternion(q).unwrap_or(Quat::IDENTITY)
}

/// Encode a unit quaternion as a "smallest three" texel: the largest component made positive,
/// the others × √2 in [−1, 1] rounded to 8 bits.
fn pack_quat(q: Quat) -> [u8; 4] {
    let c = wxyz(q.normalize());
    let largest = (0..4).max_by(|&a, &b| c[a].abs().total_cmp(&c[b].abs())).unwrap_or(0);
    let sign = if c[largest] < 0.0 { -1.0 } else { 1.0 };
    let byte = |v: f32| ((v * sign * std::f32::consts::SQRT_2 * 0.5 + 0.5) * 255.0).round().clamp(0.0, 255.0) as u8;
    let [a, b, d] = KEPT[largest].map(|k| byte(c[k]));
    [a, b, d, 252 + largest as u8]
}

/// Write `scene` as SOG version 2: a `.sog` bundle, or, for a path ending in `meta.json`, that
/// file and the images beside it.
pub fn write_sog(path: &Path, scene: &Scene) -> Result<(), Error> {
    let files = encode_sog(scene).map_err(|kind| Error::new(path, kind))?;
    let io = |p: &Path, e: std::io::Error| Error::new(p, ErrorKind::Io(e));
    if crate::extension(path).as_deref() == Some("sog") {
        let entries: Vec<(&str, &[u8])> = files.iter().map(|(n, d)| (n.as_str(), d.as_slice())).collect();
        let bundle = zip::write_stored(&entries).map_err(|e| Error::new(path, ErrorKind::Sog(e)))?;
        return std::fs::write(path, bundle).map_err(|e| io(path, e));
    }
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    for (name, data) in &files {
        let file = if name == "meta.json" { path.to_path_buf() } else { dir.join(name) };
        std::fs::write(&file, data).map_err(|e| io(&file, e))?;
    }
    Ok(())
}

/// The files of a SOG version 2 encoding of `scene`: `meta.json` first, then the images.
pub fn encode_sog(scene: &Scene) -> Result<SogFiles, ErrorKind> {
    let n = scene.particles.len();
    if n == 0 {
        return Err(sog_error("no splats to write"));
    }
    let (width, height) = texture_size(n)?;
    let order = morton_order(scene);
    let particles: Vec<&Particle> = order.iter().map(|&i| &scene.particles[i]).collect();
    let images = Images { width, height };
    let mut files = Vec::new();
    let (means_meta, means) = images.means(&particles)?;
    files.extend(means);
    files.push((
        "quats.webp".into(),
        images.encode(&particles.iter().map(|p| pack_quat(p.rotation)).collect::<Vec<_>>())?,
    ));
    let log_scales: Vec<[f32; 3]> = particles.iter().map(|p| p.scale.to_array().map(f32::ln)).collect();
    let scales = Codebook::fit(log_scales.iter().flatten().copied());
    files.push(("scales.webp".into(), images.encode(&labels3(&scales, &log_scales, |_| 255))?));
    let dc: Vec<[f32; 3]> = particles.iter().map(|p| p.sh[0].to_array()).collect();
    let colours = Codebook::fit(dc.iter().flatten().copied());
    let alpha = |i: usize| (particles[i].opacity * 255.0).round().clamp(0.0, 255.0) as u8;
    files.push(("sh0.webp".into(), images.encode(&labels3(&colours, &dc, alpha))?));
    let mut meta = json!({
        "version": SOG_VERSION,
        "asset": { "generator": concat!("splat ", env!("CARGO_PKG_VERSION")) },
        "count": n,
        "means": { "mins": means_meta.0, "maxs": means_meta.1, "files": ["means_l.webp", "means_u.webp"] },
        "scales": { "codebook": scales.values, "files": ["scales.webp"] },
        "quats": { "files": ["quats.webp"] },
        "sh0": { "codebook": colours.values, "files": ["sh0.webp"] },
    });
    if crate::SceneFormat::Sog.records(scene.screen_filter) == ScreenFilter::Antialiased {
        meta["model"] = json!("antialiased");
    }
    if scene.sh_degree > 0 {
        let (sh_meta, sh_files) = images.sh_palette(&particles, scene.sh_degree)?;
        meta["shN"] = sh_meta;
        files.extend(sh_files);
    }
    let meta = serde_json::to_vec(&meta).map_err(|e| sog_error(e.to_string()))?;
    files.insert(0, ("meta.json".into(), meta));
    Ok(files)
}

/// The images' size for `n` splats, as splat-transform chooses it: width ⌈√n / 4⌉ · 4, height
/// ⌈n / width / 4⌉ · 4.
fn texture_size(n: usize) -> Result<(u32, u32), ErrorKind> {
    let width = ((n as f64).sqrt() / 4.0).ceil() as usize * 4;
    let height = n.div_ceil(width).div_ceil(4) * 4;
    if width > MAX_SIDE as usize || height > MAX_SIDE as usize {
        return Err(sog_error(format!("{n} splats need {width} × {height} texels, above WebP's {MAX_SIDE}")));
    }
    Ok((width as u32, height as u32))
}

/// The splats in Morton (Z-order) order of their positions, 10 bits an axis within the scene's
/// bounds: near splats in near texels, which the images compress better.
fn morton_order(scene: &Scene) -> Vec<usize> {
    let (lo, hi) = scene
        .particles
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p.mean), hi.max(p.mean)));
    let span = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    let code = |p: &Particle| {
        let q = ((p.mean - lo) / span * 1023.0).round().clamp(Vec3::ZERO, Vec3::splat(1023.0));
        spread(q.x as u32) | (spread(q.y as u32) << 1) | (spread(q.z as u32) << 2)
    };
    let mut order: Vec<usize> = (0..scene.particles.len()).collect();
    order.sort_by_key(|&i| code(&scene.particles[i]));
    order
}

/// Texels (one per splat) of images `width` × `height`.
struct Images {
    width: u32,
    height: u32,
}

impl Images {
    /// A lossless WebP of `texels` (one per splat; the rest of the image 0).
    fn encode(&self, texels: &[[u8; 4]]) -> Result<Vec<u8>, ErrorKind> {
        self.encode_sized(texels, self.width, self.height)
    }

    fn encode_sized(&self, texels: &[[u8; 4]], width: u32, height: u32) -> Result<Vec<u8>, ErrorKind> {
        let mut rgba = vec![0u8; 4 * (width as usize) * (height as usize)];
        for (out, t) in rgba.chunks_exact_mut(4).zip(texels) {
            out.copy_from_slice(t);
        }
        let mut bytes = Vec::new();
        image_webp::WebPEncoder::new(&mut bytes)
            .encode(&rgba, width, height, image_webp::ColorType::Rgba8)
            .map_err(|e| sog_error(format!("WebP encoding: {e}")))?;
        Ok(bytes)
    }

    /// The two position images, and the bounds of l(p) per axis.
    fn means(&self, particles: &[&Particle]) -> Result<(Bounds, SogFiles), ErrorKind> {
        let l: Vec<[f32; 3]> = particles.iter().map(|p| p.mean.to_array().map(log_transform)).collect();
        let mins = std::array::from_fn(|a| l.iter().map(|v| v[a]).fold(f32::INFINITY, f32::min));
        let maxs: [f32; 3] = std::array::from_fn(|a| l.iter().map(|v| v[a]).fold(f32::NEG_INFINITY, f32::max));
        let step = |a: usize, v: f32| {
            let span = if maxs[a] == mins[a] { 1.0 } else { maxs[a] - mins[a] };
            ((v - mins[a]) / span * 65535.0).round().clamp(0.0, 65535.0) as u16
        };
        let steps: Vec<[u16; 3]> = l.iter().map(|v| std::array::from_fn(|a| step(a, v[a]))).collect();
        let bytes = |high: bool| -> Vec<[u8; 4]> {
            let byte = |s: u16| if high { (s >> 8) as u8 } else { s as u8 };
            steps.iter().map(|s| [byte(s[0]), byte(s[1]), byte(s[2]), 255]).collect()
        };
        let files = vec![
            ("means_l.webp".to_string(), self.encode(&bytes(false))?),
            ("means_u.webp".to_string(), self.encode(&bytes(true))?),
        ];
        Ok(((mins, maxs), files))
    }

    /// The SH palette (k-means of the splats' bands 1 and up), its codebook, and the label and
    /// centroid images.
    fn sh_palette(&self, particles: &[&Particle], degree: u8) -> Result<(Value, SogFiles), ErrorKind> {
        let coeffs = sh_coeff_count(degree) - 1;
        // Channel-major, as a `.ply`'s f_rest: coefficient j of channel c at c · coeffs + j.
        let vectors: Vec<Vec<f32>> =
            particles.iter().map(|p| (0..3 * coeffs).map(|k| p.sh[1 + k % coeffs][k / coeffs]).collect()).collect();
        let palette = kmeans(&vectors, palette_size(particles.len()));
        let labels: Vec<[u8; 4]> = nearest_all(&vectors, &palette)
            .into_iter()
            .map(|label| {
                let [low, high] = (label as u16).to_le_bytes();
                [low, high, 0, 255]
            })
            .collect();
        let book = Codebook::fit(palette.iter().flatten().copied());
        let mut texels = Vec::with_capacity(palette.len() * coeffs);
        for centroid in &palette {
            for j in 0..coeffs {
                texels.push([
                    book.index(centroid[j]),
                    book.index(centroid[coeffs + j]),
                    book.index(centroid[2 * coeffs + j]),
                    255,
                ]);
            }
        }
        let rows = palette.len().div_ceil(PALETTE_ROW) as u32;
        let centroids = self.encode_sized(&texels, (PALETTE_ROW * coeffs) as u32, rows)?;
        let meta = json!({
            "count": palette.len(),
            "bands": degree,
            "codebook": book.values,
            "files": ["shN_centroids.webp", "shN_labels.webp"],
        });
        Ok((meta, vec![("shN_centroids.webp".into(), centroids), ("shN_labels.webp".into(), self.encode(&labels)?)]))
    }
}

/// Texels of three codebook indices and an alpha byte.
fn labels3(book: &Codebook, values: &[[f32; 3]], alpha: impl Fn(usize) -> u8) -> Vec<[u8; 4]> {
    values.iter().enumerate().map(|(i, v)| [book.index(v[0]), book.index(v[1]), book.index(v[2]), alpha(i)]).collect()
}

/// The SH palette's size: splat-transform's (1024 × a power of two up to 64, by the splat
/// count), at most [`MAX_PALETTE`] and the splat count.
fn palette_size(n: usize) -> usize {
    let power = ((n as f64 / 1024.0).log2().floor()).clamp(-10.0, 6.0);
    ((2f64.powf(power) * 1024.0) as usize).clamp(1, MAX_PALETTE).min(n)
}

/// A 1D codebook of 256 values (ascending), fitted by Lloyd's k-means on a histogram of the
/// values: each value is stored as the index of its nearest entry.
struct Codebook {
    values: Vec<f32>,
}

impl Codebook {
    /// Fit to `values` (finite ones; a codebook of zeros without any).
    fn fit(values: impl Iterator<Item = f32> + Clone) -> Self {
        const BINS: usize = 1 << 14;
        let finite = values.filter(|v| v.is_finite());
        let (lo, hi) = finite.clone().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if lo > hi {
            return Self { values: vec![0.0; CODEBOOK] };
        }
        // Histogram: per bin, the count and the sum of its values.
        let width = f64::from(hi - lo).max(f64::MIN_POSITIVE) / BINS as f64;
        let mut bins = vec![(0.0f64, 0.0f64); BINS];
        for v in finite {
            let b = ((f64::from(v - lo) / width) as usize).min(BINS - 1);
            bins[b].0 += 1.0;
            bins[b].1 += f64::from(v);
        }
        let bins: Vec<(f64, f64)> = bins.into_iter().filter(|b| b.0 > 0.0).map(|(n, s)| (n, s / n)).collect();
        let total: f64 = bins.iter().map(|b| b.0).sum();
        // Start at the quantiles, then Lloyd iterations over the bins' means.
        let mut centres: Vec<f64> = (0..CODEBOOK)
            .map(|k| {
                let target = (k as f64 + 0.5) / CODEBOOK as f64 * total;
                let mut seen = 0.0;
                bins.iter()
                    .find(|b| {
                        seen += b.0;
                        seen >= target
                    })
                    .map_or(f64::from(hi), |b| b.1)
            })
            .collect();
        for _ in 0..CODEBOOK_ITERATIONS {
            let mut sums = vec![(0.0f64, 0.0f64); CODEBOOK];
            for &(n, mean) in &bins {
                let k = nearest_sorted(&centres, mean);
                sums[k].0 += n;
                sums[k].1 += n * mean;
            }
            for (c, (n, s)) in centres.iter_mut().zip(sums) {
                if n > 0.0 {
                    *c = s / n;
                }
            }
            centres.sort_by(f64::total_cmp);
        }
        Self { values: centres.into_iter().map(|c| c as f32).collect() }
    }

    /// The index of the entry nearest `v`.
    fn index(&self, v: f32) -> u8 {
        nearest_sorted(&self.values, f64::from(v)) as u8
    }
}

/// The index of the value of ascending `sorted` nearest `v`.
fn nearest_sorted<T: Copy + Into<f64>>(sorted: &[T], v: f64) -> usize {
    let at = sorted.partition_point(|&c| c.into() < v);
    match at {
        0 => 0,
        at if at == sorted.len() => at - 1,
        at => {
            if v - sorted[at - 1].into() <= sorted[at].into() - v {
                at - 1
            } else {
                at
            }
        }
    }
}

/// `k` centroids of `vectors` by Lloyd's k-means, fitted on an evenly strided sample of at most
/// [`PALETTE_SAMPLE`] vectors, started from `k` of them evenly strided.
fn kmeans(vectors: &[Vec<f32>], k: usize) -> Vec<Vec<f32>> {
    let stride = vectors.len().div_ceil(PALETTE_SAMPLE).max(1);
    let sample: Vec<&Vec<f32>> = vectors.iter().step_by(stride).collect();
    let k = k.min(sample.len()).max(1);
    let mut centroids: Vec<Vec<f32>> = (0..k).map(|i| sample[i * sample.len() / k].clone()).collect();
    let dim = vectors.first().map_or(0, Vec::len);
    for _ in 0..KMEANS_ITERATIONS {
        let labels = nearest_all(&sample, &centroids);
        let mut sums = vec![(0usize, vec![0.0f64; dim]); k];
        for (v, &label) in sample.iter().zip(&labels) {
            sums[label].0 += 1;
            for (s, &x) in sums[label].1.iter_mut().zip(v.iter()) {
                *s += f64::from(x);
            }
        }
        for (c, (n, s)) in centroids.iter_mut().zip(sums) {
            if n > 0 {
                *c = s.iter().map(|&x| (x / n as f64) as f32).collect();
            }
        }
    }
    centroids
}

/// The nearest centroid of each vector, over the machine's threads.
fn nearest_all<V: AsRef<[f32]> + Sync>(vectors: &[V], centroids: &[Vec<f32>]) -> Vec<usize> {
    let nearest = |v: &V| {
        let v = v.as_ref();
        let distance = |c: &Vec<f32>| c.iter().zip(v).map(|(a, b)| (a - b) * (a - b)).sum::<f32>();
        (0..centroids.len()).min_by(|&a, &b| distance(&centroids[a]).total_cmp(&distance(&centroids[b]))).unwrap_or(0)
    };
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    let chunk = vectors.len().div_ceil(threads).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> =
            vectors.chunks(chunk).map(|part| s.spawn(move || part.iter().map(nearest).collect::<Vec<_>>())).collect();
        handles.into_iter().flat_map(|h| h.join().expect("a k-means thread panicked")).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_round_trip_within_a_step() {
        for (i, q) in
            [Quat::IDENTITY, Quat::from_xyzw(0.1, -0.7, 0.2, 0.68), Quat::from_rotation_y(3.0)].iter().enumerate()
        {
            let q = q.normalize();
            let back = unpack_quat(pack_quat(q));
            assert!(q.dot(back).abs() > 0.9999, "{i}: {q} → {back}");
        }
    }

    #[test]
    fn positions_transform_and_back() {
        for p in [-12.5f32, -0.01, 0.0, 0.3, 1000.0] {
            assert!((inverse_log_transform(log_transform(p)) - p).abs() <= 1e-5 * p.abs().max(1.0));
        }
    }

    #[test]
    fn a_codebook_stores_each_value_at_its_nearest_entry() {
        let values: Vec<f32> = (0..10_000).map(|i| ((i as f32) * 0.37).sin() * 3.0).collect();
        let book = Codebook::fit(values.iter().copied());
        assert_eq!(book.values.len(), CODEBOOK);
        let worst = values.iter().map(|&v| (book.values[usize::from(book.index(v))] - v).abs()).fold(0.0, f32::max);
        // 256 entries over [−3, 3]: a uniform grid would leave 6 / 512 ≈ 0.012.
        assert!(worst < 0.02, "{worst}");
    }

    /// A version 1 file (as splat-transform's `readSogV1` reads it: 8-bit steps between
    /// `mins` and `maxs`, a logit opacity, the count in `means.shape`) decodes to its values.
    #[test]
    fn version_1_files_decode_their_ranges() {
        let images = Images { width: 4, height: 4 };
        let one = |t: [u8; 4]| images.encode(&[t]).unwrap();
        let files: Vec<(&str, Vec<u8>)> = vec![
            ("means_l.webp", one([0, 0xff, 0, 255])),
            ("means_u.webp", one([0, 0xff, 0x80, 255])),
            ("quats.webp", one(pack_quat(Quat::from_rotation_z(0.5)))),
            ("scales.webp", one([0, 255, 51, 255])),
            ("sh0.webp", one([255, 0, 102, 255])),
        ];
        let meta = json!({
            "means": { "shape": [1, 3], "mins": [-1.0, -1.0, -1.0], "maxs": [1.0, 1.0, 1.0], "files": ["means_l.webp", "means_u.webp"] },
            "scales": { "mins": [-4.0, -4.0, -4.0], "maxs": [1.0, 1.0, 1.0], "files": ["scales.webp"] },
            "quats": { "files": ["quats.webp"] },
            "sh0": { "mins": [-2.0, -2.0, -2.0, -3.0], "maxs": [2.0, 2.0, 2.0, 3.0], "files": ["sh0.webp"] },
        });
        let load = |name: &str| files.iter().find(|(n, _)| *n == name).map(|(_, d)| d.clone()).ok_or(sog_error(name));
        let (scene, version) = parse_sog(&serde_json::to_vec(&meta).unwrap(), &load).unwrap();
        assert_eq!((version, scene.particles.len(), scene.sh_degree), (1, 1, 0));
        let p = &scene.particles[0];
        let l = |step: f32| inverse_log_transform(-1.0 + 2.0 * step / 65535.0);
        assert!((p.mean - Vec3::new(l(0.0), l(65535.0), l(32768.0))).abs().max_element() < 1e-6, "{}", p.mean);
        assert!((p.scale - Vec3::new((-4.0f32).exp(), 1f32.exp(), (-3.0f32).exp())).abs().max_element() < 1e-6);
        assert!((p.sh[0] - Vec3::new(2.0, -2.0, -2.0 + 4.0 * 0.4)).abs().max_element() < 1e-6, "{}", p.sh[0]);
        assert!((p.opacity - 1.0 / (1.0 + (-3.0f32).exp())).abs() < 1e-6);
        assert!(p.rotation.angle_between(Quat::from_rotation_z(0.5)) < 0.02);
    }

    #[test]
    fn texture_sizes_are_splat_transforms() {
        assert_eq!(texture_size(3000).unwrap(), (56, 56));
        assert_eq!(texture_size(1).unwrap(), (4, 4));
    }
}
