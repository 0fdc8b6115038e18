//! `splat._splat`: the extension module of the Python package `splat` (`python/splat`), which
//! converts arrays (numpy, `__array__`, DLPack) to contiguous float32 and calls in here.
//!
//! One home per option: `render` takes every option of `splat render` as a keyword argument,
//! its dashes as underscores, and parses them with the CLI's own argument definitions
//! ([`splat_cli::render::RenderArgs`]); scenes from files are read by `splat-io`'s readers, and
//! scenes from arrays become the same [`Particle`]s those readers make, checked the same way.
//! Every error is a `splat.SplatError` (a `ValueError`) whose text names the problem, with
//! option names as Python spells them.

mod arrays;
mod options;

use arrays::{image_from_array, image_to_array};
use glam::{Mat3, Vec3};
use numpy::{PyArray2, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use splat_cli::args::{ReadArgs, Staged};
use splat_cli::render::{PipelineArg, RenderArgs, Rendered};
use splat_core::camera::Lens;
use splat_core::particle::sh_coeff_count;
use splat_core::undistort::Undistortion;
use splat_core::{Camera, Particle, Scene};
use splat_io::cameras::{Split, ViewOptions};
use splat_io::world::WorldSpec;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};

pyo3::create_exception!(
    _splat,
    SplatError,
    pyo3::exceptions::PyValueError,
    "Bad input or a render that cannot run; the message names the problem and what to do."
);

/// `error` (with its causes) as a [`SplatError`], CLI flags spelled as keyword arguments.
fn fail(error: impl Into<anyhow::Error>) -> PyErr {
    SplatError::new_err(options::pythonic(&format!("{:#}", error.into())))
}

/// Splats, meshes and lighting, as a file or arrays gave them.
#[pyclass(name = "Scene", module = "splat", frozen)]
struct PyScene {
    world: WorldSpec,
    name: String,
}

#[pymethods]
impl PyScene {
    /// Read a scene (.ply, compressed .ply, .splat, .spz, .glb/.gltf, .sog, .ksplat, .usda, a
    /// trainer's checkpoint) or a world (.toml) file; `options` are `splat render`'s reading
    /// options (strict, spz_axes, preset, screen_filter). The reader's notes are warnings.
    #[staticmethod]
    #[pyo3(signature = (path, **options))]
    fn load(py: Python<'_>, path: PathBuf, options: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let read: options::Parsed<ReadArgs> = options::parse("load", options)?;
        let opened = splat_io::world::open_world(Some(&path), read.0.options()).map_err(fail)?;
        let warn = |text: String| {
            let text = std::ffi::CString::new(text).unwrap_or_default();
            PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &text, 2)
        };
        if let Some(warning) = splat_io::skipped_properties_warning(&path, &opened.skipped_properties) {
            warn(format!("{warning} (strict=True refuses them)"))?;
        }
        // What the reader did or found that the user should hear of, as `splat` prints it.
        for note in &opened.notes {
            warn(splat_io::file_note(&path, note))?;
        }
        Ok(Self { world: opened.world, name: opened.name })
    }

    /// The built-in demo scene (with its camera).
    #[staticmethod]
    fn demo() -> PyResult<Self> {
        let opened = splat_io::world::open_world(None, Default::default()).map_err(fail)?;
        Ok(Self { world: opened.world, name: opened.name })
    }

    /// A scene from arrays, float32 and contiguous (the Python wrapper converts): means (N, 3),
    /// scales (N, 3), rotations (N, 4) as w, x, y, z, opacities (N,), sh (N, K, 3) with
    /// K = (degree + 1)² in 3DGS's order (sh[:, 0] the DC term). Scales are linear unless
    /// `log_scales`, opacities in [0, 1] unless `logit_opacities` (the trainers' raw
    /// parameters: exp and the sigmoid are applied here, as the .ply reader does).
    #[staticmethod]
    #[pyo3(signature = (means, scales, rotations, opacities, sh, log_scales, logit_opacities))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        py: Python<'_>,
        means: PyReadonlyArrayDyn<'_, f32>,
        scales: PyReadonlyArrayDyn<'_, f32>,
        rotations: PyReadonlyArrayDyn<'_, f32>,
        opacities: PyReadonlyArrayDyn<'_, f32>,
        sh: PyReadonlyArrayDyn<'_, f32>,
        log_scales: bool,
        logit_opacities: bool,
    ) -> PyResult<Self> {
        let n = arrays::rows("means", means.shape(), 3)?;
        arrays::check_shape("scales", scales.shape(), &[n, 3])?;
        arrays::check_shape("rotations", rotations.shape(), &[n, 4])?;
        arrays::check_shape("opacities", opacities.shape(), &[n])?;
        let k = arrays::sh_coefficients(sh.shape(), n)?;
        let degree = (1..=3u8).find(|&d| sh_coeff_count(d) == k).unwrap_or(0);
        let columns = arrays::Splats {
            means: means.as_slice()?,
            scales: scales.as_slice()?,
            rotations: rotations.as_slice()?,
            opacities: opacities.as_slice()?,
            sh: sh.as_slice()?,
            k,
            log_scales,
            logit_opacities,
        };
        let particles = py.detach(|| (0..n).map(|i| columns.particle(i)).collect::<Result<Vec<_>, String>>());
        let particles = particles.map_err(SplatError::new_err)?;
        if particles.is_empty() {
            return Err(SplatError::new_err("the arrays hold no splats (N = 0)"));
        }
        Ok(Self { world: WorldSpec::of(Scene::new(particles, degree)), name: "arrays".into() })
    }

    /// The splats as arrays in the conventions of [`PyScene::from_arrays`] (linear scales,
    /// opacities in [0, 1], unit w, x, y, z quaternions, sh (N, K, 3)): a dict of float32
    /// arrays "means", "scales", "rotations", "opacities", "sh".
    fn to_arrays<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let particles = &self.world.scene.particles;
        let (n, k) = (particles.len(), sh_coeff_count(self.world.scene.sh_degree));
        let flat = |f: &dyn Fn(&Particle) -> Vec<f32>| particles.iter().flat_map(f).collect::<Vec<f32>>();
        let means = flat(&|p| p.mean.to_array().to_vec());
        let scales = flat(&|p| p.scale.to_array().to_vec());
        let rotations = flat(&|p| vec![p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z]);
        let opacities = flat(&|p| vec![p.opacity]);
        let sh = flat(&|p| p.sh.to_array()[..k].iter().flat_map(|c| c.to_array()).collect());
        let dict = PyDict::new(py);
        dict.set_item("means", arrays::shaped(py, means, &[n, 3])?)?;
        dict.set_item("scales", arrays::shaped(py, scales, &[n, 3])?)?;
        dict.set_item("rotations", arrays::shaped(py, rotations, &[n, 4])?)?;
        dict.set_item("opacities", arrays::shaped(py, opacities, &[n])?)?;
        dict.set_item("sh", arrays::shaped(py, sh, &[n, k, 3])?)?;
        Ok(dict)
    }

    /// Number of splats.
    fn __len__(&self) -> usize {
        self.world.scene.particles.len()
    }

    /// SH degree of the splats' colours (0 to 3).
    #[getter]
    fn sh_degree(&self) -> u8 {
        self.world.scene.sh_degree
    }

    /// Number of mesh triangles (worlds and glTF files).
    #[getter]
    fn triangles(&self) -> usize {
        self.world.meshes.iter().map(|(mesh, _)| mesh.triangles.len()).sum()
    }

    /// The screen-space filter the splats were trained with, which the splatting methods apply
    /// (the file's, or the one `load`'s `screen_filter=` or `preset=` chose): "3dgs" (its
    /// dilation), "antialiased" or "mip".
    #[getter]
    fn screen_filter(&self) -> &'static str {
        self.world.scene.screen_filter.name()
    }

    /// The renderer and kernel the file says the splats were trained through (a trainer's
    /// checkpoint: gsplat's rasterizer for gsplat's and splatfacto's, 3DGRUT's as its config
    /// names it), which `render` applies where no preset, kernel or background is given: a dict
    /// of "preset" (`--preset`'s name), "kernel_degree", "cutoff", "background" (the colour its
    /// evaluation composites over, None for black) and "near_plane" (where its rasterizer
    /// culled); None where the file says nothing.
    #[getter]
    fn trained<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(trained) = self.world.scene.trained else { return Ok(None) };
        let dict = PyDict::new(py);
        dict.set_item("preset", trained.preset.name())?;
        dict.set_item("kernel_degree", trained.kernel_degree)?;
        dict.set_item("cutoff", trained.cutoff)?;
        dict.set_item("background", trained.background.map(|b| (b.x, b.y, b.z)))?;
        dict.set_item("near_plane", trained.near)?;
        Ok(Some(dict))
    }

    /// The world's own camera (a world file's or the demo's), if it has one.
    #[getter]
    fn camera(&self) -> Option<PyCamera> {
        self.world.camera.map(|camera| PyCamera { camera })
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?}: {} splats, SH degree {}, {} triangles)",
            self.name,
            self.__len__(),
            self.sh_degree(),
            self.triangles()
        )
    }
}

