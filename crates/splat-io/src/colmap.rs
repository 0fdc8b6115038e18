//! COLMAP sparse reconstructions: `cameras.bin` + `images.bin` or `cameras.txt` + `images.txt`
//! (the `sparse/0` folder most 3DGS captures arrive with). Every camera model whose lens
//! [`splat_core::camera::Lens`] models is read with it (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL,
//! RADIAL, OPENCV, FULL_OPENCV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, OPENCV_FISHEYE,
//! THIN_PRISM_FISHEYE, SIMPLE_FISHEYE, FISHEYE, EQUIRECTANGULAR); the others (FOV,
//! RAD_TAN_THIN_PRISM_FISHEYE, the division models, EUCM) are refused by name.
//!
//! An image's pose is COLMAP's world-to-camera rotation q = (qw, qx, qy, qz) and translation
//! t: x_cam = R(q) x_world + t, camera axes x right, y down, z forward — the convention of
//! [`Camera`] itself. The views are returned sorted by image name, the order in which 3DGS
//! lists them in its `cameras.json` (`id` = index).

use crate::{Error, ErrorKind, read_file};
use glam::{DMat3, DQuat, DVec3, Mat3, Quat, Vec3};
use splat_core::Camera;
use splat_core::camera::{Distortion, Lens};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// One registered image: its name and the camera that took it.
#[derive(Clone, Debug)]
pub struct View {
    /// Image file name, as COLMAP stores it.
    pub name: String,
    /// The camera.
    pub camera: Camera,
}

/// A [`View`] with its pose in double precision, as COLMAP stores it (for what trainers compute
/// from the poses in f64, such as gsplat's normalised world).
#[derive(Clone, Debug)]
pub struct PosedView {
    /// The view.
    pub view: View,
    /// Camera-to-world rotation (columns: the camera's x right, y down, z forward in the world).
    pub rotation: DMat3,
    /// Camera centre in the world.
    pub centre: DVec3,
}

impl PosedView {
    /// Its pose: camera-to-world rotation and centre.
    pub fn pose(&self) -> crate::similarity::Pose {
        (self.rotation, self.centre)
    }
}

/// Intrinsics of a COLMAP camera.
#[derive(Clone, Copy, Debug)]
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    lens: Lens,
}

/// A pose and the id of its camera.
struct Pose {
    name: String,
    q: [f64; 4],
    t: [f64; 3],
    camera_id: u32,
}

fn colmap_error(message: impl Into<String>) -> ErrorKind {
    ErrorKind::Colmap(message.into())
}

/// Whether `path` is a COLMAP model: a folder with `images.bin` or `images.txt`, or one of
/// those files.
pub fn is_colmap(path: &Path) -> bool {
    model_files(path).is_some()
}

/// The (cameras, images) files of a model given as a folder or as either file.
fn model_files(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let in_dir = |dir: &Path, ext: &str| {
        let images = dir.join(format!("images.{ext}"));
        images.exists().then(|| (dir.join(format!("cameras.{ext}")), images))
    };
    if path.is_dir() {
        return in_dir(path, "bin").or_else(|| in_dir(path, "txt"));
    }
    let name = path.file_name()?.to_str()?;
    let ext = path.extension()?.to_str()?;
    let dir = path.parent().unwrap_or(Path::new("."));
    matches!(name, "images.bin" | "images.txt" | "cameras.bin" | "cameras.txt")
        .then(|| (dir.join(format!("cameras.{ext}")), dir.join(format!("images.{ext}"))))
}

/// Read every registered view of a COLMAP model (folder, `images.*` or `cameras.*`), sorted by
/// image name.
pub fn read_colmap(path: &Path) -> Result<Vec<View>, Error> {
    Ok(read_colmap_posed(path)?.into_iter().map(|p| p.view).collect())
}

/// The (cameras, images) files of the model at `path`, or an error naming what a model is.
fn model_files_of(path: &Path) -> Result<(PathBuf, PathBuf), Error> {
    model_files(path).ok_or_else(|| {
        Error::new(path, colmap_error("not a COLMAP model: expected a folder with images.bin or images.txt"))
    })
}

