//! `transforms.json` camera files: the NeRF-synthetic (Blender) files 3DGS reads
//! (`transforms_train.json`, `transforms_test.json`: a horizontal field of view
//! `camera_angle_x` and each frame's `transform_matrix`), and the richer files of Nerfstudio
//! (`ns-process-data`), instant-ngp and Brush: intrinsics `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h`
//! and a lens (`camera_model`, distortion `k1`–`k4`, `p1`, `p2` or `distortion_params`), at the
//! top level for every frame or in a frame for itself. A key given in both must agree: Nerfstudio
//! reads the file's and Brush the frame's, so a file where they differ is refused, not read one
//! trainer's way.
//!
//! **Pose.** A frame's `transform_matrix` (4 × 4, or its top 3 × 4) is camera-to-world with
//! OpenGL's camera axes (x right, y up, z backwards). The camera's OpenCV axes, the convention of
//! [`Camera`], are its columns x, −y, −z: with C the matrix's rotation and c its last column
//! (the camera's centre), the world-to-camera rotation is R = diag(1, −1, −1) Cᵀ and t = −R c
//! (3DGS's `readCamerasFromTransforms`: `c2w[:3, 1:3] *= -1`, then the inverse). The world is the
//! file's own, where splats trained from it live (3DGS on NeRF-synthetic scenes, Brush, ...):
//! `applied_transform` (what `ns-process-data` did to COLMAP's world) is not undone. Nerfstudio
//! trains in a normalised world instead, and splatfacto exports its splats there: given the
//! run's `dataparser_transforms.json` ([`Dataparser`], [`parse_transforms_in`]), the cameras are
//! moved into that world as Nerfstudio's dataparser moves them.
//!
//! **Intrinsics.** fx is `fl_x`, else w / (2 tan(`camera_angle_x` / 2)); fy is `fl_y`, else from
//! `camera_angle_y`, else fx (3DGS's `focal2fov(fov2focal(fovx, W), H)` is fy = fx). The
//! principal point is (`cx`, `cy`), else the image centre. The image size is (`w`, `h`), else the
//! frame's image's (a PNG's or JPEG's header; `file_path` relative to the file, `.png` added where it has no
//! extension, as 3DGS and Brush add it).
//!
//! **Lens** (Nerfstudio's `CAMERA_MODEL_TO_TYPE`): no `camera_model`, `SIMPLE_PINHOLE`,
//! `PINHOLE`, `SIMPLE_RADIAL`, `RADIAL` and `OPENCV` are perspective lenses and
//! `OPENCV_FISHEYE` the equidistant fisheye, each distorting its normalised coordinates by
//! radial k1–k4 (in r², or in θ² for the fisheye) and tangential p1, p2, as Nerfstudio's
//! `radial_and_tangential_undistort` inverts them ([`Distortion`]); without distortion a
//! perspective lens is the pinhole. `EQUIRECTANGULAR` is [`Lens::Equirectangular`], Nerfstudio's
//! whole sphere (its fl_x = w / 2, fl_y = h, cx = w / 2, cy = h / 2; no distortion). Other
//! models, an equirectangular camera over part of the sphere, instant-ngp's `is_fisheye` and
//! distortion coefficients no model here holds are refused by name, never dropped.
//!
//! Views keep the file's order (3DGS's and Brush's; Nerfstudio sorts by file name), named by
//! their `file_path`.

use crate::similarity::{Similarity, affine_rows};
use crate::{Error, ErrorKind, read_file};
use glam::{DMat3, DVec3};
use serde::Deserialize;
use splat_core::Camera;
use splat_core::camera::{Distortion, Lens};
use std::path::Path;

/// The intrinsics and lens keys, at the top level or in a frame.
#[derive(Clone, Debug, Default, Deserialize)]
struct Intrinsics {
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    camera_model: Option<String>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
    /// Nerfstudio's [k1, k2, k3, k4, p1, p2], in place of the keys.
    distortion_params: Option<Vec<f64>>,
    /// Coefficients of FULL_OPENCV's rational model, which Nerfstudio's cameras do not take.
    k5: Option<f64>,
    k6: Option<f64>,
    /// instant-ngp's fisheye flag.
    is_fisheye: Option<bool>,
}

