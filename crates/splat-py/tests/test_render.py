"""Renders from Python: equal to the CLI's render of the same .ply, equal to an independent
numpy Eq. 3 on a tiny scene, every method and option reachable, the interpreter's lock
released while rendering."""

from __future__ import annotations

import subprocess
import threading

import numpy as np
import pytest
import splat
from conftest import raw_gaussians, write_3dgs_ply

EYE, TARGET = (0.3, -0.2, -0.5), (0.0, 0.0, 4.5)
WIDTH, HEIGHT = 40, 30


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """Raw Gaussians, the same written as a 3DGS .ply, and the scene from the arrays."""
    g = raw_gaussians(np.random.default_rng(7), 60, degree=2)
    ply = tmp_path_factory.mktemp("capture") / "capture.ply"
    write_3dgs_ply(ply, g)
    scene = splat.Scene.from_arrays(**g, log_scales=True, logit_opacities=True)
    return g, ply, scene


@pytest.mark.parametrize(
    "options",
    [
        {"method": "exact"},
        {"method": "exact", "sh_storage": "f16"},
        {"method": "exact", "sh_storage": "u8"},
        {"method": "stochastic", "spp": 4, "seed": 3},
        {"method": "kbuffer", "k": 4},
        {"method": "raster-sorted", "raster_samples": 4},
        {"method": "stratified", "raster_samples": 8, "spp": 2, "background": (0.2, 0.3, 0.4)},
    ],
    ids=lambda o: "-".join(str(v) for k, v in o.items() if k in ("method", "sh_storage")),
)
def test_arrays_render_equals_the_cli_render_of_the_same_ply(capture, splat_bin, tmp_path, options):
    """The scene from arrays in a trainer's raw parameters, rendered from Python, equals bit for
    bit `splat render` of the .ply written from those arrays by an independent writer (the
    activations, the quaternion order and the SH layout of .ply all checked on the way)."""
    _, ply, scene = capture
    camera = splat.Camera.look_at(EYE, TARGET, up=(0, -1, 0), fov_y=50, width=WIDTH, height=HEIGHT)
    out = splat.render(scene, camera, backend="cpu", **options)
    flags = []
    for key, value in options.items():
        text = ",".join(map(str, value)) if isinstance(value, tuple) else str(value)
        flags.append(f"--{key.replace('_', '-')}={text}")
    eye, target = ",".join(map(str, EYE)), ",".join(map(str, TARGET))
    files = {name: tmp_path / f"{name}.npy" for name in ("color", "alpha", "depth")}
    command = [splat_bin, "render", str(ply), f"--eye={eye}", f"--target={target}", "--up=0,-1,0", "--fov=50"]
    command += [f"--width={WIDTH}", f"--height={HEIGHT}", "--backend=cpu", "-o", str(files["color"])]
    command += ["--alpha", str(files["alpha"]), "--depth", str(files["depth"]), *flags]
    subprocess.run(command, check=True, capture_output=True)
    for name, path in files.items():
        cli = np.load(path)
        cli = cli.reshape(cli.shape[:2]) if cli.ndim == 3 and cli.shape[2] == 1 else cli
        np.testing.assert_array_equal(out[name], cli, err_msg=f"{name} differs from the CLI's")
    assert out["device"] == "cpu"


PATH = {"pipeline": "path", "spp": 2, "seed": 5, "max_depth": 2}


@pytest.mark.parametrize("options", [{"method": "stochastic", "spp": 2, "seed": 5}, {"method": "raster-sorted"}, PATH])
def test_render_views_equals_a_render_of_each_view(capture, options):
    """render_views prepares the world once and renders every camera through it: each view's
    dict equals render()'s of that camera alone, bit for bit, for a ray-tracing method, a
    splatting one and the path tracer; the views differ from each other; wrong inputs are
    refused by name."""
    _, _, scene = capture
    look = lambda x: splat.Camera.look_at((x, -0.2, -0.5), TARGET, up=(0, -1, 0), width=WIDTH, height=HEIGHT)  # noqa: E731
    cameras = [look(x) for x in (0.3, -0.4, 0.1)]
    views = splat.render_views(scene, cameras, backend="cpu", **options)
    assert len(views) == 3
    for camera, view in zip(cameras, views):
        one = splat.render(scene, camera, backend="cpu", **options)
        assert set(view) == set(one)
        for name in ("color", "variance", "alpha", "depth"):
            if name in one:
                np.testing.assert_array_equal(view[name], one[name], err_msg=f"{name} differs from render()'s")
        assert (view["run"], view["count"], view["device"]) == (one["run"], one["count"], one["device"])
    assert not np.array_equal(views[0]["color"], views[1]["color"])
    assert splat.render_views(scene, [], backend="cpu") == []
    with pytest.raises(splat.SplatError, match=r"cameras\[1\] is a str"):
        splat.render_views(scene, [cameras[0], "cameras.json"])


