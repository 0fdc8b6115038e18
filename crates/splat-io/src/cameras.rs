//! INRIA 3DGS `cameras.json`: a list of entries with `position` (camera centre), `rotation`
//! (camera-to-world rotation, rows as written), `fx`, `fy`, `width`, `height`. The principal
//! point is the image centre; axes follow OpenCV (x right, y down, z forward).

use crate::similarity::{Pose, Similarity};
use crate::{Error, ErrorKind, read_file};
use glam::{Mat3, Vec3};
use serde::{Deserialize, Serialize};
use splat_core::undistort::Undistortion;
use splat_core::{Camera, Scene};
use std::path::Path;

/// One entry of `cameras.json` as 3DGS writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraEntry {
    /// Index of the training view.
    #[serde(default)]
    pub id: i64,
    /// Name of the training image.
    #[serde(default)]
    pub img_name: String,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Camera centre in world space.
    pub position: [f64; 3],
    /// Camera-to-world rotation, rows as written.
    pub rotation: [[f64; 3]; 3],
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Focal length along x, pixels.
    pub fx: f64,
}

impl CameraEntry {
    /// The camera this entry describes.
    pub fn to_camera(&self) -> Result<Camera, String> {
        let r = &self.rotation;
        // Rows as written: world_from_camera = [[r00 r01 r02] [r10 ...] ...]; Mat3 takes columns.
        let c2w = Mat3::from_cols_array_2d(&[
            [r[0][0] as f32, r[1][0] as f32, r[2][0] as f32],
            [r[0][1] as f32, r[1][1] as f32, r[2][1] as f32],
            [r[0][2] as f32, r[1][2] as f32, r[2][2] as f32],
        ]);
        let w2c = c2w.transpose();
        let centre = Vec3::new(self.position[0] as f32, self.position[1] as f32, self.position[2] as f32);
        Camera::from_intrinsics(
            self.width,
            self.height,
            self.fx as f32,
            self.fy as f32,
            0.5 * self.width as f32,
            0.5 * self.height as f32,
            w2c,
            -(w2c * centre),
        )
        .map_err(|e| e.to_string())
    }

    /// The entry describing `camera` (principal point assumed at the image centre).
    pub fn from_camera(id: i64, img_name: &str, camera: &Camera) -> Self {
        let c2w = camera.rotation.transpose();
        let rotation = [0, 1, 2].map(|i| c2w.row(i).to_array().map(f64::from));
        Self {
            id,
            img_name: img_name.into(),
            width: camera.width,
            height: camera.height,
            position: camera.center().to_array().map(f64::from),
            rotation,
            fy: f64::from(camera.fy),
            fx: f64::from(camera.fx),
        }
    }
}

/// Read every camera of a `cameras.json`.
pub fn read_cameras(path: &Path) -> Result<Vec<Camera>, Error> {
    let bytes = read_file(path)?;
    parse_cameras(&bytes).map_err(|kind| Error::new(path, kind))
}

/// Read every camera of a `cameras.json` with its `img_name`. A file that is not JSON at all
/// (a scene given as `--camera`, a binary file) is [`ErrorKind::NotCameras`], naming what
/// camera files are.
pub fn read_named_cameras(path: &Path) -> Result<Vec<(String, Camera)>, Error> {
    named_cameras(path, &read_file(path)?)
}

/// [`read_named_cameras`] of the file's `bytes`.
fn named_cameras(path: &Path, bytes: &[u8]) -> Result<Vec<(String, Camera)>, Error> {
    if let Err(e) = serde_json::from_slice::<serde::de::IgnoredAny>(bytes) {
        return Err(Error::new(path, ErrorKind::NotCameras(e)));
    }
    let names = serde_json::from_slice::<Vec<CameraEntry>>(bytes).map(|e| e.into_iter().map(|e| e.img_name));
    if names.is_err() && is_exported_poses(bytes) {
        let message = "this is Nerfstudio's `ns-export cameras` output (poses in a training run's world, no \
                       intrinsics): give the dataset's transforms.json as the cameras instead, with the run's \
                       dataparser_transforms.json";
        return Err(Error::new(path, ErrorKind::Camera { index: 0, message: message.into() }));
    }
    let cameras = parse_cameras(bytes).map_err(|kind| Error::new(path, kind))?;
    Ok(names.map_err(|e| Error::new(path, ErrorKind::Json(e)))?.zip(cameras).collect())
}

