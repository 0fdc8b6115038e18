"""Photographs undistorted as the trainers undistort them: `splat undistort` against OpenCV.

A trainer scores its renders against the photos it resampled itself. Each test ports the
trainer's own image code around OpenCV, pixel for pixel (Nerfstudio's `_undistort_image` in
`nerfstudio/data/utils/dataloaders.py`: `cv2.undistort` for perspective lenses, fisheye maps
and `cv2.remap` for fisheyes; gsplat's COLMAP parser and dataset, `examples/datasets/colmap.py`:
`cv2.initUndistortRectifyMap` and `cv2.remap`), runs it with OpenCV itself
(opencv-python-headless, pinned in requirements-test.txt) on a photo of uniform noise, and
requires `splat undistort`'s PNG to be the same array, value for value.

Noise makes every pixel depend on where it is sampled: a sample 1/32 px off (OpenCV's
fixed-point map step) moves a value by about 8 levels. The intrinsics are exact in single
precision, as Nerfstudio hands them to OpenCV (its cameras are float32 tensors) and as splat
stores them; with a COLMAP camera's double-precision K, gsplat's maps differ from splat's by
about 1e-5 px, which moves some values by a level. Controls, in the tests: samples 1/32 px
off, bilinear interpolation in f32 (the arithmetic of OpenCV's newer float kernels, which the
pinned OpenCV does not use for 8-bit photos) and a principal point without Nerfstudio's
half-pixel shift each change most of the values, so none could pass.
"""

from __future__ import annotations

import json
import subprocess

import cv2
import numpy as np
import pytest
import splat
from conftest import gsplat_fisheye, nerfstudio_undistort_image
from PIL import Image

# (name, w, h, fx, fy, cx, cy, k1, k2, k3, p1, p2): small perspective lenses, barrel and
# pincushion, unequal focal lengths, off-centre principal points; f32-exact intrinsics.
PERSPECTIVE = [
    ("barrel", 320, 240, 250.0, 252.5, 161.25, 118.75, -0.3, 0.09, -0.01, 0.001, -0.0015),
    ("pincushion", 256, 192, 200.0, 201.0, 128.5, 95.25, 0.12, 0.03, 0.0, -0.002, 0.001),
]
# (name, w, h, fx, fy, cx, cy, k1, k2, k3, k4): an OpenCV fisheye.
FISHEYE = [("fisheye", 320, 240, 180.0, 179.0, 160.5, 119.25, 0.05, -0.01, 0.003, -0.0005)]


def noise(w: int, h: int, channels: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (h, w, channels), dtype=np.uint8)


def intrinsics(fx, fy, cx, cy, dtype) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=dtype)


def splatfacto_photo(camera_type: str, distortion_params: np.ndarray, K: np.ndarray, image: np.ndarray):
    """Nerfstudio's `_undistort_image`'s image (K and the parameters float32, as its cameras
    hold them)."""
    return nerfstudio_undistort_image(camera_type, distortion_params, image, K)[1]


def gsplat_photo(K: np.ndarray, params: np.ndarray, image: np.ndarray, remap=cv2.remap) -> np.ndarray:
    """gsplat's parser (its maps and valid rectangle) and dataset (`cv2.remap`, the crop);
    `remap` in place of `cv2.remap` for the controls."""
    height, width = image.shape[:2]
    K_undist, roi_undist = cv2.getOptimalNewCameraMatrix(K, params, (width, height), 0)
    mapx, mapy = cv2.initUndistortRectifyMap(K, params, None, K_undist, (width, height), cv2.CV_32FC1)
    image = remap(image, mapx, mapy, cv2.INTER_LINEAR)
    x, y, w, h = roi_undist
    return image[y : y + h, x : x + w]


