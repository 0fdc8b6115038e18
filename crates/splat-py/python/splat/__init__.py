"""Transparent 3D Gaussian splat rendering from Python.

The exact oracle (Sun et al. 2025, Eq. 3), the stochastic ray tracers and the splatting
methods of the ``splat`` command, on any CPU and any wgpu GPU, over numpy arrays::

    import numpy as np, splat
    scene = splat.Scene.from_arrays(means, scales, rotations, opacities, sh,
                                    log_scales=True, logit_opacities=True)   # gsplat's parameters
    camera = splat.Camera.from_matrices(viewmat, K, width=640, height=480)
    exact = splat.render(scene, camera)["color"]                             # (H, W, 3) float32
    noisy = splat.render(scene, camera, method="stochastic", spp=64, seed=1)
    print(splat.compare(exact, noisy["color"]))

``render`` takes every option of ``splat render`` as a keyword argument, dashes as
underscores (``raster_samples=16``, ``background=(1, 1, 1)``, ``backend="gpu"``); see
``splat render --help`` or docs/python.md.

Array conventions are those of 3DGS and gsplat: means (N, 3); scales (N, 3), linear or log;
rotations (N, 4) as quaternions w, x, y, z (normalised here); opacities (N,), in [0, 1] or
logits; sh (N, K, 3) with K = (degree + 1)^2, ``sh[:, 0]`` the DC term (colour = 0.5 +
C0 * sh0 + ...), or colors (N, 3) in [0, 1] for degree 0. Cameras are world-to-camera in
OpenCV axes (x right, y down, z forward) with K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
"""

from __future__ import annotations

import os
import uuid

import numpy as np

# Mesa's device-select layer warns on every Vulkan instance of a headless session; the `splat`
# binary silences it the same way (splat_gpu::quiet_device_select), before any thread reads
# the environment.
if "XDG_RUNTIME_DIR" not in os.environ:
    os.environ.setdefault("NODEVICE_SELECT", "1")

from . import _splat  # noqa: E402
from ._splat import SH_C0, Camera, SplatError, merge, methods  # noqa: E402
from ._splat import compare as _compare  # noqa: E402
from ._splat import power as _power  # noqa: E402
from ._splat import z_test as _z_test  # noqa: E402

__all__ = [
    "Camera",
    "Renderer",
    "Scene",
    "SplatError",
    "SH_C0",
    "compare",
    "load_cameras",
    "merge",
    "methods",
    "power",
    "render",
    "render_views",
    "z_test",
]


def _as_f32(value, name: str) -> np.ndarray:
    """A contiguous float32 array over `value`: numpy arrays, anything with ``__array__`` (a CPU
    torch tensor, a jax array) or ``__dlpack__``, without a copy when it is already float32 and
    C-contiguous."""
    if value is None:
        raise SplatError(f"{name} is None: expected an array")
    if not isinstance(value, np.ndarray) and hasattr(value, "__dlpack__") and not hasattr(value, "__array__"):
        try:
            value = np.from_dlpack(value)
        except (TypeError, RuntimeError, BufferError) as error:
            raise SplatError(f"{name}: cannot read it through DLPack ({error}); move it to the CPU first") from error
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, RuntimeError) as error:
        raise SplatError(f"{name}: cannot be read as an array ({error}); on a GPU, move it to the CPU first") from error
    if array.dtype.kind not in "fiu":
        raise SplatError(f"{name} has dtype {array.dtype}: expected numbers (float32 is read without a copy)")
    return np.ascontiguousarray(array, dtype=np.float32)