/// Whether `bytes` are a list whose first entry has Nerfstudio's exported `transform` and
/// `file_path` (`ns-export cameras`), not a `cameras.json`.
fn is_exported_poses(bytes: &[u8]) -> bool {
    let first = serde_json::from_slice::<Vec<serde_json::Value>>(bytes).ok().and_then(|v| v.into_iter().next());
    first.is_some_and(|e| e.get("transform").is_some() && e.get("file_path").is_some())
}

/// What changes the cameras of a camera file as they are read ([`read_views_in`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct ViewOptions<'a> {
    /// A Nerfstudio training run's `dataparser_transforms.json`: moves a `transforms.json`'s
    /// cameras into the run's world ([`crate::transforms::Dataparser`]); other camera files are
    /// refused with it.
    pub dataparser: Option<&'a Path>,
    /// Splats trained by gsplat's `simple_trainer` in its normalised world (its default
    /// `normalize_world_space`): moves a COLMAP model's cameras into that world
    /// ([`crate::gsplat_world`]), where these splats are; other camera files are refused with it.
    pub gsplat_world: Option<&'a Scene>,
    /// The similarity from the camera file's world to the splats' (such as one
    /// [`crate::similarity::read`] from a file): moves every camera by it; refused with either
    /// trainer's world above.
    pub world_transform: Option<Similarity>,
    /// Whose pinhole each camera becomes ([`Camera::undistorted`]).
    pub undistort: Option<Undistortion>,
    /// The trainer's split of the views to keep ([`Split`]).
    pub split: Option<Split>,
    /// The downscale factor of the photographs the trainer read (`images_F/`): each camera
    /// [`Camera::downscaled`] by it, as gsplat's and Nerfstudio's parsers take it.
    pub factor: Option<u32>,
    /// The photographs' width and height (either may be given alone): each camera
    /// [`Camera::rescaled`] to them after the factor and before it is undistorted, as gsplat
    /// scales K to the size of the photographs it finds.
    pub size: (Option<u32>, Option<u32>),
}

/// A `transforms.json`'s own split lists: each key (`train_filenames`, …) and its file paths.
pub type SplitLists = Vec<(&'static str, Vec<String>)>;

/// A trainer's split of a capture's views into those it trains on and those it holds out for
/// evaluation, in the order the trainer lists them.
///
/// - 3DGS (`--eval`: `readColmapSceneInfo`, llffhold 8) sorts COLMAP's image names and holds
///   out every 8th from the first; gsplat's `simple_trainer` (`test_every` 8, over the sorted
///   names) holds out the same views.
/// - Nerfstudio's `nerfstudio-data` dataparser (`eval_mode` "fraction", `train_split_fraction`
///   0.9: `get_train_eval_split_fraction`) sorts the frames by path and trains on the indices
///   `numpy.linspace(0, n − 1, ⌈0.9 n⌉, dtype=int)`, holding out the rest. A file that names
///   its own split lists (`train_filenames`, `val_filenames`, `test_filenames`) is split by
///   them instead: the training views are `train_filenames`', the evaluation views
///   `test_filenames`' (those `ns-eval` scores), each in the sorted order; a missing list, or
///   a listed path no frame has, is refused, as the dataparser refuses it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Split {
    /// 3DGS's and gsplat's held-out views.
    ThreeDgsTest,
    /// 3DGS's and gsplat's training views.
    ThreeDgsTrain,
    /// Nerfstudio's evaluation views.
    NerfstudioEval,
    /// Nerfstudio's training views.
    NerfstudioTrain,
}

impl Split {
    /// Every split.
    pub const ALL: [Split; 4] =
        [Split::ThreeDgsTest, Split::ThreeDgsTrain, Split::NerfstudioEval, Split::NerfstudioTrain];