@pytest.mark.parametrize("options", [{"method": "stochastic", "spp": 2, "seed": 5}, {"method": "raster-sorted"}, PATH])
def test_a_renderer_renders_each_view_as_render_does(capture, options):
    """A Renderer prepares the world once and renders camera after camera through it, with the
    splat methods and the path tracer: each view's dict equals render()'s of that camera alone,
    bit for bit, and its progress counts that view's pixels; a view too large is refused and the
    renderer goes on; after close(), and outside its with block, renders are refused by name."""
    _, _, scene = capture
    look = lambda x, w=WIDTH: splat.Camera.look_at((x, -0.2, -0.5), TARGET, up=(0, -1, 0), width=w, height=HEIGHT)  # noqa: E731
    cameras = [look(0.3), ("named", look(-0.4)), look(0.1, w=WIDTH + 8)]
    with splat.Renderer(scene, backend="cpu", **options) as renderer:
        views = []
        for camera in cameras:
            calls = []
            views.append(renderer.render(camera, progress=lambda d, t: calls.append((d, t))))
            size = views[-1]["color"].shape[0] * views[-1]["color"].shape[1]
            assert calls and calls[-1] == (size, size), calls[-3:]
        with pytest.raises(splat.SplatError, match="image size 100000"):
            renderer.render(look(0.0, w=100_000))
        with pytest.raises(splat.SplatError, match="expected a splat.Camera"):
            renderer.render("cameras.json")
        again = renderer.render(cameras[0])
    for camera, view in zip(cameras, views):
        one = splat.render(scene, camera[1] if isinstance(camera, tuple) else camera, backend="cpu", **options)
        assert set(view) == set(one)
        for name in ("color", "variance", "alpha", "depth", "normal"):
            if name in one:
                np.testing.assert_array_equal(view[name], one[name], err_msg=f"{name} differs from render()'s")
        assert (view["run"], view["count"], view["first"], view["device"]) == (
            one["run"], one["count"], one["first"], one["device"])
    np.testing.assert_array_equal(again["color"], views[0]["color"])
    assert views[2]["color"].shape == (HEIGHT, WIDTH + 8, 3)
    assert not np.array_equal(views[0]["color"], views[1]["color"])
    with pytest.raises(splat.SplatError, match="closed"):
        renderer.render(cameras[0])
    renderer.close()
    with pytest.raises(splat.SplatError, match="expected a splat.Scene"):
        splat.Renderer("scene.ply")


def test_a_renderer_answers_a_second_call_during_a_render_at_once():
    """A render called while another is under way (here from the first's progress callback,
    which runs on a worker thread while the interpreter's lock is released) is refused at once,
    one render at a time said by name, instead of waiting on the first: a renderer that held its
    lock through a render would hang here. The first render is not disturbed."""
    scene = splat.Scene.demo()
    renderer = splat.Renderer(scene, method="exact", backend="cpu")
    camera = splat.Camera.look_at((0, 0.5, 3), (0, 0.5, 0), width=64, height=48)
    refused = []

    def progress(done, total):
        if not refused:
            try:
                renderer.render(camera)
            except splat.SplatError as error:
                refused.append(str(error))

    first = renderer.render(camera, progress=progress)
    assert refused and "one render at a time" in refused[0], refused
    np.testing.assert_array_equal(renderer.render(camera)["color"], first["color"])
    renderer.close()