def load_cameras(
    path,
    dataparser_transforms=None,
    undistort=None,
    split=None,
    data_factor=None,
    image_size=None,
    gsplat_world: "Scene | None" = None,
    world_transform=None,
) -> list:
    """Every view of a camera file (an INRIA cameras.json, a COLMAP model: a sparse/0 folder or
    its images.bin / images.txt, or a transforms.json), as (image name, camera) in the order
    ``splat render`` lists them, changed as ``splat render``'s camera options change them:
    ``dataparser_transforms`` (a Nerfstudio run's dataparser_transforms.json), ``undistort``
    ("splatfacto" or "gsplat"), ``split`` ("3dgs-test", "nerfstudio-eval", ...), ``data_factor``
    F (``images_F/``), ``image_size`` (width, height), ``gsplat_world``, the Scene of splats
    gsplat's simple_trainer trained in its normalised world (its default), into which a COLMAP
    model's cameras are moved (``--gsplat-world``), and ``world_transform``, a 4 x 4 (or 3 x 4)
    similarity [s R | t] from the camera file's world to the splats' (an array such as gsplat's
    ``parser.transform``, or the path of a .npy or text file of it: ``--world-transform``),
    which moves every camera. See docs/python.md."""
    if gsplat_world is not None and not isinstance(gsplat_world, Scene):
        raise SplatError(f"gsplat_world is a {type(gsplat_world).__name__}: expected a splat.Scene of the splats")
    native = None if gsplat_world is None else gsplat_world._native
    file, rows = None, None
    if isinstance(world_transform, (str, os.PathLike)):
        file = world_transform
    elif world_transform is not None:
        matrix = np.asarray(world_transform, dtype=np.float64)
        if matrix.shape not in ((4, 4), (3, 4)):
            raise SplatError(f"world_transform has shape {matrix.shape}: expected a 4 x 4 (or 3 x 4) matrix")
        rows = matrix.tolist()
    return _splat.load_cameras(path, dataparser_transforms, undistort, split, data_factor, image_size, native, file, rows)


class Scene:
    """Splats (and, from a world file or glTF, meshes and lights) to render.

    A scene pickles (for Ray's object store, multiprocessing) as what made it: a file's path
    and reading options, or the arrays it was built from (kept by reference, so that the copy
    a worker rebuilds is the same scene bit for bit). A process rebuilds a scene once and keeps
    the last few it rebuilt, so that a Ray worker running many tasks reads the file once."""

    __slots__ = ("_native", "_origin")

    def __init__(self, native: _splat.Scene, origin: tuple):
        self._native = native
        self._origin = origin

    @staticmethod
    def load(path, **options) -> "Scene":
        """Read a scene file (.ply, compressed .ply, .splat, .spz, .sog or meta.json, .glb/.gltf,
        .ksplat, .usda, a trainer's checkpoint: 3DGS's .pth, gsplat's or 3DGRUT's .pt, Nerfstudio
        splatfacto's .ckpt) or a world file (.toml). `options` are ``splat render``'s reading options: strict,
        spz_axes, preset, screen_filter. What the reader notes (an extension skipped, the preset
        a 3DGRUT checkpoint renders with, ...) is a UserWarning."""
        path = os.fspath(path)
        return Scene(_splat.Scene.load(path, **options), ("load", uuid.uuid4().hex, path, options))

    @staticmethod
    def demo() -> "Scene":
        """The built-in demo scene, with its own camera."""
        return Scene(_splat.Scene.demo(), ("demo", uuid.uuid4().hex))

    def __reduce__(self):
        return (_rebuild, (self._origin,))

    @staticmethod
    def from_arrays(
        means,
        scales,
        rotations,
        opacities,
        sh=None,
        *,
        colors=None,
        log_scales: bool = False,
        logit_opacities: bool = False,
    ) -> "Scene":
        """Splats from arrays in the conventions of 3DGS and gsplat (see the module's doc).

        Give ``sh`` (N, K, 3) or ``colors`` (N, 3) in [0, 1]. ``log_scales`` and
        ``logit_opacities`` say that the arrays hold a trainer's raw parameters (exp and the
        sigmoid are applied here, as the .ply reader does)."""
        if (sh is None) == (colors is None):
            raise SplatError("give sh (N, K, 3) or colors (N, 3), one of them")
        if colors is not None:
            rgb = _as_f32(colors, "colors")
            if rgb.ndim != 2 or rgb.shape[1] != 3:
                raise SplatError(f"colors has shape {rgb.shape}; expected (N, 3)")
            sh = ((rgb - 0.5) / SH_C0)[:, None, :]
        arrays = (
            _as_f32(means, "means"),
            _as_f32(scales, "scales"),
            _as_f32(rotations, "rotations"),
            _as_f32(opacities, "opacities"),
            _as_f32(sh, "sh"),
            bool(log_scales),
            bool(logit_opacities),
        )
        return Scene(_splat.Scene.from_arrays(*arrays), ("arrays", uuid.uuid4().hex, arrays))

    def to_arrays(self) -> dict:
        """The splats as float32 arrays in from_arrays's conventions (linear scales, opacities
        in [0, 1], unit w, x, y, z quaternions): "means", "scales", "rotations", "opacities",
        "sh" (N, K, 3)."""
        return self._native.to_arrays()

    def __len__(self) -> int:
        return len(self._native)

    @property
    def sh_degree(self) -> int:
        """SH degree of the colours (0 to 3)."""
        return self._native.sh_degree

    @property
    def triangles(self) -> int:
        """Mesh triangles (worlds and glTF files)."""
        return self._native.triangles

    @property
    def screen_filter(self) -> str:
        """The screen-space filter the splats were trained with, which the splatting methods
        apply: "3dgs" (its dilation), "antialiased" (gsplat's) or "mip" (Mip-Splatting's); the
        file's, or the one load()'s screen_filter= or preset= chose."""
        return self._native.screen_filter

    @property
    def trained(self):
        """The renderer and kernel the file says the splats were trained through (a trainer's
        checkpoint: gsplat's rasterizer for gsplat's and splatfacto's, 3DGRUT's as its config
        names it; a 3DGS .ply in its model folder), which render() applies where no preset,
        kernel, background or near plane is given: a dict of "preset" (a preset= name:
        "gsplat", "3dgrt", ...), "kernel_degree", "cutoff", "background" (the colour the
        trainer's evaluation composites over, None for black) and "near_plane" (where its
        rasterizer culled splats); None where the file says nothing."""
        return self._native.trained

    @property
    def camera(self):
        """The world's own camera (a world file's or the demo's), or None."""
        return self._native.camera

    def __repr__(self) -> str:
        return repr(self._native)