/// A pinhole (or COLMAP-lens) camera: intrinsics in pixels and a world-to-camera pose in
/// OpenCV axes (x right, y down, z forward), as 3DGS and gsplat's `viewmats` and `Ks`.
#[pyclass(name = "Camera", module = "splat", frozen, skip_from_py_object)]
#[derive(Clone)]
struct PyCamera {
    camera: Camera,
}

#[pymethods]
impl PyCamera {
    /// A camera at `eye` looking at `target`, `up` the world's up, `fov_y` the vertical field
    /// of view in degrees.
    #[staticmethod]
    #[pyo3(signature = (eye, target, up = (0.0, 1.0, 0.0), fov_y = splat_core::camera::DEFAULT_FOV_Y, width = 640, height = 480))]
    fn look_at(
        eye: (f32, f32, f32),
        target: (f32, f32, f32),
        up: (f32, f32, f32),
        fov_y: f32,
        width: u32,
        height: u32,
    ) -> PyResult<Self> {
        let camera = Camera::look_at(eye.into(), target.into(), up.into(), fov_y, width, height).map_err(fail)?;
        Ok(Self { camera })
    }

    /// A camera from a 4 × 4 world-to-camera matrix (gsplat's `viewmats[i]`, OpenCV axes) and
    /// a 3 × 3 intrinsic matrix K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels.
    #[staticmethod]
    fn from_matrices(
        viewmat: &Bound<'_, PyAny>,
        intrinsics: &Bound<'_, PyAny>,
        width: u32,
        height: u32,
    ) -> PyResult<Self> {
        let v = arrays::matrix::<4>("viewmat", viewmat)?;
        let k = arrays::matrix::<3>("K", intrinsics)?;
        if v[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(SplatError::new_err(format!("viewmat's last row is {:?}; expected [0, 0, 0, 1]", v[3])));
        }
        if k[0][1] != 0.0 || k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
            return Err(SplatError::new_err(format!(
                "K is {k:?}; expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)"
            )));
        }
        let rotation = Mat3::from_cols_array_2d(&[
            [v[0][0], v[1][0], v[2][0]],
            [v[0][1], v[1][1], v[2][1]],
            [v[0][2], v[1][2], v[2][2]],
        ]);
        let translation = Vec3::new(v[0][3], v[1][3], v[2][3]);
        let camera = Camera::from_intrinsics(width, height, k[0][0], k[1][1], k[0][2], k[1][2], rotation, translation)
            .map_err(fail)?;
        Ok(Self { camera })
    }

    /// Image width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.camera.width
    }

    /// Image height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.camera.height
    }

    /// The 4 × 4 world-to-camera matrix (OpenCV axes).
    #[getter]
    fn viewmat<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let (r, t) = (self.camera.rotation, self.camera.translation);
        let rows = [
            vec![r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x],
            vec![r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y],
            vec![r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z],
            vec![0.0, 0.0, 0.0, 1.0],
        ];
        PyArray2::from_vec2(py, &rows).expect("rows of equal length")
    }

    /// The 3 × 3 intrinsic matrix K.
    #[getter(K)]
    fn intrinsics<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let c = &self.camera;
        let rows = [vec![c.fx, 0.0, c.cx], vec![0.0, c.fy, c.cy], vec![0.0, 0.0, 1.0]];
        PyArray2::from_vec2(py, &rows).expect("rows of equal length")
    }

    /// Pickling (Ray's object store, multiprocessing): a pinhole camera is rebuilt by
    /// [`PyCamera::from_matrices`] from its matrices, exactly.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        if !self.camera.is_pinhole() {
            return Err(SplatError::new_err(
                "a camera with a COLMAP lens does not pickle: send the camera file's path and camera_index instead",
            ));
        }
        let from = py.get_type::<PyCamera>().getattr("from_matrices")?;
        let c = &self.camera;
        let args = (self.viewmat(py), self.intrinsics(py), c.width, c.height).into_pyobject(py)?;
        Ok((from, args))
    }

    /// The camera `undistort`'s trainer ("splatfacto" or "gsplat") undistorts this camera's
    /// photos to, a pinhole or gsplat's ideal fisheye (`load_cameras(..., undistort=...)` of one
    /// camera); a camera without a distorted lens is its own.
    fn undistorted(&self, undistort: &str) -> PyResult<Self> {
        let trainer = trainer(undistort)?;
        Ok(Self { camera: self.camera.undistorted(trainer).map_err(fail)? })
    }

    /// The same view at `width` × `height`: K scaled with the sides (the field of view kept, as
    /// 3DGS's `-r` and `splat render --width` scale it).
    fn rescaled(&self, width: u32, height: u32) -> PyResult<Self> {
        Ok(Self { camera: self.camera.rescaled(width, height).map_err(fail)? })
    }

    /// The camera of this one's images downscaled by `factor`, as gsplat and Nerfstudio read
    /// `images_F/`: K / F, the sides floored (`load_cameras(..., data_factor=F)`).
    fn downscaled(&self, factor: u32) -> PyResult<Self> {
        Ok(Self { camera: self.camera.downscaled(factor).map_err(fail)? })
    }

    /// `photo`, this camera's photograph (a uint8 array (H, W) or (H, W, C) of the camera's
    /// size), as `undistort`'s trainer ("splatfacto" or "gsplat") resamples it with OpenCV for
    /// training and evaluation, as `splat undistort` writes it: an array of the size of the
    /// camera `load_cameras(..., undistort=undistort)` makes of this one; a camera the trainer
    /// takes as it is keeps its photo.
    fn undistort_photo<'py>(
        &self,
        py: Python<'py>,
        photo: &Bound<'py, PyAny>,
        undistort: &str,
    ) -> PyResult<Bound<'py, PyUntypedArray>> {
        let trainer = trainer(undistort)?;
        let photo = arrays::photo_from_array("photo", photo)?;
        let out = py.detach(|| self.camera.undistort_photo(trainer, &photo)).map_err(fail)?;
        arrays::photo_to_array(py, out)
    }

    /// The pixels of `undistorted(undistort)`'s image the trainer scores, a bool array (H, W),
    /// where it masks some: gsplat's fisheye masks those whose sample falls outside the photo
    /// (its parser's `mask`: its loss leaves them out, its evaluation renders them black); None
    /// where every pixel counts.
    fn undistortion_mask<'py>(&self, py: Python<'py>, undistort: &str) -> PyResult<Option<Bound<'py, PyUntypedArray>>> {
        let trainer = trainer(undistort)?;
        let Some(mask) = self.camera.undistortion_mask(trainer).map_err(fail)? else { return Ok(None) };
        let counts = mask.data.iter().map(|&v| v > 0).collect();
        Ok(Some(arrays::shaped(py, counts, &[mask.height as usize, mask.width as usize])?))
    }

    /// Whether the lens is a pinhole (COLMAP's distorted, fisheye and equirectangular models are
    /// not; the ray-tracing methods render through them).
    #[getter]
    fn is_pinhole(&self) -> bool {
        self.camera.is_pinhole()
    }

    /// The lens: "pinhole", "perspective" (distorted), "fisheye" or "equirectangular".
    #[getter]
    fn lens(&self) -> &'static str {
        match self.camera.lens {
            Lens::Pinhole => "pinhole",
            Lens::Perspective(_) => "perspective",
            Lens::Fisheye(_) => "fisheye",
            Lens::Equirectangular => "equirectangular",
        }
    }

    /// The lens's distortion coefficients, COLMAP's and OpenCV's: a dict of "radial" (k1–k4),
    /// "rational" (FULL_OPENCV's k4–k6, the denominator), "tangential" (p1, p2) and "prism"
    /// (s1, s2), each a list; None for a pinhole or equirectangular lens.
    #[getter]
    fn distortion<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(d) = self.camera.lens.distortion() else { return Ok(None) };
        let dict = PyDict::new(py);
        dict.set_item("radial", d.radial.to_vec())?;
        dict.set_item("rational", d.rational.to_vec())?;
        dict.set_item("tangential", d.tangential.to_vec())?;
        dict.set_item("prism", d.prism.to_vec())?;
        Ok(Some(dict))
    }

    fn __repr__(&self) -> String {
        let c = &self.camera;
        format!(
            "Camera({}×{}, fx {:.2}, fy {:.2}, cx {:.2}, cy {:.2}, centre {})",
            c.width,
            c.height,
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            c.center()
        )
    }
}