/// [`read_colmap`], each view with its pose in double precision.
pub fn read_colmap_posed(path: &Path) -> Result<Vec<PosedView>, Error> {
    let (cameras_path, images_path) = model_files_of(path)?;
    let binary = images_path.extension().is_some_and(|e| e == "bin");
    let cameras = read_file(&cameras_path)?;
    let images = read_file(&images_path)?;
    let intrinsics = if binary { parse_cameras_bin(&cameras) } else { parse_cameras_txt(&cameras) }
        .map_err(|kind| Error::new(&cameras_path, kind))?;
    let poses = if binary { parse_images_bin(&images) } else { parse_images_txt(&images) }
        .map_err(|kind| Error::new(&images_path, kind))?;
    views(&intrinsics, poses).map_err(|kind| Error::new(&images_path, kind))
}

/// The 3D points of the model at `path`: its `points3D.bin` or `points3D.txt`, beside its
/// `images.*`, in the file's order. They are the structure-from-motion points trainers start
/// their splats from.
pub fn read_points3d(path: &Path) -> Result<Vec<DVec3>, Error> {
    let (_, images_path) = model_files_of(path)?;
    let binary = images_path.extension().is_some_and(|e| e == "bin");
    let points_path = images_path.with_file_name(if binary { "points3D.bin" } else { "points3D.txt" });
    let data = read_file(&points_path)?;
    parse_points3d(&data, binary).map_err(|kind| Error::new(&points_path, kind))
}

/// The points of a `points3D.bin` (`binary`) or `points3D.txt`; a point whose coordinates are
/// not finite is refused.
pub fn parse_points3d(data: &[u8], binary: bool) -> Result<Vec<DVec3>, ErrorKind> {
    let points = if binary { parse_points3d_bin(data)? } else { parse_points3d_txt(data)? };
    match points.iter().position(|p| !p.is_finite()) {
        Some(i) => Err(colmap_error(format!("3D point {i} (0-based, in file order) is not finite: {}", points[i]))),
        None => Ok(points),
    }
}

fn parse_points3d_bin(data: &[u8]) -> Result<Vec<DVec3>, ErrorKind> {
    let mut b = Bytes { data, at: 0 };
    // id, x y z, r g b, error, track length: 51 bytes before the track.
    let n = b.count(51, "the 3D point count")?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        b.u64("a 3D point id")?;
        out.push(DVec3::new(b.f64("x")?, b.f64("y")?, b.f64("z")?));
        b.take(3 + 8, "a 3D point's colour and error")?;
        let track = b.count(8, "a track length")?;
        b.take(track * 8, "a track")?;
    }
    Ok(out)
}

fn parse_points3d_txt(data: &[u8]) -> Result<Vec<DVec3>, ErrorKind> {
    if std::str::from_utf8(data).is_err() {
        return Err(colmap_error("points3D.txt is not UTF-8 text"));
    }
    content_lines(data)
        .map(|(line, text)| {
            let words: Vec<&str> = text.split_whitespace().collect();
            let [_, x, y, z, _, _, _, _, ..] = words.as_slice() else {
                return Err(colmap_error(format!("line {line}: expected POINT3D_ID X Y Z R G B ERROR TRACK…")));
            };
            Ok(DVec3::new(number(line, x, "x")?, number(line, y, "y")?, number(line, z, "z")?))
        })
        .collect()
}

/// Parse a model from the bytes of its two files (`binary`: `.bin`, else `.txt`).
pub fn parse_colmap(cameras: &[u8], images: &[u8], binary: bool) -> Result<Vec<View>, ErrorKind> {
    let intrinsics = if binary { parse_cameras_bin(cameras)? } else { parse_cameras_txt(cameras)? };
    let poses = if binary { parse_images_bin(images)? } else { parse_images_txt(images)? };
    Ok(views(&intrinsics, poses)?.into_iter().map(|p| p.view).collect())
}