def float_bilinear(image, mapx, mapy, _):
    """Bilinear interpolation in f32, p00 + a (p01 - p00) along x then y, rounded (the
    arithmetic of OpenCV's newer float kernels), edges clamped: a control."""
    ix, iy = np.floor(mapx).astype(int), np.floor(mapy).astype(int)
    a, b = (mapx - ix)[..., None], (mapy - iy)[..., None]
    h, w = image.shape[:2]

    def p(dy, dx):
        return image[np.clip(iy + dy, 0, h - 1), np.clip(ix + dx, 0, w - 1)].astype(np.float32)

    v0 = p(0, 0) + a * (p(0, 1) - p(0, 0))
    v1 = p(1, 0) + a * (p(1, 1) - p(1, 0))
    return np.clip(np.rint(v0 + b * (v1 - v0)), 0, 255).astype(np.uint8)


def shifted_remap(image, mapx, mapy, interpolation):
    """`cv2.remap` a thirtysecond of a pixel to the right: a control."""
    return cv2.remap(image, mapx + np.float32(1 / 32), mapy, interpolation)


def undistort(splat_bin: str, tmp_path, camera, trainer: str, photo: np.ndarray, name: str) -> np.ndarray:
    """`splat undistort` of the one view of `camera`, whose photo lies in tmp_path/images."""
    (tmp_path / "images").mkdir(exist_ok=True)
    Image.fromarray(photo.squeeze()).save(tmp_path / "images" / name)
    out = tmp_path / "out"
    args = [splat_bin, "undistort", "--camera", str(camera), "--undistort", trainer, "-o", str(out)]
    subprocess.run(args, check=True, capture_output=True)
    result = np.asarray(Image.open(out / (name.rsplit(".", 1)[0] + ".png")))
    return result.reshape(result.shape[0], result.shape[1], -1)


def nerfstudio_file(path, camera_model: str, lens: tuple, distortion: dict) -> None:
    _, w, h, fx, fy, cx, cy = lens[:7]
    frame = {"file_path": "images/frame_00001.png", "transform_matrix": np.eye(4).tolist()}
    meta = {"camera_model": camera_model, "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": w, "h": h}
    path.write_text(json.dumps({**meta, **distortion, "frames": [frame]}))


def assert_same(ours: np.ndarray, theirs: np.ndarray, label: str) -> None:
    assert ours.shape == theirs.shape, f"{label}: {ours.shape} against OpenCV's {theirs.shape}"
    differ = ours != theirs
    worst = np.abs(ours.astype(int) - theirs.astype(int)).max()
    assert not differ.any(), f"{label}: {differ.mean():.2%} of the values differ, by up to {worst}"


@pytest.mark.parametrize("channels", [3, 1])
@pytest.mark.parametrize("lens", PERSPECTIVE, ids=lambda lens: lens[0])
def test_splatfactos_photo_of_an_opencv_lens(splat_bin, tmp_path, lens, channels):
    name, w, h, fx, fy, cx, cy, k1, k2, k3, p1, p2 = lens
    nerfstudio_file(tmp_path / "transforms.json", "OPENCV", lens, {"k1": k1, "k2": k2, "k3": k3, "p1": p1, "p2": p2})
    photo = noise(w, h, channels, 1)
    # Nerfstudio's get_distortion_params order: k1, k2, k3, k4, p1, p2.
    params = np.array([k1, k2, k3, 0.0, p1, p2], dtype=np.float32)
    theirs = splatfacto_photo("perspective", params, intrinsics(fx, fy, cx, cy, np.float32), photo.squeeze())
    theirs = theirs.reshape(theirs.shape[0], theirs.shape[1], -1)
    ours = undistort(splat_bin, tmp_path, tmp_path / "transforms.json", "splatfacto", photo, "frame_00001.png")
    assert_same(ours, theirs, name)
    # Control: the principal point without Nerfstudio's half-pixel shift.
    unshifted = splatfacto_photo("perspective", params, intrinsics(fx, fy, cx + 0.5, cy + 0.5, np.float32), photo.squeeze())
    unshifted = unshifted.reshape(unshifted.shape[0], unshifted.shape[1], -1)
    assert unshifted.shape != theirs.shape or (unshifted != theirs).mean() > 0.3