/// Every view of a camera file (an INRIA cameras.json, a COLMAP model: a sparse/0 folder or
/// its images.bin / images.txt, or a transforms.json of NeRF-synthetic or Nerfstudio: the file
/// or its folder), as (image name, camera) in the order `splat render` lists them;
/// `dataparser_transforms`, a Nerfstudio run's `dataparser_transforms.json`, moves a
/// transforms.json's cameras into that run's world (splatfacto's splats'); `undistort`
/// ("splatfacto" or "gsplat") makes each camera the one that trainer undistorts its photos to
/// (a pinhole; gsplat's fisheye, the ideal fisheye), as `splat render --undistort` does; `split` ("3dgs-test", "nerfstudio-eval", …) keeps a
/// trainer's split of the views, as `--split` does; `data_factor` F gives each camera K / F and
/// its sides floored, as gsplat and Nerfstudio take `images_F/` (`--data-factor`); `image_size`
/// (width, height) scales each camera to the photographs' size after that and before it is
/// undistorted, as gsplat does; `gsplat_world`, a Scene of splats gsplat's simple_trainer
/// trained in its normalised world (its default), moves a COLMAP model's cameras into that world
/// (`--gsplat-world`); `world_transform`, a file of a 4 × 4 (or 3 × 4) similarity from the camera
/// file's world to the splats' (`--world-transform`), or `world_rows`, its rows, moves every
/// camera by it.
#[pyfunction]
#[pyo3(signature = (path, dataparser_transforms = None, undistort = None, split = None, data_factor = None, image_size = None, gsplat_world = None, world_transform = None, world_rows = None))]
#[allow(clippy::too_many_arguments)]
fn load_cameras(
    path: PathBuf,
    dataparser_transforms: Option<PathBuf>,
    undistort: Option<&str>,
    split: Option<&str>,
    data_factor: Option<u32>,
    image_size: Option<(u32, u32)>,
    gsplat_world: Option<PyRef<PyScene>>,
    world_transform: Option<PathBuf>,
    world_rows: Option<Vec<Vec<f64>>>,
) -> PyResult<Vec<(String, PyCamera)>> {
    let undistort = undistort.map(trainer).transpose()?;
    let split = split.map(|name| choice("split", name, &Split::ALL, Split::name)).transpose()?;
    let size = image_size.map_or((None, None), |(w, h)| (Some(w), Some(h)));
    let world_transform = match (world_transform, world_rows) {
        (Some(file), _) => Some(splat_io::similarity::read(&file).map_err(fail)?),
        (None, Some(rows)) => Some(
            splat_io::similarity::Similarity::from_rows(&rows, "world_transform", false)
                .map_err(SplatError::new_err)?,
        ),
        (None, None) => None,
    };
    let options = ViewOptions {
        dataparser: dataparser_transforms.as_deref(),
        gsplat_world: gsplat_world.as_ref().map(|s| &s.world.scene),
        world_transform,
        undistort,
        split,
        factor: data_factor,
        size,
    };
    let views = splat_cli::args::load_cameras(&path, options).map_err(fail)?;
    Ok(views.into_iter().map(|(name, camera)| (name, PyCamera { camera })).collect())
}