fn views(intrinsics: &HashMap<u32, Intrinsics>, mut poses: Vec<Pose>) -> Result<Vec<PosedView>, ErrorKind> {
    if poses.is_empty() {
        return Err(colmap_error("the model has no registered image"));
    }
    poses.sort_by(|a, b| a.name.cmp(&b.name));
    poses
        .into_iter()
        .map(|p| {
            let k = intrinsics.get(&p.camera_id).ok_or_else(|| {
                colmap_error(format!("image '{}' names camera {}, which cameras.* does not list", p.name, p.camera_id))
            })?;
            let [w, x, y, z] = p.q;
            let q = DQuat::from_xyzw(x, y, z, w);
            if !(q.length() > 1e-6 && q.is_finite()) {
                return Err(colmap_error(format!("image '{}': quaternion {:?} is not a rotation", p.name, p.q)));
            }
            let rotation = Mat3::from_quat(q.normalize().as_quat().normalize());
            let translation = DVec3::from(p.t).as_vec3();
            let world_from_camera = DMat3::from_quat(q.normalize()).transpose();
            let centre = -(world_from_camera * DVec3::from(p.t));
            let camera = Camera::from_intrinsics(
                k.width,
                k.height,
                k.fx as f32,
                k.fy as f32,
                k.cx as f32,
                k.cy as f32,
                rotation,
                translation,
            )
            .and_then(|c| c.with_lens(k.lens))
            .map_err(|e| colmap_error(format!("image '{}': {e}", p.name)))?;
            Ok(PosedView { view: View { name: p.name, camera }, rotation: world_from_camera, centre })
        })
        .collect()
}

/// COLMAP's camera models by id, with their parameter counts.
const MODELS: [(&str, usize); 18] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
    ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
    ("SIMPLE_DIVISION", 4),
    ("DIVISION", 5),
    ("SIMPLE_FISHEYE", 3),
    ("FISHEYE", 4),
    ("EUCM", 6),
    ("EQUIRECTANGULAR", 2),
];

/// A perspective lens of radial, rational and tangential coefficients.
fn perspective(radial: [f64; 4], rational: [f64; 3], tangential: [f64; 2]) -> Lens {
    Lens::Perspective(Distortion {
        radial: radial.map(|c| c as f32),
        rational: rational.map(|c| c as f32),
        tangential: tangential.map(|c| c as f32),
        prism: [0.0; 2],
    })
}

/// An equidistant fisheye lens of radial coefficients in θ.
fn fisheye(radial: [f64; 4]) -> Lens {
    Lens::Fisheye(Distortion { radial: radial.map(|c| c as f32), ..Distortion::default() })
}

fn intrinsics(id: u32, model: &str, width: u64, height: u64, params: &[f64]) -> Result<Intrinsics, ErrorKind> {
    if let Some(&(_, count)) = MODELS.iter().find(|(name, count)| *name == model && *count != params.len()) {
        return Err(colmap_error(format!("camera {id}: {model} takes {count} parameters, not {}", params.len())));
    }
    let (fx, fy, cx, cy, lens) = match (model, params) {
        ("SIMPLE_PINHOLE", &[f, cx, cy]) => (f, f, cx, cy, Lens::Pinhole),
        ("PINHOLE", &[fx, fy, cx, cy]) => (fx, fy, cx, cy, Lens::Pinhole),
        ("SIMPLE_RADIAL", &[f, cx, cy, k]) => (f, f, cx, cy, perspective([k, 0.0, 0.0, 0.0], [0.0; 3], [0.0; 2])),
        ("RADIAL", &[f, cx, cy, k1, k2]) => (f, f, cx, cy, perspective([k1, k2, 0.0, 0.0], [0.0; 3], [0.0; 2])),
        ("OPENCV", &[fx, fy, cx, cy, k1, k2, p1, p2]) => {
            (fx, fy, cx, cy, perspective([k1, k2, 0.0, 0.0], [0.0; 3], [p1, p2]))
        }
        ("FULL_OPENCV", &[fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6]) => {
            (fx, fy, cx, cy, perspective([k1, k2, k3, 0.0], [k4, k5, k6], [p1, p2]))
        }
        ("SIMPLE_RADIAL_FISHEYE", &[f, cx, cy, k]) => (f, f, cx, cy, fisheye([k, 0.0, 0.0, 0.0])),
        ("RADIAL_FISHEYE", &[f, cx, cy, k1, k2]) => (f, f, cx, cy, fisheye([k1, k2, 0.0, 0.0])),
        ("OPENCV_FISHEYE", &[fx, fy, cx, cy, k1, k2, k3, k4]) => (fx, fy, cx, cy, fisheye([k1, k2, k3, k4])),
        ("THIN_PRISM_FISHEYE", &[fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1]) => {
            let radial = [k1, k2, k3, k4].map(|c| c as f32);
            let (tangential, prism) = ([p1 as f32, p2 as f32], [sx1 as f32, sy1 as f32]);
            let lens = Lens::Fisheye(Distortion { radial, tangential, prism, ..Distortion::default() });
            (fx, fy, cx, cy, lens)
        }
        ("SIMPLE_FISHEYE", &[f, cx, cy]) => (f, f, cx, cy, fisheye([0.0; 4])),
        ("FISHEYE", &[fx, fy, cx, cy]) => (fx, fy, cx, cy, fisheye([0.0; 4])),
        ("EQUIRECTANGULAR", &[w, h]) => {
            if w != width as f64 || h != height as f64 {
                return Err(colmap_error(format!(
                    "camera {id}: an EQUIRECTANGULAR model of {w} × {h} for an image of {width} × {height} is not \
                     supported (they must agree)"
                )));
            }
            let [fx, fy, cx, cy] = equirectangular_intrinsics(w, h);
            (fx, fy, cx, cy, Lens::Equirectangular)
        }
        _ => {
            return Err(colmap_error(format!(
                "camera {id}: model {model} is not supported (the pinhole, radial, OpenCV, fisheye and \
                 equirectangular models are; undistort the images first, e.g. `colmap image_undistorter`)"
            )));
        }
    };
    let size = |v: u64, what: &str| {
        u32::try_from(v).ok().filter(|&v| v > 0).ok_or_else(|| colmap_error(format!("camera {id}: {what} {v}")))
    };
    if ![fx, fy, cx, cy].iter().all(|v| v.is_finite()) || fx <= 0.0 || fy <= 0.0 {
        return Err(colmap_error(format!("camera {id}: focal lengths and principal point {params:?} are unusable")));
    }
    Ok(Intrinsics { width: size(width, "width")?, height: size(height, "height")?, fx, fy, cx, cy, lens })
}