def test_a_scene_from_arrays_equals_the_same_scene_from_linear_values(capture):
    """log_scales and logit_opacities apply exp and the sigmoid, nothing else."""
    g, _, raw_scene = capture
    linear = dict(g, scales=np.exp(g["scales"]), opacities=1 / (1 + np.exp(-g["opacities"].astype(np.float64))))
    scene = splat.Scene.from_arrays(**linear)
    camera = splat.Camera.look_at(EYE, TARGET, width=24, height=18)
    a = splat.render(raw_scene, camera, backend="cpu")["color"]
    b = splat.render(scene, camera, backend="cpu")["color"]
    np.testing.assert_allclose(a, b, atol=2e-6)
    assert len(scene) == 60 and scene.sh_degree == 2


def independent_eq3(means, scales, quats, opacities, colors, viewmat, K, width, height, background):
    """Eq. 3 of Sun et al. in numpy, from the definitions: each ray through a pixel centre
    meets each Gaussian at its maximum response along the ray, α = min(o · exp(−½ d²), 0.99)
    (kept where d ≤ 3 and α ≥ 1/255), hits sorted by the distance of that point, composited
    C = Σ cᵢ αᵢ Πⱼ<ᵢ (1 − αⱼ) + T · background."""
    rotation_wc, translation = viewmat[:3, :3], viewmat[:3, 3]
    origin = -rotation_wc.T @ translation
    w, x, y, z = (quats / np.linalg.norm(quats, axis=1, keepdims=True)).T
    rotations = np.stack(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    ).transpose(2, 0, 1)
    image = np.zeros((height, width, 3))
    for py in range(height):
        for px in range(width):
            d_cam = np.array([(px + 0.5 - K[0, 2]) / K[0, 0], (py + 0.5 - K[1, 2]) / K[1, 1], 1.0])
            d = rotation_wc.T @ d_cam
            d /= np.linalg.norm(d)
            hits = []
            for i in range(len(means)):
                to_canonical = np.diag(1 / scales[i]) @ rotations[i].T
                o_c, d_c = to_canonical @ (origin - means[i]), to_canonical @ d
                t = -(o_c @ d_c) / (d_c @ d_c)
                d2 = np.sum((o_c + t * d_c) ** 2)
                alpha = min(opacities[i] * np.exp(-0.5 * d2), 0.99)
                if d2 <= 9 and alpha >= 1 / 255 and t > 0.001:
                    hits.append((t, alpha, colors[i]))
            transmittance, color = 1.0, np.zeros(3)
            for _, alpha, c in sorted(hits, key=lambda h: h[0]):
                color += transmittance * alpha * c
                transmittance *= 1 - alpha
            image[py, px] = color + transmittance * background
    return image