    /// Its name, as the CLI and Python take it.
    pub const fn name(self) -> &'static str {
        match self {
            Split::ThreeDgsTest => "3dgs-test",
            Split::ThreeDgsTrain => "3dgs-train",
            Split::NerfstudioEval => "nerfstudio-eval",
            Split::NerfstudioTrain => "nerfstudio-train",
        }
    }

    /// What it keeps, in words.
    pub const fn describe(self) -> &'static str {
        match self {
            Split::ThreeDgsTest => {
                "3DGS's held-out views in eval mode (and gsplat's): every 8th by name, from the first"
            }
            Split::ThreeDgsTrain => "3DGS's and gsplat's training views: all but every 8th by name",
            Split::NerfstudioEval => {
                "Nerfstudio's evaluation views: those off linspace(0, n-1, ceil(0.9 n)) by path, or the file's test_filenames"
            }
            Split::NerfstudioTrain => {
                "Nerfstudio's training views: linspace(0, n-1, ceil(0.9 n)) by path, or the file's train_filenames"
            }
        }
    }

    /// The views of `views` (named by their image) in the split, in the trainer's order; `lists`,
    /// the file's own split lists, decide Nerfstudio's splits where there are any.
    pub fn select<T>(self, mut views: Vec<(String, T)>, lists: &SplitLists) -> Result<Vec<(String, T)>, String> {
        let n = views.len();
        let keep: Vec<bool> = match self {
            Split::ThreeDgsTest | Split::ThreeDgsTrain => {
                views.sort_by(|(a, _), (b, _)| a.cmp(b));
                (0..n).map(|i| (i % 8 == 0) == (self == Split::ThreeDgsTest)).collect()
            }
            Split::NerfstudioEval | Split::NerfstudioTrain => {
                views.sort_by_cached_key(|(name, _)| path_parts(name));
                if !lists.is_empty() {
                    self.listed(&views, lists)?
                } else if n < 2 {
                    return Err("Nerfstudio cannot split a single view (its fraction split fails)".into());
                } else {
                    // math.ceil(n * 0.9), in f64 as Python computes it.
                    let train = linspace_floor(n - 1, (n as f64 * 0.9).ceil() as usize);
                    (0..n).map(|i| train.binary_search(&i).is_ok() == (self == Split::NerfstudioTrain)).collect()
                }
            }
        };
        let kept: Vec<_> = views.into_iter().zip(keep).filter_map(|(v, k)| k.then_some(v)).collect();
        if kept.is_empty() {
            return Err(format!("{} of {n} views is empty", self.name()));
        }
        Ok(kept)
    }
}

impl Split {
    /// Which of the sorted `views` Nerfstudio's dataparser keeps by the file's own `lists`:
    /// those whose path (compared as Python's paths compare) its split's list names.
    fn listed<T>(self, views: &[(String, T)], lists: &SplitLists) -> Result<Vec<bool>, String> {
        let key = if self == Split::NerfstudioTrain { "train_filenames" } else { "test_filenames" };
        let Some((_, list)) = lists.iter().find(|(k, _)| *k == key) else {
            let names: Vec<&str> = lists.iter().map(|(k, _)| *k).collect();
            return Err(format!(
                "the file names its own split lists ({}) but not {key}, which {} reads in their place \
                 (Nerfstudio's dataparser refuses the file so)",
                names.join(", "),
                self.name()
            ));
        };
        let wanted: std::collections::HashSet<_> = list.iter().map(|p| path_parts(p)).collect();
        let have: std::collections::HashSet<_> = views.iter().map(|(name, _)| path_parts(name)).collect();
        let missing: Vec<&String> = list.iter().filter(|p| !have.contains(&path_parts(p))).collect();
        if let Some(first) = missing.first() {
            return Err(format!("{key} names {} path(s) no frame has, such as {first}", missing.len()));
        }
        Ok(views.iter().map(|(name, _)| wanted.contains(&path_parts(name))).collect())
    }
}

/// A path's parts as Python's `pathlib` compares them: `.` parts and repeated separators
/// dropped.
fn path_parts(name: &str) -> Vec<std::ffi::OsString> {
    let parts = Path::new(name).components().filter(|c| *c != std::path::Component::CurDir);
    parts.map(|c| c.as_os_str().to_owned()).collect()
}

/// `numpy.linspace(0, last, count, dtype=int)`: i · (last / (count − 1)) in f64, floored, the
/// last value `last` itself (count ≥ 2).
fn linspace_floor(last: usize, count: usize) -> Vec<usize> {
    let step = last as f64 / (count - 1) as f64;
    (0..count).map(|i| if i == count - 1 { last } else { (i as f64 * step).floor() as usize }).collect()
}