/// fx, fy, cx, cy an equirectangular camera of w × h pixels stores (its lens spans the whole
/// image and reads none of them): w / 2π pixels a radian and the image centre, so that the
/// pinhole fields stay meaningful.
pub(crate) fn equirectangular_intrinsics(w: f64, h: f64) -> [f64; 4] {
    let f = w / std::f64::consts::TAU;
    [f, f, 0.5 * w, 0.5 * h]
}

/// A little-endian reader that names what it was reading when the bytes run out.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ErrorKind> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.data.len()).ok_or_else(|| {
            colmap_error(format!(
                "truncated: {what} at byte {} needs {n} bytes, {} remain",
                self.at,
                self.data.len() - self.at
            ))
        })?;
        let out = &self.data[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u32(&mut self, what: &str) -> Result<u32, ErrorKind> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }

    fn u64(&mut self, what: &str) -> Result<u64, ErrorKind> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }

    fn f64(&mut self, what: &str) -> Result<f64, ErrorKind> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }

    /// A count of records of at least `min_bytes` each, checked against the bytes left.
    fn count(&mut self, min_bytes: usize, what: &str) -> Result<usize, ErrorKind> {
        let n = self.u64(what)?;
        let left = (self.data.len() - self.at) as u64;
        if n.saturating_mul(min_bytes as u64) > left {
            return Err(colmap_error(format!("truncated: {what} is {n} but only {left} bytes follow")));
        }
        Ok(n as usize)
    }
}

fn parse_cameras_bin(data: &[u8]) -> Result<HashMap<u32, Intrinsics>, ErrorKind> {
    let mut b = Bytes { data, at: 0 };
    let n = b.count(24, "the camera count")?;
    let mut out = HashMap::new();
    for _ in 0..n {
        let id = b.u32("a camera id")?;
        let model_id = b.u32("a camera model")? as usize;
        let (model, params) =
            *MODELS.get(model_id).ok_or_else(|| colmap_error(format!("camera {id}: unknown model id {model_id}")))?;
        let (width, height) = (b.u64("a width")?, b.u64("a height")?);
        let params = (0..params).map(|_| b.f64("a camera parameter")).collect::<Result<Vec<_>, _>>()?;
        out.insert(id, intrinsics(id, model, width, height, &params)?);
    }
    Ok(out)
}