impl Intrinsics {
    /// The keys of a frame (`self`) merged with the file's (`top`): a key given in one is taken
    /// from it; given in both, the two must agree, since Nerfstudio reads the file's and Brush
    /// the frame's. The distortion is one key, as Nerfstudio reads it: the merged keys hold it
    /// in `distortion_params` alone.
    fn merged(&self, top: &Intrinsics) -> Result<Intrinsics, String> {
        let distortion = merge("the distortion", self.distortion()?, top.distortion()?)?;
        Ok(Intrinsics {
            camera_angle_x: merge("camera_angle_x", self.camera_angle_x, top.camera_angle_x)?,
            camera_angle_y: merge("camera_angle_y", self.camera_angle_y, top.camera_angle_y)?,
            fl_x: merge("fl_x", self.fl_x, top.fl_x)?,
            fl_y: merge("fl_y", self.fl_y, top.fl_y)?,
            cx: merge("cx", self.cx, top.cx)?,
            cy: merge("cy", self.cy, top.cy)?,
            w: merge("w", self.w, top.w)?,
            h: merge("h", self.h, top.h)?,
            camera_model: merge("camera_model", self.camera_model.clone(), top.camera_model.clone())?,
            distortion_params: distortion.map(Vec::from),
            k5: merge("k5", self.k5, top.k5)?,
            k6: merge("k6", self.k6, top.k6)?,
            is_fisheye: self.is_fisheye.or(top.is_fisheye),
            ..Intrinsics::default()
        })
    }

    /// Nerfstudio's [k1, k2, k3, k4, p1, p2] at this level, if it gives any.
    fn distortion(&self) -> Result<Option<[f64; 6]>, String> {
        if let Some(d) = &self.distortion_params {
            return <[f64; 6]>::try_from(d.as_slice()).map(Some).map_err(|_| {
                format!("distortion_params has {} values, not Nerfstudio's 6 (k1, k2, k3, k4, p1, p2)", d.len())
            });
        }
        let keys = [self.k1, self.k2, self.k3, self.k4, self.p1, self.p2];
        Ok(keys.iter().any(Option::is_some).then(|| keys.map(|k| k.unwrap_or(0.0))))
    }

    /// The lens of `camera_model` with its distortion.
    fn lens(&self) -> Result<Lens, String> {
        if self.is_fisheye == Some(true) {
            return Err("instant-ngp's `is_fisheye` is not read: give `camera_model: OPENCV_FISHEYE` and \
                        its k1–k4 instead"
                .into());
        }
        if [self.k5, self.k6].into_iter().flatten().any(|k| k != 0.0) {
            return Err("k5 and k6 (FULL_OPENCV's rational distortion) are not a Nerfstudio camera's".into());
        }
        let [k1, k2, k3, k4, p1, p2] = self.distortion()?.unwrap_or([0.0; 6]);
        let distortion = Distortion {
            radial: [k1, k2, k3, k4].map(|k| k as f32),
            tangential: [p1, p2].map(|p| p as f32),
            ..Distortion::default()
        };
        match self.camera_model.as_deref() {
            None | Some("SIMPLE_PINHOLE" | "PINHOLE" | "SIMPLE_RADIAL" | "RADIAL" | "OPENCV") => {
                Ok(if distortion == Distortion::default() { Lens::Pinhole } else { Lens::Perspective(distortion) })
            }
            Some("OPENCV_FISHEYE") => Ok(Lens::Fisheye(distortion)),
            // Nerfstudio applies no distortion to an equirectangular image.
            Some("EQUIRECTANGULAR") => Ok(Lens::Equirectangular),
            Some(other) => Err(format!(
                "camera_model {other} is not supported (the pinhole, radial, OPENCV, OPENCV_FISHEYE and \
                 EQUIRECTANGULAR models are)"
            )),
        }
    }
}