/// The trainer whose undistortion the keyword argument `undistort` names.
fn trainer(name: &str) -> PyResult<Undistortion> {
    choice("undistort", name, &Undistortion::ALL, Undistortion::name)
}

/// The one of `all` named `name`, for the keyword argument `argument`.
fn choice<T: Copy>(argument: &str, name: &str, all: &[T], name_of: fn(T) -> &'static str) -> PyResult<T> {
    all.iter().copied().find(|&v| name_of(v) == name).ok_or_else(|| {
        let names: Vec<_> = all.iter().map(|&v| name_of(v)).collect();
        SplatError::new_err(format!("{argument} = {name:?}: expected one of {}", names.join(", ")))
    })
}

/// Render `scene` as `splat render` would, with `options` its options (dashes as underscores)
/// and `camera` in place of its camera options; `progress(done, total)` is called with pixels
/// done as a CPU render advances. Returns a dict of float32 arrays: colour (H, W, 3), variance
/// (H, W, 3), alpha (H, W), and where the backend made them depth (H, W) and normal (H, W, 3);
/// the frames it holds ("first", "count") and what else decides them ("run").
#[pyfunction]
#[pyo3(signature = (scene, view = None, /, *, progress = None, **options))]
fn render<'py>(
    py: Python<'py>,
    scene: &PyScene,
    view: Option<&PyCamera>,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (args, extras) = options::render_args(py, options)?;
    let (args, staged) = stage(args.0, scene, view)?;
    let reporter = Reporter::new(progress, u64::from(staged.camera.width) * u64::from(staged.camera.height));
    let mut one = None;
    py.detach(|| {
        render_each(&args, &staged, [staged.camera], extras, &|n| reporter.advance(n), |_, view| {
            one = Some(view);
            Ok(())
        })
    })
    .map_err(fail)?;
    reporter.raise()?;
    let view = one.ok_or_else(|| SplatError::new_err("no view was rendered"))?;
    let run = splat_cli::render::run_description(&args, &staged, &staged.camera, &view.method);
    view_dict(py, view, &args, extras, run)
}