@pytest.mark.parametrize("lens", FISHEYE, ids=lambda lens: lens[0])
def test_splatfactos_photo_of_an_opencv_fisheye(splat_bin, tmp_path, lens):
    name, w, h, fx, fy, cx, cy, k1, k2, k3, k4 = lens
    nerfstudio_file(tmp_path / "transforms.json", "OPENCV_FISHEYE", lens, {"k1": k1, "k2": k2, "k3": k3, "k4": k4})
    photo = noise(w, h, 4, 2)
    params = np.array([k1, k2, k3, k4, 0.0, 0.0], dtype=np.float32)
    theirs = splatfacto_photo("fisheye", params, intrinsics(fx, fy, cx, cy, np.float32), photo)
    ours = undistort(splat_bin, tmp_path, tmp_path / "transforms.json", "splatfacto", photo, "frame_00001.png")
    assert_same(ours, theirs, name)


@pytest.mark.parametrize("lens", PERSPECTIVE, ids=lambda lens: lens[0])
def test_gsplats_photo_of_a_colmap_camera(splat_bin, tmp_path, lens):
    name, w, h, fx, fy, cx, cy, k1, k2, _, p1, p2 = lens
    sparse = tmp_path / "sparse" / "0"
    sparse.mkdir(parents=True)
    values = " ".join(repr(float(p)) for p in [fx, fy, cx, cy, k1, k2, p1, p2])
    (sparse / "cameras.txt").write_text(f"1 OPENCV {w} {h} {values}\n")
    (sparse / "images.txt").write_text("1 1 0 0 0 0 0 0 1 shot.png\n\n")
    (sparse / "points3D.txt").write_text("")
    photo = noise(w, h, 3, 3)
    # gsplat's _camera_distortion keeps OPENCV's k1, k2, p1, p2 as float32.
    K, params = intrinsics(fx, fy, cx, cy, np.float64), np.array([k1, k2, p1, p2], dtype=np.float32)
    theirs = gsplat_photo(K, params, photo)
    ours = undistort(splat_bin, tmp_path, sparse, "gsplat", photo, "shot.png")
    assert_same(ours, theirs, name)
    # Controls: samples 1/32 px off, and interpolation in f32, change most values.
    for control in (shifted_remap, float_bilinear):
        assert (gsplat_photo(K, params, photo, control) != theirs).mean() > 0.3, control.__name__