/// A key of a frame and of the file, as [`Intrinsics::merged`] takes it.
fn merge<T: PartialEq + std::fmt::Debug>(name: &str, frame: Option<T>, file: Option<T>) -> Result<Option<T>, String> {
    match (frame, file) {
        (Some(f), Some(t)) if f != t => Err(format!(
            "{name} {f:?} differs from the file's {t:?} (Nerfstudio reads the file's, Brush the frame's): give it once"
        )),
        (f, t) => Ok(f.or(t)),
    }
}

/// One frame: its image, pose and own intrinsics.
#[derive(Debug, Deserialize)]
struct Frame {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    intrinsics: Intrinsics,
}

/// The file: intrinsics shared by its frames, and the frames.
#[derive(Debug, Deserialize)]
struct Transforms {
    frames: Vec<Frame>,
    /// What `ns-process-data` applied to the data's original coordinates (3 × 4).
    applied_transform: Option<Vec<Vec<f64>>>,
    /// The scale it applied to them.
    applied_scale: Option<f64>,
    #[serde(flatten)]
    intrinsics: Intrinsics,
}

/// A Nerfstudio training run's `dataparser_transforms.json` (`{"transform": 3 × 4, "scale": s}`):
/// the map x ↦ s (R x + t) from the data's original coordinates (before the `transforms.json`'s
/// `applied_transform`) to the run's normalised world, where splatfacto trains and exports its
/// splats. Given to [`parse_transforms_in`], it moves a file's cameras into that world as
/// Nerfstudio's dataparser does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dataparser {
    /// [R | t], rigid.
    transform: Similarity,
    scale: f64,
}

/// Read a `dataparser_transforms.json`.
pub fn read_dataparser(path: &Path) -> Result<Dataparser, Error> {
    parse_dataparser(&read_file(path)?).map_err(|kind| Error::new(path, kind))
}

/// Parse a `dataparser_transforms.json`.
pub fn parse_dataparser(bytes: &[u8]) -> Result<Dataparser, ErrorKind> {
    #[derive(Deserialize)]
    struct File {
        transform: Vec<Vec<f64>>,
        scale: f64,
    }
    let file: File = serde_json::from_slice(bytes)?;
    let transform = Similarity::from_rows(&file.transform, "transform", true).map_err(ErrorKind::Dataparser)?;
    if !(file.scale.is_finite() && file.scale > 0.0) {
        return Err(ErrorKind::Dataparser(format!("scale {} is not a positive number", file.scale)));
    }
    Ok(Dataparser { transform, scale: file.scale })
}

/// What `ns-process-data` applied to COLMAP's world before `applied_transform` was written
/// down: Nerfstudio assumes it for a file without one whose folder holds `colmap/sparse/0`.
const LEGACY_APPLIED: [[f64; 4]; 3] = [[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0]];

impl Transforms {
    /// The map of this file's camera centres and axes into `dataparser`'s world, and the scale
    /// its centres then take: Nerfstudio's training poses are [T A⁻¹ P] with the translation
    /// times s / `applied_scale` (its dataparser orients the file's poses, then scales their
    /// centres by its own factor, and saves T after A and s times `applied_scale`).
    fn to_run_world(&self, dataparser: &Dataparser, folder: Option<&Path>) -> Result<Similarity, String> {
        let legacy = || folder.is_some_and(|f| f.join("colmap/sparse/0").is_dir());
        let applied = match &self.applied_transform {
            Some(rows) => Similarity::from_rows(rows, "applied_transform", true)?,
            None if legacy() => Similarity::from_rows(&LEGACY_APPLIED.map(Vec::from), "applied_transform", true)?,
            None => Similarity::IDENTITY,
        };
        let applied_scale = self.applied_scale.unwrap_or(1.0);
        if !(applied_scale.is_finite() && applied_scale > 0.0) {
            return Err(format!("applied_scale {applied_scale} is not a positive number"));
        }
        let scale = Similarity { scale: dataparser.scale / applied_scale, ..Similarity::IDENTITY };
        Ok(applied.inverse().then(dataparser.transform).then(scale))
    }
}