/// One view's render as a dict carries it: the images, the frames they hold, where they ran,
/// and the method's part of the run's description.
struct View {
    out: splat_core::frame::RenderOutput,
    count: u32,
    gpu: Option<String>,
    method: String,
}

/// Render `staged` through each of `cameras` as `args` say, the world prepared once: the path
/// tracer for `pipeline="path"` (`splat_cli::render::render_path_views`), else the splat
/// methods (`splat_cli::render::render_views`); `each(i, view)` receives view i as soon as it is
/// rendered.
fn render_each(
    args: &RenderArgs,
    staged: &Staged,
    cameras: impl IntoIterator<Item = Camera, IntoIter: Send>,
    extras: splat_gpu::Extras,
    progress: splat_core::frame::Progress,
    mut each: impl FnMut(usize, View) -> anyhow::Result<()> + Send,
) -> anyhow::Result<()> {
    if args.pipeline == Some(PipelineArg::Path) {
        let (method, count) = (splat_cli::render::path_description(args)?, args.frames().count);
        splat_cli::render::render_path_views(args, staged, cameras, progress, |i, out, gpu| {
            each(i, View { out, count, gpu: gpu.clone(), method: method.clone() })
        })
    } else {
        splat_cli::render::render_views(args, staged, cameras, extras, progress, |i, rendered| {
            let Rendered { out, count, gpu, algorithm } = rendered;
            each(i, View { out, count, gpu, method: format!("{algorithm:?}") })
        })
    }
}

/// The dict a view renders into: [`outputs`], the frames it holds ("first", "count") and what
/// else decides them ("run").
fn view_dict<'py>(
    py: Python<'py>,
    view: View,
    args: &RenderArgs,
    extras: splat_gpu::Extras,
    run: String,
) -> PyResult<Bound<'py, PyDict>> {
    let path = args.pipeline == Some(PipelineArg::Path);
    let dict = outputs(py, view.out, view.gpu, extras, path)?;
    dict.set_item("first", args.frames().first)?;
    dict.set_item("count", view.count)?;
    dict.set_item("run", run)?;
    Ok(dict)
}

/// Render `scene` through each camera of `views` as [`render`] renders one (the same options,
/// the same dict a view), the world prepared once for all of them: the BVH, and on the GPU the
/// device arrays and pipelines, which `render` rebuilds at every call. Every view's images are
/// returned together, so a long list of large images is best given in batches;
/// `progress(done, total)` counts a CPU render's pixels over all the views.
#[pyfunction]
#[pyo3(signature = (scene, views, /, *, progress = None, **options))]
fn render_views<'py>(
    py: Python<'py>,
    scene: &PyScene,
    views: Vec<Bound<'py, PyCamera>>,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let (args, extras) = options::render_args(py, options)?;
    let Some(first) = views.first() else { return Ok(Vec::new()) };
    let (args, staged) = stage(args.0, scene, Some(first.get()))?;
    let cameras = views
        .iter()
        .map(|view| args.scene.view(view.get().camera))
        .collect::<anyhow::Result<Vec<Camera>>>()
        .map_err(fail)?;
    let pixels = cameras.iter().map(|c| u64::from(c.width) * u64::from(c.height)).sum();
    let reporter = Reporter::new(progress, pixels);
    let mut rendered = Vec::with_capacity(cameras.len());
    py.detach(|| {
        render_each(&args, &staged, cameras.iter().copied(), extras, &|n| reporter.advance(n), |_, view| {
            rendered.push(view);
            Ok(())
        })
    })
    .map_err(fail)?;
    reporter.raise()?;
    rendered
        .into_iter()
        .zip(&cameras)
        .map(|(view, camera)| {
            let run = splat_cli::render::run_description(&args, &staged, camera, &view.method);
            view_dict(py, view, &args, extras, run)
        })
        .collect()
}

/// A world prepared once for any number of [`render`] calls, each through its own camera: the
/// BVH (and on the GPU the device arrays and pipelines) built when it is made, kept by a worker
/// thread that renders each camera sent to it, until the renderer is closed or dropped.
#[pyclass(name = "Renderer", module = "splat")]
struct PyRenderer {
    extras: splat_gpu::Extras,
    state: Mutex<State>,
    /// The progress callback of the render under way, which the worker's progress calls.
    reporter: Arc<Mutex<Option<Arc<Reporter>>>>,
}

/// Where a [`PyRenderer`]'s worker is. Its lock is never held while rendering, so that another
/// Python thread that calls in while the interpreter's lock is released is answered at once.
enum State {
    Idle(Worker),
    /// A render is under way (the worker is out with it).
    Busy,
    Closed,
    /// The worker stopped on this error.
    Failed(String),
}

