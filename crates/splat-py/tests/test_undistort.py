"""Distorted cameras made the pinholes the trainers undistort their photos to, as OpenCV does.

Splatfacto and gsplat train on photos resampled by OpenCV to a pinhole camera that OpenCV
chooses. Each test ports the trainer's own code around OpenCV (Nerfstudio's `_undistort_image`
in `nerfstudio/data/utils/dataloaders.py`; gsplat's COLMAP parser, `examples/datasets/colmap.py`),
calls OpenCV itself (opencv-python-headless, pinned in requirements-test.txt), and compares the
resulting K and image size with `splat.load_cameras(..., undistort=...)`: splat's port of OpenCV's
estimates, in Rust, must agree with OpenCV.

The strong lenses make OpenCV's own approximation visible: `undistortPoints` stops after five
fixed-point steps, short of the inverse there. Control, run by hand: the port iterated 50 times
instead misses OpenCV's K by 258 px on the strong barrel lens and 0.004 px on the pincushion,
against the tolerance of 1e-3 px (f32 storage of K).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import splat
from conftest import gsplat_fisheye, nerfstudio_undistort_image

# f32 storage of K (values up to 2,000 px) against OpenCV's f64.
TOLERANCE_PX = 1e-3


def opencv_lenses():
    """(name, w, h, fx, fy, cx, cy, k1, k2, k3, p1, p2): mild and strong perspective lenses,
    barrel and pincushion, with unequal focal lengths and an off-centre principal point."""
    return [
        ("mild-barrel", 1280, 720, 1000.0, 1010.0, 645.3, 352.9, -0.08, 0.02, 0.0, 0.0004, -0.0007),
        ("strong-barrel", 1600, 1200, 900.0, 880.0, 790.0, 610.0, -0.32, 0.11, -0.015, 0.001, 0.002),
        ("pincushion", 640, 480, 500.0, 505.0, 322.0, 236.0, 0.12, 0.03, 0.0, -0.002, 0.001),
    ]


def fisheye_lenses():
    """(name, w, h, fx, fy, cx, cy, k1, k2, k3, k4): OpenCV fisheyes."""
    return [
        ("gopro", 1920, 1080, 860.0, 858.0, 955.0, 545.0, 0.05, -0.01, 0.003, -0.0005),
        ("narrow", 800, 600, 700.0, 690.0, 405.0, 297.0, 0.1, 0.02, 0.0, 0.0),
    ]


def nerfstudio_file(path, camera_model: str, lens: tuple, distortion: dict) -> None:
    """A Nerfstudio transforms.json of one view through `lens`."""
    _, w, h, fx, fy, cx, cy = lens[:7]
    frame = {"file_path": "images/frame_00001.png", "transform_matrix": np.eye(4).tolist()}
    meta = {"camera_model": camera_model, "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": w, "h": h}
    path.write_text(json.dumps({**meta, **distortion, "frames": [frame]}))


def splatfacto_undistort(camera_type: str, distortion_params: np.ndarray, K: np.ndarray, size):
    """Nerfstudio's `_undistort_image` for K and the image's size: returns the new K and
    (width, height)."""
    if not np.any(distortion_params):
        return K, size
    width, height = size
    K, image = nerfstudio_undistort_image(camera_type, distortion_params, np.zeros((height, width), np.uint8), K)
    return K, (image.shape[1], image.shape[0])


def intrinsics(fx, fy, cx, cy) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def assert_camera(camera, K: np.ndarray, size, label: str) -> None:
    assert (camera.width, camera.height) == tuple(int(s) for s in size), label
    assert camera.is_pinhole, label
    np.testing.assert_allclose(camera.K, K, rtol=0, atol=TOLERANCE_PX, err_msg=label)


@pytest.mark.parametrize("lens", opencv_lenses(), ids=lambda lens: lens[0])
def test_splatfactos_pinhole_of_an_opencv_lens(tmp_path, lens):
    name, w, h, fx, fy, cx, cy, k1, k2, k3, p1, p2 = lens
    path = tmp_path / "transforms.json"
    nerfstudio_file(path, "OPENCV", lens, {"k1": k1, "k2": k2, "k3": k3, "p1": p1, "p2": p2})
    # Nerfstudio's camera_utils.get_distortion_params order: k1, k2, k3, k4, p1, p2.
    params = np.array([k1, k2, k3, 0.0, p1, p2])
    K, size = splatfacto_undistort("perspective", params, intrinsics(fx, fy, cx, cy), (w, h))
    [(_, camera)] = splat.load_cameras(path, undistort="splatfacto")
    assert_camera(camera, K, size, name)


@pytest.mark.parametrize("lens", fisheye_lenses(), ids=lambda lens: lens[0])
def test_splatfactos_pinhole_of_an_opencv_fisheye(tmp_path, lens):
    name, w, h, fx, fy, cx, cy, k1, k2, k3, k4 = lens
    path = tmp_path / "transforms.json"
    nerfstudio_file(path, "OPENCV_FISHEYE", lens, {"k1": k1, "k2": k2, "k3": k3, "k4": k4})
    params = np.array([k1, k2, k3, k4, 0.0, 0.0])
    K, size = splatfacto_undistort("fisheye", params, intrinsics(fx, fy, cx, cy), (w, h))
    [(_, camera)] = splat.load_cameras(path, undistort="splatfacto")
    assert_camera(camera, K, size, name)


def colmap_text_model(folder, model: str, w: int, h: int, params: list[float]) -> None:
    """A COLMAP text model of one camera and one registered image at the origin."""
    folder.mkdir()
    values = " ".join(repr(float(p)) for p in params)
    (folder / "cameras.txt").write_text(f"1 {model} {w} {h} {values}\n")
    (folder / "images.txt").write_text("1 1 0 0 0 0 0 0 1 frame.png\n\n")
    (folder / "points3D.txt").write_text("")


def gsplat_undistort(model: str, params: list[float], size):
    """gsplat's COLMAP parser (`_camera_distortion`, then the undistortion of `Parser.__init__`)
    for K and the image's size."""
    width, height = size
    if model == "SIMPLE_RADIAL":
        f, cx, cy, k = params
        K, distortion = intrinsics(f, f, cx, cy), np.array([k, 0.0, 0.0, 0.0], dtype=np.float32)
    elif model == "RADIAL":
        f, cx, cy, k1, k2 = params
        K, distortion = intrinsics(f, f, cx, cy), np.array([k1, k2, 0.0, 0.0], dtype=np.float32)
    else:
        fx, fy, cx, cy = params[:4]
        K, distortion = intrinsics(fx, fy, cx, cy), np.array(params[4:8], dtype=np.float32)
    K_undist, roi_undist = cv2.getOptimalNewCameraMatrix(K, distortion, (width, height), 0)
    return K_undist, (roi_undist[2], roi_undist[3])