/// Whether `bytes` look like a `transforms.json` rather than a `cameras.json`: a JSON object
/// (a `cameras.json` is a list).
pub fn is_transforms(bytes: &[u8]) -> bool {
    bytes.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{')
}

/// The split lists a Nerfstudio `transforms.json` names (`train_filenames`, `val_filenames`,
/// `test_filenames`), which its dataparser uses in place of its fraction split: each list's key
/// and its file paths. A list that is not a list of paths is refused by its key.
pub fn split_lists(bytes: &[u8]) -> Result<Vec<(&'static str, Vec<String>)>, String> {
    let keys = ["train_filenames", "val_filenames", "test_filenames"];
    let mut meta = serde_json::from_slice::<serde_json::Map<String, serde_json::Value>>(bytes).unwrap_or_default();
    let list = |key: &'static str| {
        let value = meta.remove(key)?;
        Some(
            serde_json::from_value(value)
                .map(|paths| (key, paths))
                .map_err(|_| format!("{key} is not a list of paths")),
        )
    };
    keys.into_iter().filter_map(list).collect()
}

/// The `transforms.json` a folder holds, if it holds one.
pub fn in_folder(path: &Path) -> Option<std::path::PathBuf> {
    let file = path.join("transforms.json");
    (path.is_dir() && file.is_file()).then_some(file)
}

/// Every view of the `transforms.json` at `path`, named by `file_path`, in the file's order.
pub fn read_transforms(path: &Path) -> Result<Vec<(String, Camera)>, Error> {
    views_of(path, &read_file(path)?, None)
}

/// [`read_transforms`] of the file's `bytes`, in `dataparser`'s world when given.
pub(crate) fn views_of(
    path: &Path,
    bytes: &[u8],
    dataparser: Option<&Dataparser>,
) -> Result<Vec<(String, Camera)>, Error> {
    let folder = path.parent().unwrap_or(Path::new("."));
    parse_transforms_in(bytes, Some(folder), dataparser).map_err(|kind| Error::new(path, kind))
}

/// Parse a `transforms.json`; a frame without `w` and `h` takes its image's size, looked up
/// relative to `folder` (refused where there is none).
pub fn parse_transforms(bytes: &[u8], folder: Option<&Path>) -> Result<Vec<(String, Camera)>, ErrorKind> {
    parse_transforms_in(bytes, folder, None)
}

/// [`parse_transforms`], the cameras moved into a Nerfstudio training run's world when its
/// `dataparser` transforms are given.
pub fn parse_transforms_in(
    bytes: &[u8],
    folder: Option<&Path>,
    dataparser: Option<&Dataparser>,
) -> Result<Vec<(String, Camera)>, ErrorKind> {
    let file: Transforms = serde_json::from_slice(bytes)?;
    if file.frames.is_empty() {
        return Err(ErrorKind::Camera { index: 0, message: "the file lists no frame".into() });
    }
    let world = match dataparser {
        Some(d) => file.to_run_world(d, folder).map_err(ErrorKind::Dataparser)?,
        None => Similarity::IDENTITY,
    };
    file.frames
        .iter()
        .enumerate()
        .map(|(index, frame)| {
            let camera = frame
                .intrinsics
                .merged(&file.intrinsics)
                .and_then(|k| frame_camera(frame, &k, folder, world))
                .map_err(|e| ErrorKind::Camera { index, message: format!("'{}': {e}", frame.file_path) })?;
            Ok((frame.file_path.clone(), camera))
        })
        .collect()
}

/// The camera of `frame` with intrinsics `k` (its own and the file's, merged), its pose moved by
/// `world`.
fn frame_camera(frame: &Frame, k: &Intrinsics, folder: Option<&Path>, world: Similarity) -> Result<Camera, String> {
    let (rotation, centre) = world.pose(affine_rows(&frame.transform_matrix, "transform_matrix")?);
    let (width, height) = match (k.w, k.h) {
        (Some(w), Some(h)) => (side(w, "w")?, side(h, "h")?),
        _ => image_size(&frame.file_path, folder)?,
    };
    let lens = k.lens()?;
    let [fx, fy, cx, cy] = match lens {
        Lens::Equirectangular => equirectangular(k, width, height)?,
        _ => perspective(k, &lens, width, height)?,
    };
    // OpenGL's camera axes to OpenCV's: R = diag(1, −1, −1) Cᵀ, t = −R c.
    let r = DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0)) * rotation.transpose();
    let t = -(r * centre);
    Camera::from_intrinsics(width, height, fx as f32, fy as f32, cx as f32, cy as f32, r.as_mat3(), t.as_vec3())
        .and_then(|c| c.with_lens(lens))
        .map_err(|e| e.to_string())
}