/// The worker thread of a [`PyRenderer`], its two channels, and the options and world it
/// renders (each camera sized and checked by the options on the caller's side), all freed
/// when the renderer closes.
struct Worker {
    staged: Arc<(RenderArgs, Staged)>,
    cameras: mpsc::Sender<Camera>,
    views: mpsc::Receiver<(View, String)>,
    thread: std::thread::JoinHandle<anyhow::Result<()>>,
}

impl Worker {
    /// Render `camera`: the worker again with the view, or the error that stopped it.
    fn render(self, camera: Camera) -> Result<(Worker, (View, String)), String> {
        if self.cameras.send(camera).is_ok()
            && let Ok(view) = self.views.recv()
        {
            return Ok((self, view));
        }
        drop(self.cameras);
        Err(match self.thread.join() {
            Ok(Err(e)) => format!("{e:#}"),
            Ok(Ok(())) => "the renderer's worker stopped".to_string(),
            Err(_) => "the renderer's worker panicked".to_string(),
        })
    }
}

impl PyRenderer {
    /// The worker back from a render, unless the renderer was closed meanwhile (then it is
    /// dropped, which stops it).
    fn idle(&self, worker: Worker) {
        let mut state = self.state.lock().expect("not poisoned");
        if matches!(*state, State::Busy) {
            *state = State::Idle(worker);
        }
    }
}

#[pymethods]
impl PyRenderer {
    /// Prepare `scene` for rendering with `options` (those of [`render`]).
    #[new]
    #[pyo3(signature = (scene, /, **options))]
    fn new(py: Python<'_>, scene: &PyScene, options: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let (args, extras) = options::render_args(py, options)?;
        let shared = Arc::new(stage(args.0, scene, None)?);
        let (cameras, requests) = mpsc::channel::<Camera>();
        let (done, views) = mpsc::channel();
        let reporter = Arc::new(Mutex::new(None::<Arc<Reporter>>));
        let (worker_shared, worker_reporter) = (shared.clone(), reporter.clone());
        let thread = std::thread::spawn(move || {
            let (args, staged) = &*worker_shared;
            let current = Mutex::new(None);
            let requests =
                requests.into_iter().inspect(|camera| *current.lock().expect("not poisoned") = Some(*camera));
            let progress = |n: u64| {
                let reporter = worker_reporter.lock().expect("not poisoned").clone();
                if let Some(reporter) = reporter {
                    reporter.advance(n);
                }
            };
            render_each(args, staged, requests, extras, &progress, |_, view| {
                let camera = current.lock().expect("not poisoned").expect("a camera was sent");
                let run = splat_cli::render::run_description(args, staged, &camera, &view.method);
                done.send((view, run)).map_err(|_| anyhow::anyhow!("the renderer was dropped"))
            })
        });
        let state = Mutex::new(State::Idle(Worker { staged: shared, cameras, views, thread }));
        Ok(Self { extras, state, reporter })
    }

    /// Render through `view` as `render(scene, view, **options)` would, with this renderer's
    /// scene and options: the same dict, bit for bit.
    #[pyo3(signature = (view, /, *, progress = None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        view: &PyCamera,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let worker = {
            let mut state = self.state.lock().expect("not poisoned");
            match std::mem::replace(&mut *state, State::Busy) {
                State::Idle(worker) => worker,
                other => {
                    let e = match &other {
                        State::Busy => "the renderer is rendering for another thread: one render at a time (make a Renderer a thread)".to_string(),
                        State::Failed(e) => format!("the renderer stopped on an error: {e}"),
                        _ => "the renderer is closed: make another".to_string(),
                    };
                    *state = other;
                    return Err(SplatError::new_err(e));
                }
            }
        };
        let staged = worker.staged.clone();
        let camera = match staged.0.scene.view(view.camera) {
            Ok(camera) => camera,
            Err(e) => {
                self.idle(worker);
                return Err(fail(e));
            }
        };
        let reporter = Arc::new(Reporter::new(progress, u64::from(camera.width) * u64::from(camera.height)));
        *self.reporter.lock().expect("not poisoned") = Some(reporter.clone());
        let rendered = py.detach(|| worker.render(camera));
        *self.reporter.lock().expect("not poisoned") = None;
        let (view, run) = match rendered {
            Ok((worker, view)) => {
                self.idle(worker);
                view
            }
            Err(e) => {
                let e = options::pythonic(&e);
                *self.state.lock().expect("not poisoned") = State::Failed(e.clone());
                return Err(SplatError::new_err(e));
            }
        };
        reporter.raise()?;
        view_dict(py, view, &staged.0, self.extras, run)
    }

    /// Stop the worker and free the prepared world (and the renderer's copy of the scene); later
    /// renders are refused.
    fn close(&self, py: Python<'_>) {
        let state = std::mem::replace(&mut *self.state.lock().expect("not poisoned"), State::Closed);
        if let State::Idle(Worker { staged, cameras, views, thread }) = state {
            drop((staged, cameras, views));
            py.detach(|| {
                let _ = thread.join();
            });
        }
    }
}

/// `scene` staged as `splat render` stages a file with `args` (the screen filter they name and
/// the trainer's implications applied), `view` as the world's camera; refused when the camera
/// is given twice or the image cannot fit in memory.
fn stage(mut args: RenderArgs, scene: &PyScene, view: Option<&PyCamera>) -> PyResult<(RenderArgs, Staged)> {
    if view.is_some() && (args.scene.camera.is_some() || args.scene.eye.is_some()) {
        return Err(SplatError::new_err(
            "give the camera once: a Camera argument, or camera= (a camera file), or eye= and target=",
        ));
    }
    args.options.apply_preset(args.scene.read.preset);
    let mut world = scene.world.clone();
    // The screen filter `screen_filter=` or `preset=` names, as `splat render` reads its file.
    if let Some(filter) = args.scene.read.options().screen_filter {
        world.scene.screen_filter = filter;
    }
    if let Some(view) = view {
        world.camera = Some(view.camera);
    }
    let staged = args.scene.stage(world, 640, 480).map_err(fail)?;
    args.options.apply_capture(&staged.world.scene);
    splat_cli::args::check_memory(&staged.camera).map_err(fail)?;
    Ok((args, staged))
}