/// Every view of a `cameras.json`, a COLMAP model ([`crate::colmap::is_colmap`]) or a
/// `transforms.json` ([`crate::transforms`]: the file, or a folder holding it), with its image
/// name, in the file's (or, for COLMAP, the names') order.
pub fn read_views(path: &Path) -> Result<Vec<(String, Camera)>, Error> {
    read_views_in(path, ViewOptions::default())
}

/// [`read_views`], changed by `options`: moved by the world transform, the dataparser
/// transforms or into gsplat's world, the split kept, downscaled and sized, then undistorted.
pub fn read_views_in(path: &Path, options: ViewOptions) -> Result<Vec<(String, Camera)>, Error> {
    let (mut views, lists) = read_views_moved(path, options)?;
    if let Some(split) = options.split {
        views = split.select(views, &lists).map_err(|m| Error::new(path, ErrorKind::Split(m)))?;
    }
    let size = |(index, (name, camera)): (usize, (String, Camera))| {
        let camera = match options.factor {
            Some(factor) => camera.downscaled(factor),
            None => Ok(camera),
        };
        let (w, h) = options.size;
        let camera = camera.and_then(|c| c.rescaled(w.unwrap_or(c.width), h.unwrap_or(c.height)));
        let message = |e: splat_core::camera::CameraError| format!("{name}: {e}");
        camera.map_err(|e| Error::new(path, ErrorKind::Camera { index, message: message(e) })).map(|c| (name, c))
    };
    let views = views.into_iter().enumerate().map(size).collect::<Result<Vec<_>, Error>>()?;
    let Some(trainer) = options.undistort else { return Ok(views) };
    // The views of a capture share a few cameras, and gsplat's fisheye crop reads its whole map.
    let mut undistortions = splat_core::undistort::Undistortions::new(trainer);
    let mut undistort =
        |(index, (name, camera)): (usize, (String, Camera))| match undistortions.of(&camera).and_then(|u| u.camera()) {
            Ok(done) => Ok((name, done)),
            Err(e) => Err(Error::new(path, ErrorKind::Camera { index, message: format!("{name}: {e}") })),
        };
    views.into_iter().enumerate().map(&mut undistort).collect()
}

/// [`read_views`], every camera moved by `options`' world transform (a COLMAP model's from its
/// double-precision poses), a `transforms.json`'s by its dataparser transforms, a COLMAP model's
/// into gsplat's world; and the split lists a `transforms.json` names, for
/// Nerfstudio's splits (none for other files).
fn read_views_moved(path: &Path, options: ViewOptions) -> Result<(Vec<(String, Camera)>, SplitLists), Error> {
    if let Some(world) = options.world_transform {
        if options.gsplat_world.is_some() || options.dataparser.is_some() {
            let why = "a world transform moves the cameras by itself: give it without gsplat's world or a Nerfstudio \
                       run's dataparser transforms";
            return Err(Error::new(path, ErrorKind::WorldTransform(why.into())));
        }
        if crate::colmap::is_colmap(path) {
            return Ok((moved_posed(path, crate::colmap::read_colmap_posed(path)?, world)?, SplitLists::new()));
        }
        let (views, lists) = read_views_moved(path, ViewOptions { world_transform: None, ..options })?;
        let posed = views.into_iter().map(|(name, camera)| (name, camera, crate::similarity::pose_of(&camera)));
        return Ok((moved(path, posed, world)?, lists));
    }
    if let Some(splats) = options.gsplat_world {
        if options.dataparser.is_some() {
            let why = "a Nerfstudio run's dataparser transforms and gsplat's world are two trainers' worlds: give one";
            return Err(Error::new(path, ErrorKind::GsplatWorld(why.into())));
        }
        return Ok((in_gsplat_world(path, splats)?, SplitLists::new()));
    }
    let dataparser = options.dataparser.map(crate::transforms::read_dataparser).transpose()?;
    let not_transforms = || {
        let why = "a training run's dataparser transforms move a transforms.json's cameras, and this is a \
                   COLMAP model or a cameras.json: give the run's dataset's transforms.json";
        Err(Error::new(path, ErrorKind::Dataparser(why.into())))
    };
    if crate::colmap::is_colmap(path) {
        if dataparser.is_some() {
            return not_transforms();
        }
        let views = crate::colmap::read_colmap(path)?.into_iter().map(|v| (v.name, v.camera)).collect();
        return Ok((views, SplitLists::new()));
    }
    let file = crate::transforms::in_folder(path).unwrap_or_else(|| path.to_path_buf());
    let bytes = read_file(&file)?;
    if crate::transforms::is_transforms(&bytes) {
        // Only Nerfstudio's splits read the lists: a malformed one stops nothing else.
        let lists = match options.split {
            Some(Split::NerfstudioEval | Split::NerfstudioTrain) => {
                crate::transforms::split_lists(&bytes).map_err(|m| Error::new(path, ErrorKind::Split(m)))?
            }
            _ => SplitLists::new(),
        };
        return Ok((crate::transforms::views_of(&file, &bytes, dataparser.as_ref())?, lists));
    }
    if dataparser.is_some() {
        return not_transforms();
    }
    Ok((named_cameras(path, &bytes)?, SplitLists::new()))
}