/// fx, fy, cx, cy of a perspective or fisheye lens: `fl_x`, else from `camera_angle_x` (a
/// perspective lens's only); fy likewise, else fx; the principal point, else the image centre.
fn perspective(k: &Intrinsics, lens: &Lens, width: u32, height: u32) -> Result<[f64; 4], String> {
    let focal = |fl: Option<f64>, angle: Option<f64>, side: u32, axis: &str| match (fl, angle) {
        (Some(f), _) => Ok(Some(f)),
        (None, Some(a)) if !matches!(lens, Lens::Fisheye(_)) => Ok(Some(0.5 * f64::from(side) / (0.5 * a).tan())),
        (None, Some(_)) => Err(format!("a fisheye's focal length is fl_{axis}, not camera_angle_{axis}")),
        (None, None) => Ok(None),
    };
    let (fx, fy) = match (focal(k.fl_x, k.camera_angle_x, width, "x")?, focal(k.fl_y, k.camera_angle_y, height, "y")?) {
        (Some(fx), fy) => (fx, fy.unwrap_or(fx)),
        (None, Some(fy)) => (fy, fy),
        (None, None) => return Err("no focal length: give fl_x (and fl_y) or camera_angle_x".into()),
    };
    Ok([fx, fy, k.cx.unwrap_or(0.5 * f64::from(width)), k.cy.unwrap_or(0.5 * f64::from(height))])
}

/// fx, fy, cx, cy of an equirectangular lens, which spans the whole image: Nerfstudio maps
/// ((u − cx) / fx, (v − cy) / fy) to the azimuth −π … π and the elevation, so its whole sphere
/// is fl_x = w / 2, fl_y = h, cx = w / 2, cy = h / 2 (what its `cameras.py` assumes), and
/// [`Lens::Equirectangular`] is that map (the azimuth from −π at the left edge, forward at the
/// centre, the elevation +π/2 at the top). A camera that names other values covers part of
/// the sphere, which no lens here models. Stored as COLMAP's are
/// ([`crate::colmap::equirectangular_intrinsics`]).
fn equirectangular(k: &Intrinsics, width: u32, height: u32) -> Result<[f64; 4], String> {
    let (w, h) = (f64::from(width), f64::from(height));
    for (name, given, whole) in
        [("fl_x", k.fl_x, 0.5 * w), ("fl_y", k.fl_y, h), ("cx", k.cx, 0.5 * w), ("cy", k.cy, 0.5 * h)]
    {
        if given.is_some_and(|v| (v - whole).abs() > 1e-6 * whole) {
            return Err(format!(
                "an EQUIRECTANGULAR camera with {name} {} covers part of the sphere; its whole sphere is fl_x = w / 2, \
                 fl_y = h, cx = w / 2, cy = h / 2 ({name} = {whole})",
                given.unwrap_or_default()
            ));
        }
    }
    Ok(crate::colmap::equirectangular_intrinsics(w, h))
}

/// An image side given as a JSON number (Nerfstudio writes integers, some tools floats).
fn side(v: f64, name: &str) -> Result<u32, String> {
    (v >= 1.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX))
        .then_some(v as u32)
        .ok_or_else(|| format!("{name} = {v} is not a whole number of pixels"))
}