/// The images of a render as a dict of arrays: colour and variance always; alpha, depth and
/// normal from the frame loop, depth and normal of a GPU render where `extras` asked for them;
/// and where it ran.
fn outputs(
    py: Python<'_>,
    out: splat_core::frame::RenderOutput,
    gpu: Option<String>,
    extras: splat_gpu::Extras,
    path: bool,
) -> PyResult<Bound<'_, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("color", image_to_array(py, out.mean)?)?;
    dict.set_item("variance", image_to_array(py, out.variance)?)?;
    if !path {
        dict.set_item("alpha", image_to_array(py, out.alpha)?)?;
        if gpu.is_none() || extras.depth {
            dict.set_item("depth", image_to_array(py, out.depth)?)?;
        }
        if gpu.is_none() || extras.normal {
            dict.set_item("normal", image_to_array(py, out.normal)?)?;
        }
    }
    dict.set_item("device", gpu.unwrap_or_else(|| "cpu".into()))?;
    Ok(dict)
}

/// Calls a Python progress callback from the render's worker threads: at most about a hundred
/// times a render, the first exception it raises kept to be raised when the render ends.
struct Reporter {
    callback: Option<Py<PyAny>>,
    total: u64,
    done: AtomicU64,
    /// The last count reported, held while the callback runs so that counts arrive in order.
    reported: Mutex<u64>,
    error: Mutex<Option<PyErr>>,
}

impl Reporter {
    fn new(callback: Option<Py<PyAny>>, total: u64) -> Self {
        Self { callback, total, done: AtomicU64::new(0), reported: Mutex::new(0), error: Mutex::new(None) }
    }

    /// `n` more pixels done: report when another hundredth of the image is, or all of it.
    fn advance(&self, n: u64) {
        let Some(callback) = &self.callback else { return };
        self.done.fetch_add(n, Ordering::Relaxed);
        let step = (self.total / 100).max(1);
        let mut reported = self.reported.lock().expect("not poisoned");
        let done = self.done.load(Ordering::Relaxed);
        if done / step == *reported / step && !(done == self.total && *reported < done) {
            return;
        }
        *reported = done;
        Python::attach(|py| {
            if let Err(e) = callback.call1(py, (done, self.total)) {
                self.error.lock().expect("not poisoned").get_or_insert(e);
            }
        });
    }

    /// The callback's first exception, if it raised one.
    fn raise(&self) -> PyResult<()> {
        match self.error.lock().expect("not poisoned").take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// The catalogue of methods: for each, its name, summary, family ("oracle", "trace",
/// "raster"), the keyword arguments of its parameters, whether it is stochastic and unbiased,
/// and whether the GPU has a kernel for it.
#[pyfunction]
fn methods(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    use splat_core::catalogue::{CATALOGUE, Family};
    CATALOGUE
        .iter()
        .map(|entry| {
            let dict = PyDict::new(py);
            dict.set_item("name", entry.name)?;
            dict.set_item("summary", entry.summary)?;
            let family = match entry.family {
                Family::Oracle => "oracle",
                Family::Trace => "trace",
                Family::Raster => "raster",
            };
            dict.set_item("family", family)?;
            let params: Vec<String> = entry.params.iter().map(|p| options::keyword(p.info().flag)).collect();
            dict.set_item("parameters", params)?;
            dict.set_item("stochastic", entry.stochastic)?;
            dict.set_item("unbiased", entry.unbiased)?;
            dict.set_item("gpu", entry.gpu)?;
            Ok(dict)
        })
        .collect()
}

/// RMSE, PSNR (peak 1), SSIM (3DGS's, and torchmetrics' as `ssim_inside`: None for an image
/// smaller than its 11 × 11 window) and ꟻLIP of `test` against `reference`, float32 arrays
/// (H, W) or (H, W, C), as `splat compare` measures them.
#[pyfunction]
#[pyo3(signature = (reference, test, pixels_per_degree = None))]
fn compare<'py>(
    py: Python<'py>,
    reference: PyReadonlyArrayDyn<'py, f32>,
    test: PyReadonlyArrayDyn<'py, f32>,
    pixels_per_degree: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let (a, b) = (image_from_array("reference", &reference)?, image_from_array("test", &test)?);
    let ppd = pixels_per_degree.unwrap_or(splat_cli::compare::DEFAULT_PIXELS_PER_DEGREE);
    let m = py.detach(|| splat_cli::compare::metrics(&a, &b, ppd)).map_err(fail)?;
    let dict = PyDict::new(py);
    dict.set_item("rmse", m.rmse)?;
    dict.set_item("psnr", m.psnr)?;
    dict.set_item("ssim", m.ssim)?;
    dict.set_item("ssim_inside", m.ssim_inside)?;
    dict.set_item("flip", m.flip)?;
    Ok(dict)
}

/// The project's per-pixel z-test (`splat ztest`) of `mean`, averaged over `frames` frames,
/// against `reference`, with the per-frame `variance` of an independent run of
/// `variance_frames` frames, pooled with the mean run's own `mean_variance` where given.
#[pyfunction]
#[pyo3(signature = (mean, variance, reference, frames, mean_variance = None, variance_frames = None))]
fn z_test<'py>(
    py: Python<'py>,
    mean: PyReadonlyArrayDyn<'py, f32>,
    variance: PyReadonlyArrayDyn<'py, f32>,
    reference: PyReadonlyArrayDyn<'py, f32>,
    frames: u32,
    mean_variance: Option<PyReadonlyArrayDyn<'py, f32>>,
    variance_frames: Option<u32>,
) -> PyResult<Bound<'py, PyDict>> {
    let mean = image_from_array("mean", &mean)?;
    let variance = image_from_array("variance", &variance)?;
    let reference = image_from_array("reference", &reference)?;
    let pooling = match (mean_variance, variance_frames) {
        (Some(v), Some(f)) => Some((image_from_array("mean_variance", &v)?, f)),
        (None, None) => None,
        _ => return Err(SplatError::new_err("give mean_variance and variance_frames together, or neither")),
    };
    let pooling = pooling.as_ref().map(|(image, frames)| (image, *frames));
    let v = splat_cli::ztest::verdict(&mean, &variance, &reference, frames, pooling).map_err(fail)?;
    let dict = PyDict::new(py);
    dict.set_item("passes", v.passes())?;
    dict.set_item("tested", v.tested)?;
    dict.set_item("left_out", v.left_out)?;
    dict.set_item("global", v.global)?;
    dict.set_item("spread", v.spread)?;
    dict.set_item("outliers", v.outliers)?;
    dict.set_item("variance", v.variance)?;
    dict.set_item("floored", v.floored)?;
    dict.set_item("failures", v.failures)?;
    Ok(dict)
}