fn parse_images_bin(data: &[u8]) -> Result<Vec<Pose>, ErrorKind> {
    let mut b = Bytes { data, at: 0 };
    let n = b.count(64, "the image count")?;
    let mut out = Vec::new();
    for _ in 0..n {
        let _image_id = b.u32("an image id")?;
        let q = [b.f64("qw")?, b.f64("qx")?, b.f64("qy")?, b.f64("qz")?];
        let t = [b.f64("tx")?, b.f64("ty")?, b.f64("tz")?];
        let camera_id = b.u32("a camera id")?;
        let rest = &b.data[b.at..];
        let len =
            rest.iter().position(|&c| c == 0).ok_or_else(|| colmap_error("an image name has no terminating NUL"))?;
        let name = String::from_utf8_lossy(b.take(len + 1, "an image name")?.split_last().expect("NUL").1).into_owned();
        let points = b.count(24, "a 2D point count")?;
        b.take(points * 24, "the 2D points")?;
        out.push(Pose { name, q, t, camera_id });
    }
    Ok(out)
}

/// The COLMAP model that holds a camera's lens, with its parameters: PINHOLE, FULL_OPENCV,
/// THIN_PRISM_FISHEYE or EQUIRECTANGULAR; an error for a distortion none of them holds.
fn model_of(c: &Camera) -> Result<(&'static str, Vec<f32>), ErrorKind> {
    let k = [c.fx, c.fy, c.cx, c.cy];
    Ok(match c.lens {
        Lens::Pinhole => ("PINHOLE", k.to_vec()),
        Lens::Perspective(d) if d.radial[3] == 0.0 && d.prism == [0.0; 2] => {
            let ([a1, a2, a3, _], [b1, b2, b3], [p1, p2]) = (d.radial, d.rational, d.tangential);
            ("FULL_OPENCV", [&k[..], &[a1, a2, p1, p2, a3, b1, b2, b3]].concat())
        }
        Lens::Fisheye(d) if d.rational == [0.0; 3] => {
            let ([a1, a2, a3, a4], [p1, p2], [s1, s2]) = (d.radial, d.tangential, d.prism);
            ("THIN_PRISM_FISHEYE", [&k[..], &[a1, a2, p1, p2, a3, a4, s1, s2]].concat())
        }
        Lens::Equirectangular => ("EQUIRECTANGULAR", vec![c.width as f32, c.height as f32]),
        lens => return Err(colmap_error(format!("no COLMAP camera model holds the lens {lens:?}"))),
    })
}