/// The size of a frame's image, from its header.
fn image_size(file_path: &str, folder: Option<&Path>) -> Result<(u32, u32), String> {
    let missing = "no w and h, and no image to take them from";
    let folder = folder.ok_or(missing)?;
    let mut image = folder.join(file_path);
    if image.extension().is_none() {
        image.set_extension("png");
    }
    let size = image::ImageReader::open(&image)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| e.to_string())
        .and_then(|r| r.into_dimensions().map_err(|e| e.to_string()));
    size.map_err(|e| format!("{missing} ({}: {e}; PNG and JPEG headers are read): give w and h", image.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A NeRF-synthetic file of one frame: a camera at (0, 0, 4) looking down −z, OpenGL axes.
    const BLENDER: &str = r#"{"camera_angle_x": 0.6911112070083618, "frames": [
        {"file_path": "./train/r_0", "rotation": 0.0, "transform_matrix":
            [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]}]}"#;

    fn one(json: &str) -> Result<Camera, ErrorKind> {
        parse_transforms(json.as_bytes(), None).map(|views| views[0].1)
    }

    fn message(json: &str) -> String {
        one(json).unwrap_err().to_string()
    }

    #[test]
    fn a_blender_camera_looks_down_its_minus_z_with_the_fov_it_names() {
        let json = BLENDER.replace(r#""frames""#, r#""w": 800, "h": 600, "frames""#);
        let views = parse_transforms(json.as_bytes(), None).unwrap();
        let (name, c) = &views[0];
        assert_eq!(name, "./train/r_0");
        assert!((c.center() - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6, "{}", c.center());
        // The world's origin is straight ahead, and world +y is up the image (pixel y down).
        let ahead = c.rotation * Vec3::ZERO + c.translation;
        assert!((ahead - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6, "{ahead}");
        assert!((c.rotation * Vec3::Y).y < -0.999);
        let fx = 400.0 / (0.5 * 0.6911112070083618f64).tan();
        assert!(((c.fx as f64) - fx).abs() < 1e-3 && c.fy == c.fx && (c.cx, c.cy) == (400.0, 300.0), "{c:?}");
        assert_eq!((c.width, c.height, c.lens), (800, 600, Lens::Pinhole));
    }

    #[test]
    fn frames_take_the_files_intrinsics_and_lenses_nerfstudios_coefficients() {
        let json = r#"{"fl_y": 510, "cy": 240, "w": 640, "h": 480, "camera_model": "OPENCV", "frames": [
            {"file_path": "a.jpg", "fl_x": 500, "cx": 320, "k1": 0.1, "k2": -0.02, "p1": 0.001, "p2": -0.002,
             "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]},
            {"file_path": "b.jpg", "fl_x": 700, "cx": 300, "fl_y": 510, "distortion_params": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
             "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]}"#;
        let views = parse_transforms(json.as_bytes(), None).unwrap();
        let a = views[0].1;
        let expected = Distortion { radial: [0.1, -0.02, 0.0, 0.0], tangential: [0.001, -0.002], ..Default::default() };
        assert_eq!((a.fx, a.fy, a.cx, a.cy, a.lens), (500.0, 510.0, 320.0, 240.0, Lens::Perspective(expected)));
        let b = views[1].1;
        let expected = Distortion { radial: [0.1, 0.2, 0.3, 0.4], tangential: [0.5, 0.6], ..Default::default() };
        assert_eq!((b.fx, b.fy, b.cx, b.cy, b.lens), (700.0, 510.0, 300.0, 240.0, Lens::Perspective(expected)));
        // A key in both the file and a frame must agree (Nerfstudio reads the file's, Brush the frame's).
        let both = json.replace(r#""fl_y": 510, "cy""#, r#""fl_y": 510, "k3": 0.5, "cy""#);
        assert!(parse_transforms(both.as_bytes(), None).unwrap_err().to_string().contains("the distortion"));
        let differs = json.replace(r#""fl_y": 510, "distortion"#, r#""fl_y": 511, "distortion"#);
        let message = parse_transforms(differs.as_bytes(), None).unwrap_err().to_string();
        assert!(message.contains("camera 1: 'b.jpg': fl_y 511.0 differs from the file's 510.0"), "{message}");
        let fisheye = json.replace("\"OPENCV\"", "\"OPENCV_FISHEYE\"");
        assert!(matches!(one(&fisheye).unwrap().lens, Lens::Fisheye(_)));
        let plain = r#"{"fl_x": 500, "w": 640, "h": 480, "frames": [
            {"file_path": "a", "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]}]}"#;
        assert_eq!(one(plain).unwrap().lens, Lens::Pinhole);
    }

    #[test]
    fn what_the_reader_cannot_honour_is_refused_by_name() {
        let sized = BLENDER.replace(r#""frames""#, r#""w": 800, "h": 600, "frames""#);
        let cases = [
            (BLENDER.to_string(), "no w and h, and no image"),
            (sized.replace("0.6911112070083618", "0.7, \"camera_model\": \"VR180_L\""), "camera_model VR180_L"),
            (
                sized.replace("0.6911112070083618", "0.7, \"camera_model\": \"EQUIRECTANGULAR\", \"fl_x\": 300"),
                "fl_x 300 covers part of the sphere",
            ),
            (
                sized.replace("0.6911112070083618", "0.7, \"camera_model\": \"OPENCV_FISHEYE\""),
                "fl_x, not camera_angle_x",
            ),
            (sized.replace("0.6911112070083618", "0.7, \"is_fisheye\": true"), "is_fisheye"),
            (sized.replace("0.6911112070083618", "0.7, \"k5\": 0.1"), "k5"),
            (sized.replace("0.6911112070083618", "0.7, \"distortion_params\": [0.1]"), "1 values"),
            (sized.replace("\"camera_angle_x\": 0.6911112070083618, ", ""), "no focal length"),
            (sized.replace("[0, 0, 0, 1]]", "[0, 0, 1, 1]]"), "last row"),
            (sized.replace("[0, 1, 0, 0]", "[0, 1, 0]"), "not 4 × 4"),
            (sized.replace("[1, 0, 0, 0]", "[2, 0, 0, 0]"), "not a proper rotation"),
            (sized.replace("\"w\": 800", "\"w\": 800.5"), "w = 800.5"),
            (r#"{"frames": []}"#.into(), "no frame"),
            (r#"{"fl_x": 1}"#.into(), "frames"),
        ];
        for (json, expected) in cases {
            let message = message(&json);
            assert!(message.contains(expected), "{expected}: {message}");
        }
        assert!(message(&BLENDER.replace("{\"camera", "{\"w\": 8, \"h\": 6, \"fl_x\": 1e40, \"camera")).contains("fx"));
    }

    #[test]
    fn dataparser_transforms_are_a_rigid_map_and_a_scale_or_refused() {
        let identity = r#"{"transform": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], "scale": 1.0}"#;
        let d = parse_dataparser(identity.as_bytes()).unwrap();
        assert_eq!((d.transform, d.scale), (Similarity::IDENTITY, 1.0));
        // The identity run leaves a file's cameras where they were.
        let json = BLENDER.replace(r#""frames""#, r#""w": 8, "h": 6, "frames""#);
        let moved = parse_transforms_in(json.as_bytes(), None, Some(&d)).unwrap();
        assert_eq!(moved, parse_transforms(json.as_bytes(), None).unwrap());
        let cases = [
            (identity.replace("1.0}", "0.0}"), "scale 0 is not a positive number"),
            (identity.replace("[[1, 0, 0, 0]", "[[2, 0, 0, 0]"), "not a rotation"),
            (identity.replace("[[1, 0, 0, 0]", "[[-1, 0, 0, 0]"), "it is a mirror"),
            (identity.replace("[0, 0, 1, 0]]", "[0, 0, 1]]"), "not 4 × 4"),
            (r#"{"scale": 1.0}"#.into(), "missing field `transform`"),
        ];
        for (json, expected) in cases {
            let message = parse_dataparser(json.as_bytes()).unwrap_err().to_string();
            assert!(message.contains(expected), "{expected}: {message}");
        }
        let bad_applied = json.replace(r#""w": 8"#, r#""applied_transform": [[1, 0, 0, 0], [0, 1, 0, 0]], "w": 8"#);
        let message = parse_transforms_in(bad_applied.as_bytes(), None, Some(&d)).unwrap_err().to_string();
        assert!(message.contains("applied_transform is 2 rows"), "{message}");
    }

    /// Nerfstudio's equirectangular ray of a pixel (`cameras.py`, `_generate_rays_from_coords`:
    /// the pixel's centre, ((u − cx) / fx, −(v − cy) / fy), then θ = −π x, φ = π (0.5 − y) and
    /// (−sin θ sin φ, cos φ, −cos θ sin φ) in OpenGL camera axes, rotated by the pose) is the
    /// camera's: within 1e-5 at every pixel of a 16 × 8 image, for a turned pose, with the
    /// whole sphere's intrinsics given and left out.
    #[test]
    fn equirectangular_rays_are_nerfstudios() {
        let angle = 0.7f64;
        let (c, s) = (angle.cos(), angle.sin());
        let c2w = [[c, 0.0, s, 1.0], [0.0, 1.0, 0.0, 2.0], [-s, 0.0, c, 3.0]];
        let matrix = serde_json::to_string(&c2w).unwrap();
        for intrinsics in [r#""fl_x": 8, "fl_y": 8, "cx": 8, "cy": 4, "#, ""] {
            let json = format!(
                r#"{{"w": 16, "h": 8, {intrinsics}"camera_model": "EQUIRECTANGULAR", "k1": 0.3, "frames": [
                    {{"file_path": "a.jpg", "transform_matrix": {matrix}}}]}}"#
            );
            let camera = one(&json).unwrap();
            assert_eq!(camera.lens, Lens::Equirectangular);
            for (x, y) in (0..16).flat_map(|x| (0..8).map(move |y| (x, y))) {
                let (fx, fy, cx, cy) = (8.0, 8.0, 8.0, 4.0);
                let coord = [(x as f64 + 0.5 - cx) / fx, -((y as f64 + 0.5 - cy) / fy)];
                let (theta, phi) = (-std::f64::consts::PI * coord[0], std::f64::consts::PI * (0.5 - coord[1]));
                let local = [-theta.sin() * phi.sin(), phi.cos(), -theta.cos() * phi.sin()];
                let world = DVec3::from([0, 1, 2].map(|i| (0..3).map(|j| c2w[i][j] * local[j]).sum::<f64>()));
                let ray = camera.ray(x, y, glam::Vec2::splat(0.5));
                let error = (ray.dir.as_dvec3() - world.normalize()).length();
                assert!(error < 1e-5, "pixel ({x}, {y}): {} against Nerfstudio's {world}", ray.dir);
            }
        }
    }

    /// Every prefix of a file, and the file with each byte changed, is refused or read, never a
    /// panic (as the fuzz target `transforms` checks at length).
    #[test]
    fn cut_and_changed_files_never_panic() {
        let json = BLENDER.replace(r#""frames""#, r#""w": 8, "h": 6, "k1": 0.1, "frames""#);
        let bytes = json.as_bytes();
        for end in 0..bytes.len() {
            let _ = parse_transforms(&bytes[..end], None);
        }
        for i in 0..bytes.len() {
            for b in [b'0', b'9', b'-', b'e', b'{', b']', b'"'] {
                let mut changed = bytes.to_vec();
                changed[i] = b;
                let _ = parse_transforms(&changed, None);
            }
        }
    }

    #[test]
    fn a_size_comes_from_the_frames_png_or_jpeg_where_the_file_has_none() {
        let dir = std::env::temp_dir().join(format!("splat-transforms-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("train")).unwrap();
        image::RgbaImage::new(40, 30).save(dir.join("train/r_0.png")).unwrap();
        image::RgbImage::new(24, 18).save(dir.join("train/photo.JPG")).unwrap();
        let views = parse_transforms(BLENDER.as_bytes(), Some(&dir)).unwrap();
        let photo = BLENDER.replace("./train/r_0", "train/photo.JPG");
        let photos = parse_transforms(photo.as_bytes(), Some(&dir)).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let c = views[0].1;
        assert_eq!((c.width, c.height, c.cx, c.cy), (40, 30, 20.0, 15.0));
        let c = photos[0].1;
        assert_eq!((c.width, c.height, c.cx, c.cy), (24, 18, 12.0, 9.0));
    }
}