def test_a_tiny_scene_equals_an_independent_numpy_eq3():
    """Five overlapping Gaussians through a camera given as gsplat's viewmat and K."""
    rng = np.random.default_rng(11)
    means = np.array([[0.0, 0.0, 4.0], [0.3, 0.1, 4.5], [-0.4, -0.2, 3.5], [0.1, -0.3, 5.0], [-0.2, 0.3, 4.2]])
    scales = rng.uniform(0.15, 0.5, (5, 3))
    quats = rng.normal(size=(5, 4))
    opacities = np.array([0.9, 0.6, 0.4, 0.95, 0.2])
    colors = rng.uniform(0.05, 0.95, (5, 3))
    angle = 0.1
    viewmat = np.eye(4)
    viewmat[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    viewmat[:3, 3] = [0.1, -0.05, 0.2]
    K = np.array([[30.0, 0, 12.3], [0, 31.0, 9.1], [0, 0, 1]])
    background = np.array([0.1, 0.2, 0.3])
    scene = splat.Scene.from_arrays(means, scales, quats, opacities, colors=colors)
    camera = splat.Camera.from_matrices(viewmat, K, 24, 18)
    np.testing.assert_allclose(camera.viewmat, viewmat, atol=1e-7)
    np.testing.assert_allclose(camera.K, K, atol=1e-7)
    for method in ("exact", "oracle"):
        ours = splat.render(scene, camera, method=method, background=tuple(background), backend="cpu")["color"]
        theirs = independent_eq3(means, scales, quats, opacities, colors, viewmat, K, 24, 18, background)
        assert np.abs(theirs - background).max() > 0.3, "the Gaussians cover part of the image"
        np.testing.assert_allclose(ours, theirs, atol=2e-5, err_msg=method)


def test_every_method_of_the_catalogue_renders_from_python():
    """Every method the catalogue lists, by its name, with its parameters as keywords."""
    scene = splat.Scene.demo()
    values = {"k": 4, "max_passes": 50, "samples_per_traversal": 4, "traversals": 2, "raster_samples": 4}
    names = []
    for entry in splat.methods():
        params = {p: values[p] for p in entry["parameters"] if p in values}
        out = splat.render(scene, method=entry["name"], width=16, height=12, spp=2, backend="cpu", **params)
        assert out["color"].shape == (12, 16, 3) and np.isfinite(out["color"]).all(), entry["name"]
        names.append(entry["name"])
    assert {"exact", "stochastic", "raster-sorted", "stratified", "oracle"} <= set(names)


def test_the_path_tracer_and_a_camera_file(tmp_path):
    """pipeline="path" renders colour and variance; camera= reads a cameras.json."""
    camera = splat.Scene.demo().camera
    entry = {
        "id": 0,
        "img_name": "view",
        "width": 20,
        "height": 16,
        "position": [0.0, 1.9, 3.6],
        "rotation": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        "fx": 18.0,
        "fy": 18.0,
    }
    path = tmp_path / "cameras.json"
    path.write_text(__import__("json").dumps([entry]))
    ((name, loaded),) = splat.load_cameras(path)
    assert name == "view" and (loaded.width, loaded.height) == (20, 16)
    out = splat.render(splat.Scene.demo(), camera=str(path), pipeline="path", spp=2, backend="cpu")
    assert set(out) == {"color", "variance", "device", "first", "count", "run"} and out["color"].shape == (16, 20, 3)
    assert camera is not None


def test_progress_is_reported_and_the_lock_is_released():
    """progress(done, total) rises to the pixel count; another Python thread runs while the
    render does (the interpreter's lock is released); an exception in the callback is raised."""
    scene = splat.Scene.demo()
    calls, ticks, stop = [], [0], threading.Event()

    def count():
        while not stop.is_set():
            ticks[0] += 1

    counter = threading.Thread(target=count)
    counter.start()
    try:
        splat.render(scene, width=96, height=72, method="exact", backend="cpu", progress=lambda d, t: calls.append((d, t)))
    finally:
        stop.set()
        counter.join()
    assert calls and calls[-1] == (96 * 72, 96 * 72)
    assert all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))
    assert ticks[0] > 1000, "the counting thread ran during the render"

    def fail(done, total):
        raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        splat.render(scene, width=16, height=12, backend="cpu", progress=fail)


def test_arrays_are_read_without_a_copy_where_the_layout_allows():
    """float32 C-contiguous arrays pass through as they are; objects with __array__ (a CPU
    torch tensor, a jax array) or only __dlpack__ are read too."""
    from splat import _as_f32

    a = np.ones((4, 3), np.float32)
    assert _as_f32(a, "a") is a

    class ArrayLike:
        def __array__(self, dtype=None, copy=None):
            return a

    class DlpackOnly:
        def __dlpack__(self, stream=None, **kwargs):
            return a.__dlpack__()

        def __dlpack_device__(self):
            return a.__dlpack_device__()

    assert np.shares_memory(_as_f32(ArrayLike(), "x"), a)
    assert np.shares_memory(_as_f32(DlpackOnly(), "x"), a)
    assert _as_f32(np.ones((4, 3)), "f64").dtype == np.float32


def test_the_type_stubs_cover_the_extension_module():
    """Every public name of splat._splat, and every method of its classes, has a stub in
    _splat.pyi (so that editors complete them), and the stubs name nothing that is not there."""
    import ast
    import importlib.resources

    stubs = ast.parse(importlib.resources.files("splat").joinpath("_splat.pyi").read_text())
    stubbed = {}
    for node in stubs.body:
        if isinstance(node, ast.ClassDef):
            stubbed[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        elif isinstance(node, ast.FunctionDef):
            stubbed[node.name] = None
        elif isinstance(node, ast.AnnAssign):
            stubbed[node.target.id] = None
    native = splat._splat
    public = {name for name in dir(native) if not name.startswith("_")}
    assert public == set(stubbed), (public ^ set(stubbed))
    for name in ("Scene", "Camera", "Renderer"):
        methods = {m for m in dir(getattr(native, name)) if not m.startswith("_")}
        assert methods == {m for m in stubbed[name] if not m.startswith("_")}, (name, methods ^ stubbed[name])