def test_gsplats_photo_of_a_colmap_fisheye(splat_bin, tmp_path):
    name, w, h, fx, fy, cx, cy, *k = FISHEYE[0]
    sparse = tmp_path / "sparse" / "0"
    sparse.mkdir(parents=True)
    values = " ".join(repr(float(p)) for p in [fx, fy, cx, cy, *k])
    (sparse / "cameras.txt").write_text(f"1 OPENCV_FISHEYE {w} {h} {values}\n")
    (sparse / "images.txt").write_text("1 1 0 0 0 0 0 0 1 shot.png\n\n")
    (sparse / "points3D.txt").write_text("")
    photo = noise(w, h, 3, 6)
    K, params = intrinsics(fx, fy, cx, cy, np.float64), np.array(k, dtype=np.float32)

    def theirs(remap=cv2.remap, middle=True):
        """gsplat's parser (the fisheye map and its crop) and dataset (`cv2.remap`, the crop)."""
        _, _, mapx, mapy, (x, y, w, h), _ = gsplat_fisheye(K, params, (photo.shape[1], photo.shape[0]), middle)
        return remap(photo, mapx, mapy, cv2.INTER_LINEAR)[y : y + h, x : x + w]

    expected = theirs()
    assert_same(undistort(splat_bin, tmp_path, sparse, "gsplat", photo, "shot.png"), expected, name)
    # Controls: samples 1/32 px off, interpolation in f32, and the map about c rather than the
    # image's middle (half a pixel and a quarter away) change most values.
    for control in (shifted_remap, float_bilinear):
        assert (theirs(control) != expected).mean() > 0.3, control.__name__
    about_c = theirs(middle=False)
    assert about_c.shape != expected.shape or (about_c != expected).mean() > 0.3
    # The mask of the pixels gsplat scores: `splat undistort --masks` and Camera.undistortion_mask
    # are its parser's `mask`, cropped; the mask about c, a control, differs.
    mask = gsplat_fisheye(K, params, (photo.shape[1], photo.shape[0]))[5]
    assert 0 < mask.mean() < 1, mask.mean()
    args = [splat_bin, "undistort", "--camera", str(sparse), "--undistort", "gsplat", "-o", str(tmp_path / "o")]
    subprocess.run([*args, "--masks", str(tmp_path / "masks")], check=True, capture_output=True)
    assert_same(np.asarray(Image.open(tmp_path / "masks" / "shot.png")), mask.astype(np.uint8) * 255, "--masks")
    camera = splat.load_cameras(sparse)[0][1]
    assert np.array_equal(camera.undistortion_mask("gsplat"), mask)
    assert camera.undistortion_mask("splatfacto") is None
    about_c = gsplat_fisheye(K, params, (photo.shape[1], photo.shape[0]), middle=False)[5]
    assert about_c.shape != mask.shape or (about_c != mask).mean() > 0.001
    # Scored as gsplat's evaluation scores a render (`render_colors[~masks] = 0`, then
    # torchmetrics' PSNR against the photograph): `splat compare --masks`.
    (tmp_path / "renders").mkdir()
    render = noise(mask.shape[1], mask.shape[0], 3, 7)
    Image.fromarray(render).save(tmp_path / "renders" / "shot.png")
    colors, pixels = render / 255.0, expected / 255.0
    colors[~mask] = 0
    theirs = 10 * np.log10(1 / np.mean((colors - pixels) ** 2))
    compare = [splat_bin, "compare", str(tmp_path / "o"), str(tmp_path / "renders")]

    def psnr(extra):
        out = subprocess.run([*compare, *extra], check=True, capture_output=True, text=True).stdout
        return float(next(line for line in out.splitlines() if line.startswith("shot ")).split()[1])

    masked, whole = psnr(["--masks", str(tmp_path / "masks")]), psnr([])
    assert abs(masked - theirs) < 1e-3 and abs(whole - theirs) > 0.01, (masked, whole, theirs)


def test_photos_that_do_not_fit_are_refused(splat_bin, tmp_path):
    lens = PERSPECTIVE[0]
    nerfstudio_file(tmp_path / "transforms.json", "OPENCV", lens, {"k1": -0.1})
    (tmp_path / "images").mkdir()
    Image.fromarray(noise(100, 80, 3, 4)).save(tmp_path / "images" / "frame_00001.png")
    args = [splat_bin, "undistort", "--camera", str(tmp_path), "--undistort", "splatfacto", "-o", str(tmp_path / "o")]
    run = subprocess.run(args, capture_output=True, text=True)
    assert run.returncode != 0 and "100 × 80 and the camera 320 × 240" in run.stderr, run.stderr
    (tmp_path / "images" / "frame_00001.png").unlink()
    run = subprocess.run(args, capture_output=True, text=True)
    assert run.returncode != 0 and "frame_00001.png" in run.stderr and "--images" in run.stderr, run.stderr


def test_a_python_camera_undistorts_its_photos_as_the_cli(tmp_path):
    name, w, h, fx, fy, cx, cy, k1, k2, k3, k4 = lens = FISHEYE[0]
    nerfstudio_file(tmp_path / "transforms.json", "OPENCV_FISHEYE", lens, {"k1": k1, "k2": k2, "k3": k3, "k4": k4})
    [(_, camera)] = splat.load_cameras(tmp_path / "transforms.json")
    params = np.array([k1, k2, k3, k4, 0.0, 0.0], dtype=np.float32)
    photo = noise(w, h, 4, 5)
    # An RGB view of an RGBA photo, as gsplat slices its images: not contiguous.
    rgb = photo[..., :3]
    theirs = splatfacto_photo("fisheye", params, intrinsics(fx, fy, cx, cy, np.float32), rgb)
    ours = camera.undistort_photo(rgb, "splatfacto")
    assert ours.dtype == np.uint8
    np.testing.assert_array_equal(ours, theirs, err_msg=name)
    assert camera.undistort_photo(photo[..., 0], "splatfacto").shape == (h, w)
    with pytest.raises(splat.SplatError, match="uint8"):
        camera.undistort_photo(photo.astype(np.float32), "splatfacto")
    with pytest.raises(splat.SplatError, match="100 × 80 and the camera 320 × 240"):
        camera.undistort_photo(noise(100, 80, 3, 6), "splatfacto")
    with pytest.raises(splat.SplatError, match="expected one of splatfacto, gsplat"):
        camera.undistort_photo(photo, "3dgs")
    # gsplat's ideal fisheye of the same photo, through Python.
    _, _, mapx, mapy, (x, y, cw, ch), _ = gsplat_fisheye(
        intrinsics(fx, fy, cx, cy, np.float64), np.array([k1, k2, k3, k4], dtype=np.float32), (w, h)
    )
    gsplat = cv2.remap(rgb, mapx, mapy, cv2.INTER_LINEAR)[y : y + ch, x : x + cw]
    np.testing.assert_array_equal(camera.undistort_photo(rgb, "gsplat"), gsplat, err_msg=name)