/// The power of the z-test against a bias (docs/power.md): the z-test of `expectation`, a
/// biased estimator's exact expected image (the oracle of a scene with its opacities × 1.02,
/// say), against `reference` with the unbiased estimator's per-frame `variance` at `frames`
/// frames, noise-free: "global" and "spread", the statistics that estimator's z-test has on
/// average, and "visible", whether either reaches the level a test of this budget can be
/// required to see.
#[pyfunction]
fn power<'py>(
    py: Python<'py>,
    expectation: PyReadonlyArrayDyn<'py, f32>,
    variance: PyReadonlyArrayDyn<'py, f32>,
    reference: PyReadonlyArrayDyn<'py, f32>,
    frames: u32,
) -> PyResult<Bound<'py, PyDict>> {
    let expectation = image_from_array("expectation", &expectation)?;
    let variance = image_from_array("variance", &variance)?;
    let reference = image_from_array("reference", &reference)?;
    let p = splat_cli::ztest::power(&expectation, &variance, &reference, frames).map_err(fail)?;
    let dict = PyDict::new(py);
    dict.set_item("global", p.global)?;
    dict.set_item("spread", p.spread)?;
    dict.set_item("visible", p.visible)?;
    Ok(dict)
}

/// Merge renders of shares of one run (`render(..., frames="A..B")`, in any order, their
/// frames following on) into the render of the whole run, as `splat merge` does: a dict with
/// "color", "variance", "alpha", "first", "count" and "run".
#[pyfunction]
fn merge<'py>(py: Python<'py>, parts: Vec<Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyDict>> {
    let mut shares = Vec::with_capacity(parts.len());
    for (i, part) in parts.iter().enumerate() {
        let item = |key: &str| {
            part.get_item(key)?.ok_or_else(|| {
                SplatError::new_err(format!("parts[{i}] has no \"{key}\": give merge the dicts render returns"))
            })
        };
        let image = |key: &str| -> PyResult<splat_core::Image> {
            let array = item(key)?;
            let array: PyReadonlyArrayDyn<'_, f32> = array
                .extract()
                .map_err(|_| SplatError::new_err(format!("parts[{i}][\"{key}\"] is not a float32 array")))?;
            image_from_array(&format!("parts[{i}][\"{key}\"]"), &array)
        };
        let accumulation = splat_core::frame::Accumulation {
            first: item("first")?.extract()?,
            count: item("count")?.extract()?,
            mean: image("color")?,
            variance: image("variance")?,
            alpha: image("alpha")?,
        };
        shares.push(splat_io::accumulation::Share { accumulation, render: item("run")?.extract()? });
    }
    let names: Vec<PathBuf> = (0..parts.len()).map(|i| PathBuf::from(format!("parts[{i}]"))).collect();
    let merged = splat_cli::merge::merge(&shares, &names).map_err(fail)?;
    let a = merged.accumulation;
    let dict = PyDict::new(py);
    dict.set_item("color", image_to_array(py, a.mean)?)?;
    dict.set_item("variance", image_to_array(py, a.variance)?)?;
    dict.set_item("alpha", image_to_array(py, a.alpha)?)?;
    dict.set_item("first", a.first)?;
    dict.set_item("count", a.count)?;
    dict.set_item("run", merged.render)?;
    Ok(dict)
}

/// The module.
#[pymodule]
fn _splat(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SplatError", m.py().get_type::<SplatError>())?;
    m.add("SH_C0", splat_core::sh::SH_C0)?;
    m.add_class::<PyScene>()?;
    m.add_class::<PyCamera>()?;
    m.add_class::<PyRenderer>()?;
    m.add_function(wrap_pyfunction!(load_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(render_views, m)?)?;
    m.add_function(wrap_pyfunction!(methods, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(z_test, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(power, m)?)?;
    Ok(())
}