/// Lines that are neither blank nor comments, with their 1-based numbers.
fn content_lines(data: &[u8]) -> impl Iterator<Item = (usize, &str)> {
    std::str::from_utf8(data)
        .unwrap_or("")
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn number<T: std::str::FromStr>(line: usize, token: &str, what: &str) -> Result<T, ErrorKind> {
    token.parse().map_err(|_| colmap_error(format!("line {line}: {what} '{token}' is not a number")))
}

fn parse_cameras_txt(data: &[u8]) -> Result<HashMap<u32, Intrinsics>, ErrorKind> {
    if std::str::from_utf8(data).is_err() {
        return Err(colmap_error("cameras.txt is not UTF-8 text"));
    }
    let mut out = HashMap::new();
    for (line, text) in content_lines(data) {
        let words: Vec<&str> = text.split_whitespace().collect();
        let [id, model, width, height, params @ ..] = words.as_slice() else {
            return Err(colmap_error(format!("line {line}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS…")));
        };
        let id: u32 = number(line, id, "camera id")?;
        let params = params.iter().map(|p| number(line, p, "parameter")).collect::<Result<Vec<f64>, _>>()?;
        let k = intrinsics(id, model, number(line, width, "width")?, number(line, height, "height")?, &params)?;
        out.insert(id, k);
    }
    Ok(out)
}

fn parse_images_txt(data: &[u8]) -> Result<Vec<Pose>, ErrorKind> {
    let text = std::str::from_utf8(data).map_err(|_| colmap_error("images.txt is not UTF-8 text"))?;
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let mut out = Vec::new();
    // Each image is a pose line and a 2D-point line; the latter may be empty, so only the pose
    // lines skip blanks and comments (as COLMAP's own reader does).
    while let Some((line, pose)) = lines.find(|(_, l)| !l.is_empty() && !l.starts_with('#')) {
        let words: Vec<&str> = pose.split_whitespace().collect();
        let [_, qw, qx, qy, qz, tx, ty, tz, camera, name @ ..] = words.as_slice() else {
            return Err(colmap_error(format!("line {line}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")));
        };
        if name.is_empty() {
            return Err(colmap_error(format!("line {line}: the image has no name")));
        }
        let f = |t: &str, what: &str| number::<f64>(line, t, what);
        out.push(Pose {
            name: name.join(" "),
            q: [f(qw, "qw")?, f(qx, "qx")?, f(qy, "qy")?, f(qz, "qz")?],
            t: [f(tx, "tx")?, f(ty, "ty")?, f(tz, "tz")?],
            camera_id: number(line, camera, "camera id")?,
        });
        lines.next(); // the 2D points
    }
    Ok(out)
}

/// Write a model as `cameras.txt` and `images.txt` into `dir` (one camera per view, of the model
/// that holds its lens): for tests and for handing views to COLMAP-based tools.
pub fn write_colmap_txt(dir: &Path, views: &[View]) -> Result<(), Error> {
    let mut cameras = String::from("# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n");
    let mut images = String::from("# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then POINTS2D\n");
    for (i, v) in views.iter().enumerate() {
        let c = &v.camera;
        let (model, params) = model_of(c).map_err(|kind| Error::new(dir, kind))?;
        let params: Vec<String> = params.iter().map(f32::to_string).collect();
        cameras += &format!("{} {model} {} {} {}\n", i + 1, c.width, c.height, params.join(" "));
        let q = Quat::from_mat3(&c.rotation).normalize();
        let t: Vec3 = c.translation;
        images +=
            &format!("{} {} {} {} {} {} {} {} {} {}\n\n", i + 1, q.w, q.x, q.y, q.z, t.x, t.y, t.z, i + 1, v.name);
    }
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).map_err(|e| Error::new(&path, ErrorKind::Io(e)))
    };
    write("cameras.txt", &cameras)?;
    write("images.txt", &images)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `points3D.bin` of `points`, the i-th with a track of i elements.
    fn points3d_bin(points: &[[f64; 3]]) -> Vec<u8> {
        let mut out = (points.len() as u64).to_le_bytes().to_vec();
        for (i, p) in points.iter().enumerate() {
            out.extend((i as u64 + 10).to_le_bytes());
            p.iter().for_each(|c| out.extend(c.to_le_bytes()));
            out.extend([200, 100, 50]);
            out.extend(0.5f64.to_le_bytes());
            out.extend((i as u64).to_le_bytes());
            (0..i as u32).for_each(|j| out.extend([j.to_le_bytes(), (2 * j).to_le_bytes()].concat()));
        }
        out
    }

    #[test]
    fn points3d_read_alike_from_binary_and_text_and_bad_files_are_refused() {
        let points = [[1.0, -2.0, 3.5], [0.25, 1e-3, -7.0], [4.0, 5.0, 6.0]];
        let text = "# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                    10 1 -2 3.5 200 100 50 0.5\n11 0.25 0.001 -7 1 2 3 0.1 1 0\n\n12 4 5 6 0 0 0 2 1 0 2 2\n";
        let expected: Vec<DVec3> = points.iter().map(|&p| DVec3::from(p)).collect();
        assert_eq!(parse_points3d(&points3d_bin(&points), true).unwrap(), expected);
        assert_eq!(parse_points3d(text.as_bytes(), false).unwrap(), expected);
        let bin = points3d_bin(&points);
        for end in 0..bin.len() {
            let e = parse_points3d(&bin[..end], true).unwrap_err().to_string();
            assert!(e.contains("truncated"), "{end}: {e}");
        }
        let e = parse_points3d(&points3d_bin(&[[0.0, f64::NAN, 1.0]]), true).unwrap_err().to_string();
        assert!(e.contains("3D point 0") && e.contains("not finite"), "{e}");
        let e = parse_points3d(b"10 1 2 3 4 5 6\n", false).unwrap_err().to_string();
        assert!(e.contains("line 1: expected POINT3D_ID"), "{e}");
        let e = parse_points3d(b"10 1 y 3 4 5 6 0.5\n", false).unwrap_err().to_string();
        assert!(e.contains("line 1: y 'y' is not a number"), "{e}");
    }
}