def gsplat_parser_K(K: np.ndarray, size, factor: int, actual):
    """gsplat's parser before it undistorts: K / factor and the sides floored, then K scaled to
    the size of the photographs it finds (`actual`, width and height)."""
    K = K.copy()
    K[:2, :] /= factor
    width, height = size[0] // factor, size[1] // factor
    s_height, s_width = actual[1] / height, actual[0] / width
    K[0, :] *= s_width
    K[1, :] *= s_height
    return K, (int(width * s_width), int(height * s_height))


def colmap_opencv(sparse, w, h, params, name="shot.png") -> None:
    sparse.mkdir(parents=True)
    (sparse / "cameras.txt").write_text(f"1 OPENCV {w} {h} {' '.join(repr(float(p)) for p in params)}\n")
    (sparse / "images.txt").write_text(f"1 1 0 0 0 0 0 0 1 {name}\n\n")
    (sparse / "points3D.txt").write_text("")


def test_gsplats_photo_at_a_data_factor(splat_bin, tmp_path):
    # A 1283 × 962 capture read from images_4/: K / 4 and 320 × 240, as gsplat's --data_factor 4;
    # its JPEG's photograph a PNG, as gsplat's images_4_png/ holds them.
    fx, fy, cx, cy, k1, k2, p1, p2 = 1000.0, 1010.0, 641.5, 480.25, -0.3, 0.09, 0.001, -0.0015
    sparse = tmp_path / "sparse" / "0"
    colmap_opencv(sparse, 1283, 962, [fx, fy, cx, cy, k1, k2, p1, p2], name="shot.JPG")
    photo = noise(320, 240, 3, 7)
    params = np.array([k1, k2, p1, p2], dtype=np.float32)
    K, size = gsplat_parser_K(intrinsics(fx, fy, cx, cy, np.float64), (1283, 962), 4, (320, 240))
    assert size == (320, 240)
    theirs = gsplat_photo(K, params, photo)
    (tmp_path / "images").mkdir()
    Image.fromarray(photo).save(tmp_path / "images" / "shot.png")
    args = [splat_bin, "undistort", "--camera", str(sparse), "--undistort", "gsplat", "--data-factor", "4"]
    subprocess.run([*args, "-o", str(tmp_path / "out")], check=True, capture_output=True)
    assert_same(np.asarray(Image.open(tmp_path / "out" / "shot.png")), theirs, "data factor 4")
    # Without the factor, the camera does not fit the photographs, and the refusal says so.
    run = subprocess.run([*args[:-2], "-o", str(tmp_path / "o")], capture_output=True, text=True)
    assert run.returncode != 0 and "--data-factor" in run.stderr, run.stderr