#: Scenes this process rebuilt from pickles, by the token of the scene they copy, newest last.
_rebuilt: dict = {}


def _rebuild(origin: tuple) -> Scene:
    """The scene `origin` describes (Scene.__reduce__), rebuilt once per process."""
    kind, token, *args = origin
    if token in _rebuilt:
        return _rebuilt[token]
    if kind == "load":
        path, options = args
        native = _splat.Scene.load(path, **options)
    elif kind == "demo":
        native = _splat.Scene.demo()
    else:
        (arrays,) = args
        native = _splat.Scene.from_arrays(*arrays)
    scene = Scene(native, origin)
    _rebuilt[token] = scene
    while len(_rebuilt) > 2:
        del _rebuilt[next(iter(_rebuilt))]
    return scene


def render(scene: Scene, camera=None, *, progress=None, **options) -> dict:
    """Render `scene` from `camera` as ``splat render`` does, `options` its options with dashes
    as underscores (method, spp, seed, backend, raster_samples, background, pipeline, ...).

    `camera` is a Camera, or a camera file (a cameras.json, COLMAP model or transforms.json,
    the view chosen by camera_index=); without it, eye= and target=, else the world's own
    camera, else one framing the scene. width= and height= rescale any of them.
    `progress(done, total)` is called with pixels done as a CPU render advances. On the GPU,
    ``depth=True`` and ``normal=True`` ask for those images (the CPU makes them always).

    Returns a dict of float32 arrays: "color" (H, W, 3), the mean over the frames; "variance"
    (H, W, 3), the per-frame variance; "alpha" (H, W), the coverage 1 - T; "depth" (H, W), the
    iso-opacity depth of frame 0 (NaN where none); "normal" (H, W, 3); and "device", where it
    ran; "first" and "count", the frames averaged (one where every frame is the same), and
    "run", what decides the frames besides their range. The path tracer (pipeline="path")
    returns no alpha, depth or normal.

    frames="A..B" renders frames A..B of the run seeded by seed= (a share of it): shares whose
    frames follow on merge into the whole run with merge().

    The interpreter's lock is released while rendering: other Python threads run meanwhile.
    """
    if not isinstance(scene, Scene):
        raise SplatError(f"scene is a {type(scene).__name__}: expected a splat.Scene (Scene.load, Scene.from_arrays)")
    if isinstance(camera, (str, os.PathLike)):
        options["camera"] = os.fspath(camera)
        camera = None
    elif camera is not None and not isinstance(camera, Camera):
        raise SplatError(f"camera is a {type(camera).__name__}: expected a splat.Camera or a camera file's path")
    return _splat.render(scene._native, camera, progress=progress, **options)