/// Every view of the COLMAP model at `path`, moved into the gsplat world where `splats` were
/// trained ([`crate::gsplat_world::normalized_world`]).
fn in_gsplat_world(path: &Path, splats: &Scene) -> Result<Vec<(String, Camera)>, Error> {
    if !crate::colmap::is_colmap(path) {
        std::fs::metadata(path).map_err(|e| Error::new(path, ErrorKind::Io(e)))?;
        let why = "gsplat normalises the world of a COLMAP model (its cameras and 3D points): give the capture's \
                   sparse/0 folder as the cameras";
        return Err(Error::new(path, ErrorKind::GsplatWorld(why.into())));
    }
    let posed = crate::colmap::read_colmap_posed(path)?;
    let points = crate::colmap::read_points3d(path)?;
    let poses: Vec<_> = posed.iter().map(crate::colmap::PosedView::pose).collect();
    let means: Vec<_> = splats.particles.iter().map(|p| p.mean).collect();
    let (world, _) = crate::gsplat_world::normalized_world(&poses, &points, &means)
        .map_err(|why| Error::new(path, ErrorKind::GsplatWorld(why)))?;
    moved_posed(path, posed, world)
}

/// The `posed` views of the COLMAP model at `path`, moved by `world` from their
/// double-precision poses.
fn moved_posed(
    path: &Path,
    posed: Vec<crate::colmap::PosedView>,
    world: Similarity,
) -> Result<Vec<(String, Camera)>, Error> {
    let views = posed.into_iter().map(|p| {
        let pose = p.pose();
        (p.view.name, p.view.camera, pose)
    });
    moved(path, views, world)
}

/// The `views` of the camera file at `path` (each named, with its camera and that camera's
/// pose) moved by `world`, each checked as a camera.
fn moved(
    path: &Path,
    views: impl Iterator<Item = (String, Camera, Pose)>,
    world: Similarity,
) -> Result<Vec<(String, Camera)>, Error> {
    let move_one = |(index, (name, camera, pose)): (usize, (String, Camera, Pose))| match world.camera(&camera, pose) {
        Ok(camera) => Ok((name, camera)),
        Err(e) => Err(Error::new(path, ErrorKind::Camera { index, message: format!("{name}: {e}") })),
    };
    views.enumerate().map(move_one).collect()
}

/// Parse a `cameras.json`.
pub fn parse_cameras(bytes: &[u8]) -> Result<Vec<Camera>, ErrorKind> {
    let entries: Vec<CameraEntry> = serde_json::from_slice(bytes)?;
    if entries.is_empty() {
        return Err(ErrorKind::Camera { index: 0, message: "the file lists no camera".into() });
    }
    entries
        .iter()
        .enumerate()
        .map(|(index, e)| e.to_camera().map_err(|message| ErrorKind::Camera { index, message }))
        .collect()
}

/// Write cameras as a `cameras.json`.
pub fn write_cameras(path: &Path, cameras: &[Camera]) -> Result<(), Error> {
    let entries: Vec<CameraEntry> = cameras
        .iter()
        .enumerate()
        .map(|(i, c)| CameraEntry::from_camera(i as i64, &format!("view_{i:04}"), c))
        .collect();
    let json = serde_json::to_string_pretty(&entries).map_err(|e| Error::new(path, ErrorKind::Json(e)))?;
    std::fs::write(path, json + "\n").map_err(|e| Error::new(path, ErrorKind::Io(e)))
}