@pytest.mark.parametrize("actual", [(320, 240), (321, 241)])
def test_gsplats_camera_at_a_data_factor_and_the_photographs_size(tmp_path, actual):
    fx, fy, cx, cy, k1, k2, p1, p2 = 1000.0, 1010.0, 641.5, 480.25, -0.3, 0.09, 0.001, -0.0015
    sparse = tmp_path / "sparse" / "0"
    colmap_opencv(sparse, 1283, 962, [fx, fy, cx, cy, k1, k2, p1, p2])
    K, size = gsplat_parser_K(intrinsics(fx, fy, cx, cy, np.float64), (1283, 962), 4, actual)
    params = np.array([k1, k2, p1, p2], dtype=np.float32)
    K_undist, roi = cv2.getOptimalNewCameraMatrix(K, params, size, 0)
    [(_, camera)] = splat.load_cameras(sparse, undistort="gsplat", data_factor=4, image_size=actual)
    assert (camera.width, camera.height) == (roi[2], roi[3])
    np.testing.assert_allclose(camera.K, K_undist, rtol=0, atol=1e-3)
    # Scaled to the photographs from the whole capture instead (3DGS's way, which keeps the
    # field of view), the camera misses gsplat's by more than half a pixel (fx and cx: 0.58, 0.38 px).
    [(_, proportional)] = splat.load_cameras(sparse)
    ratio = np.array([actual[0] / 1283, actual[1] / 962, 1.0])[:, None]
    assert np.abs(proportional.K * ratio - K).max() > 0.5


def test_a_python_camera_scales_and_undistorts_as_load_cameras(tmp_path):
    sparse = tmp_path / "sparse" / "0"
    colmap_opencv(sparse, 1283, 962, [1000.0, 1010.0, 641.5, 480.25, -0.3, 0.09, 0.001, -0.0015])
    [(_, camera)] = splat.load_cameras(sparse)
    for options, made in [
        ({"data_factor": 4}, camera.downscaled(4)),
        ({"undistort": "gsplat"}, camera.undistorted("gsplat")),
        (
            {"undistort": "splatfacto", "data_factor": 4, "image_size": (321, 241)},
            camera.downscaled(4).rescaled(321, 241).undistorted("splatfacto"),
        ),
    ]:
        [(_, loaded)] = splat.load_cameras(sparse, **options)
        assert (made.width, made.height) == (loaded.width, loaded.height), options
        np.testing.assert_array_equal(made.K, loaded.K, err_msg=str(options))
    assert (camera.downscaled(4).width, camera.downscaled(4).height) == (320, 240)
    with pytest.raises(splat.SplatError, match="downscale factor of 0"):
        camera.downscaled(0)
    with pytest.raises(splat.SplatError, match="expected one of splatfacto, gsplat"):
        camera.undistorted("3dgs")


def test_splatfactos_photo_at_a_downscale_factor(splat_bin, tmp_path):
    # A 641 × 481 Nerfstudio capture read from images_2/: the dataparser's
    # rescale_output_resolution(1 / 2) (float32 K times 0.5, the sides floored to 320 × 240),
    # then _undistort_image of the 320 × 240 photograph, which lies in images_2/ by file name.
    lens = ("odd", 641, 481, 500.0, 505.0, 321.25, 240.75, -0.3, 0.09, -0.01, 0.001, -0.0015)
    name, w, h, fx, fy, cx, cy, k1, k2, k3, p1, p2 = lens
    nerfstudio_file(tmp_path / "transforms.json", "OPENCV", lens, {"k1": k1, "k2": k2, "k3": k3, "p1": p1, "p2": p2})
    photo = noise(w // 2, h // 2, 3, 8)
    (tmp_path / "images_2").mkdir()
    Image.fromarray(photo).save(tmp_path / "images_2" / "frame_00001.png")
    K = intrinsics(fx, fy, cx, cy, np.float32) * np.array([[0.5], [0.5], [1.0]], dtype=np.float32)
    params = np.array([k1, k2, k3, 0.0, p1, p2], dtype=np.float32)
    theirs = splatfacto_photo("perspective", params, K, photo)
    args = ["--camera", str(tmp_path), "--undistort", "splatfacto", "--data-factor", "2"]
    out = tmp_path / "out"
    subprocess.run([splat_bin, "undistort", *args, "--images", str(tmp_path / "images_2"), "-o", str(out)], check=True)
    assert_same(np.asarray(Image.open(out / "frame_00001.png")), theirs, name)