def render_views(scene: Scene, cameras, *, progress=None, **options) -> list:
    """Render `scene` through each of `cameras` (Camera objects, or the (name, Camera) pairs of
    load_cameras) as `render` renders one
    view, the same options and one dict a view, in order: each view's images equal
    ``render(scene, camera, **options)``'s, but the world is prepared once (the BVH; on the GPU
    also its device arrays and pipelines), where every `render` call prepares it anew. All the
    views' images are returned together: give a long list of large views in batches.
    `progress(done, total)` counts a CPU render's pixels over all the views. The path tracer
    (pipeline="path") renders this way too."""
    if not isinstance(scene, Scene):
        raise SplatError(f"scene is a {type(scene).__name__}: expected a splat.Scene (Scene.load, Scene.from_arrays)")
    cameras = [c[1] if isinstance(c, tuple) and len(c) == 2 else c for c in cameras]
    for i, camera in enumerate(cameras):
        if not isinstance(camera, Camera):
            raise SplatError(f"cameras[{i}] is a {type(camera).__name__}: expected a splat.Camera")
    return _splat.render_views(scene._native, cameras, progress=progress, **options)


class Renderer:
    """`scene` prepared once for renders through any number of cameras, one at a time, with
    `options` (those of `render`)::

        with splat.Renderer(scene, method="stochastic", spp=16, seed=1) as renderer:
            for camera in trajectory:
                image = renderer.render(camera)["color"]

    Each ``renderer.render(camera)`` returns what ``render(scene, camera, **options)`` returns,
    bit for bit, but the world is prepared once, when the renderer is made (the BVH; on the GPU
    also its device arrays and pipelines), where every `render` call prepares it anew: a worker
    thread keeps it until `close` (or the end of a ``with`` block, or the renderer's deletion).
    Views come back one at a time, so a long trajectory needs no more memory than one image.
    One render at a time: a second thread calling in meanwhile is refused (make a Renderer a
    thread). The path tracer (pipeline="path") renders this way too, its world (the BVH, the
    emitters; on the GPU the device arrays and kernel) prepared once."""

    def __init__(self, scene: Scene, **options):
        if not isinstance(scene, Scene):
            raise SplatError(f"scene is a {type(scene).__name__}: expected a splat.Scene (Scene.load, Scene.from_arrays)")
        self._native = _splat.Renderer(scene._native, **options)

    def render(self, camera, *, progress=None) -> dict:
        """The dict `render` returns for `camera` (a Camera, or a (name, Camera) pair of
        load_cameras); `progress(done, total)` counts a CPU render's pixels."""
        if isinstance(camera, tuple) and len(camera) == 2:
            camera = camera[1]
        if not isinstance(camera, Camera):
            raise SplatError(f"camera is a {type(camera).__name__}: expected a splat.Camera")
        return self._native.render(camera, progress=progress)

    def close(self) -> None:
        """Stop the worker, freeing what it prepared; later renders are refused."""
        self._native.close()

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def compare(reference, test, pixels_per_degree: float | None = None) -> dict:
    """RMSE, PSNR (peak 1), SSIM and FLIP of `test` against `reference` (images (H, W) or
    (H, W, C)), as ``splat compare`` measures them: a dict with those four keys."""
    return _compare(_as_f32(reference, "reference"), _as_f32(test, "test"), pixels_per_degree)


def z_test(mean, variance, reference, frames: int, mean_variance=None, variance_frames: int | None = None) -> dict:
    """The project's per-pixel z-test (``splat ztest``): is `mean`, averaged over `frames`
    frames of an estimator, consistent with `reference`? `variance` is the per-frame variance
    of an independent run of the same estimator (its "variance" output); given the mean run's
    own `mean_variance` and the independent run's `variance_frames`, the two are pooled by
    degrees of freedom (a rare event that moves the mean then widens its standard error too).

    Returns a dict: "passes", the statistics "global" (a consistent bias), "spread" (a bias of
    varying sign), "outliers", "variance" (the variance check), "floored", "tested" and
    "left_out" (pixel-channels), and "failures" (the criteria failed, in words)."""
    own = None if mean_variance is None else _as_f32(mean_variance, "mean_variance")
    return _z_test(
        _as_f32(mean, "mean"),
        _as_f32(variance, "variance"),
        _as_f32(reference, "reference"),
        int(frames),
        own,
        variance_frames,
    )


def power(expectation, variance, reference, frames: int) -> dict:
    """The power of the z-test against a bias (docs/power.md): `expectation` is a biased
    estimator's exact expected image (say the exact render of the scene with its opacities
    × 1.02), `variance` the per-frame variance of the unbiased estimator, `frames` the budget.
    Returns "global" and "spread", the statistics the biased estimator's z-test has on average,
    and "visible", whether either reaches 6, the level a test of this budget can be required to
    see (below it the bias hides in the noise of `frames` frames)."""
    return _power(
        _as_f32(expectation, "expectation"), _as_f32(variance, "variance"), _as_f32(reference, "reference"), int(frames)
    )