def gsplat_cases():
    """(model, w, h, params): COLMAP's distorted perspective models gsplat reads."""
    cases = [
        ("SIMPLE_RADIAL", 1000, 750, [820.0, 501.5, 373.0, -0.05]),
        ("RADIAL", 640, 480, [520.0, 318.0, 243.0, 0.09, -0.02]),
    ]
    for name, w, h, fx, fy, cx, cy, k1, k2, _, p1, p2 in opencv_lenses():
        cases.append((f"OPENCV {name}", w, h, [fx, fy, cx, cy, k1, k2, p1, p2]))
    return cases


@pytest.mark.parametrize("case", gsplat_cases(), ids=lambda case: case[0])
def test_gsplats_pinhole_of_a_colmap_camera(tmp_path, case):
    label, w, h, params = case
    model = label.split()[0]
    folder = tmp_path / "sparse"
    colmap_text_model(folder, model, w, h, params)
    K, size = gsplat_undistort(model, params, (w, h))
    [(_, camera)] = splat.load_cameras(folder, undistort="gsplat")
    assert_camera(camera, K, size, label)


@pytest.mark.parametrize("lens", fisheye_lenses(), ids=lambda lens: lens[0])
def test_gsplats_ideal_fisheye_of_a_colmap_fisheye(tmp_path, lens):
    name, w, h, fx, fy, cx, cy, *k = lens
    folder = tmp_path / "sparse"
    colmap_text_model(folder, "OPENCV_FISHEYE", w, h, [fx, fy, cx, cy, *k])
    K, size, *_ = gsplat_fisheye(intrinsics(fx, fy, cx, cy), np.array(k, dtype=np.float32), (w, h))
    [(_, camera)] = splat.load_cameras(folder, undistort="gsplat")
    assert (camera.width, camera.height) == size, (camera, size)
    assert camera.lens == "fisheye" and not any(np.concatenate(list(camera.distortion.values()))), camera.distortion
    np.testing.assert_array_equal(camera.K, K.astype(np.float32), err_msg=name)
    # Control: the map about c, not about the image's middle, crops elsewhere.
    other, *_ = gsplat_fisheye(intrinsics(fx, fy, cx, cy), np.array(k, dtype=np.float32), (w, h), middle=False)
    assert not np.array_equal(other, K), name


def test_lenses_opencv_cannot_undistort_are_refused(tmp_path):
    path = tmp_path / "transforms.json"
    nerfstudio_file(path, "OPENCV", opencv_lenses()[0], {"k1": -0.1, "k4": 0.01})
    with pytest.raises(splat.SplatError, match="no r⁸ term"):
        splat.load_cameras(path, undistort="splatfacto")
    nerfstudio_file(path, "OPENCV_FISHEYE", fisheye_lenses()[0], {"k1": 0.05, "p1": 0.01})
    for trainer in ("splatfacto", "gsplat"):
        with pytest.raises(splat.SplatError, match="k1–k4 only"):
            splat.load_cameras(path, undistort=trainer)
    with pytest.raises(splat.SplatError, match="expected one of splatfacto, gsplat"):
        splat.load_cameras(path, undistort="3dgs")
    # Without distortion, every camera is its own pinhole.
    nerfstudio_file(path, "OPENCV", opencv_lenses()[0], {})
    [(_, plain)] = splat.load_cameras(path)
    [(_, same)] = splat.load_cameras(path, undistort="splatfacto")
    np.testing.assert_array_equal(same.K, plain.K)
