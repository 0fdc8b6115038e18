"""Shared fixtures of the Python package's tests: the `splat` binary the package is compared
with, random Gaussians in a trainer's raw parameters, and an independent 3DGS .ply writer."""

from __future__ import annotations

import os
import pathlib
import shutil
import struct

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def missing(what: str) -> None:
    """A test that cannot run fails under CI=true and says loudly that it skipped otherwise."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"{what} (CI=true: a test that cannot run fails)")
    print(f"\nSKIPPED LOUDLY: {what}")
    pytest.skip(what)


@pytest.fixture(scope="session")
def splat_bin() -> str:
    """The `splat` CLI of this checkout's release build (or $SPLAT_BIN)."""
    path = os.environ.get("SPLAT_BIN") or str(REPO / "target" / "release" / "splat")
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        found = shutil.which("splat")
        if found is None:
            missing(f"no splat binary at {path}: build it with `cargo build --release --bin splat`")
        path = found
    return path


def raw_gaussians(rng: np.random.Generator, n: int, degree: int = 1) -> dict:
    """`n` Gaussians in front of a camera at the origin looking down +z, as a trainer stores
    them: log scales, logit opacities, unnormalised w, x, y, z quaternions, SH (n, K, 3)."""
    k = (degree + 1) ** 2
    means = np.column_stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.9, 0.9, n), rng.uniform(3.0, 6.0, n)])
    sh = rng.normal(0.0, 0.4, (n, k, 3))
    sh[:, 0] = rng.uniform(-1.5, 1.5, (n, 3))
    return {
        "means": means.astype(np.float32),
        "scales": np.log(rng.uniform(0.08, 0.4, (n, 3))).astype(np.float32),
        "rotations": (rng.normal(size=(n, 4)) * rng.uniform(0.5, 2.0, (n, 1))).astype(np.float32),
        "opacities": rng.normal(0.0, 1.5, n).astype(np.float32),
        "sh": sh.astype(np.float32),
    }


def write_3dgs_ply(path: pathlib.Path, g: dict) -> None:
    """A binary little-endian .ply as the INRIA 3DGS code writes it: x y z nx ny nz, f_dc_0..2,
    f_rest_* channel-major (all red coefficients, then green, then blue), opacity (logit),
    scale_0..2 (log), rot_0..3 (w, x, y, z)."""
    n, k, _ = g["sh"].shape
    rest = g["sh"][:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (k - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    columns = [g["means"], np.zeros((n, 3)), g["sh"][:, 0, :], rest, g["opacities"][:, None], g["scales"], g["rotations"]]
    table = np.hstack(columns).astype("<f4")
    assert table.shape[1] == len(names)
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {name}\n" for name in names) + "end_header\n"
    path.write_bytes(header.encode() + table.tobytes())
    assert struct.calcsize("<f") * table.size == len(table.tobytes())


def nerfstudio_undistort_image(camera_type: str, distortion_params: np.ndarray, image: np.ndarray, K: np.ndarray):
    """Nerfstudio's `_undistort_image` (`nerfstudio/data/utils/dataloaders.py`), its perspective
    and fisheye branches for the image and K, as they are (masks and depths aside): returns
    the new K and the undistorted image. `distortion_params` in Nerfstudio's order, k1, k2, k3,
    k4, p1, p2."""
    import cv2

    if camera_type == "perspective":
        assert distortion_params[3] == 0
        distortion_params = np.array(
            [
                distortion_params[0],
                distortion_params[1],
                distortion_params[4],
                distortion_params[5],
                distortion_params[2],
                distortion_params[3],
                0,
                0,
            ]
        )
        K[0, 2] = K[0, 2] - 0.5
        K[1, 2] = K[1, 2] - 0.5
        if np.any(distortion_params):
            newK, roi = cv2.getOptimalNewCameraMatrix(K, distortion_params, (image.shape[1], image.shape[0]), 0)
            image = cv2.undistort(image, K, distortion_params, None, newK)
        else:
            newK = K
            roi = 0, 0, image.shape[1], image.shape[0]
        x, y, w, h = roi
        image = image[y : y + h, x : x + w]
        newK[0, 2] -= x
        newK[1, 2] -= y
    else:
        K[0, 2] = K[0, 2] - 0.5
        K[1, 2] = K[1, 2] - 0.5
        distortion_params = np.array(
            [distortion_params[0], distortion_params[1], distortion_params[2], distortion_params[3]]
        )
        size = (image.shape[1], image.shape[0])
        newK = cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(
            K, distortion_params, size, np.eye(3), balance=0
        )
        map1, map2 = cv2.fisheye.initUndistortRectifyMap(K, distortion_params, np.eye(3), newK, size, cv2.CV_32FC1)
        image = cv2.remap(image, map1, map2, interpolation=cv2.INTER_LINEAR)
    newK[0, 2] = newK[0, 2] + 0.5
    newK[1, 2] = newK[1, 2] + 0.5
    return newK, image


def gsplat_fisheye(K: np.ndarray, params: np.ndarray, size, middle: bool = True):
    """gsplat's COLMAP parser for an OPENCV_FISHEYE camera (`examples/datasets/colmap.py`, the
    fisheye branch of `Parser.__init__`), as it is: its map about the image's middle, the mask
    of where the map lands inside, the crop to the mask's box and K moved with it. `params` are
    k1–k4 as float32, as `_camera_distortion` keeps them. Returns (K_undist, (w, h), mapx, mapy,
    roi, mask), the mask cropped. `middle=False` maps about c instead: a control."""
    width, height = size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    grid_x, grid_y = np.meshgrid(
        np.arange(width, dtype=np.float32), np.arange(height, dtype=np.float32), indexing="xy"
    )
    x1 = (grid_x - cx) / fx
    y1 = (grid_y - cy) / fy
    theta = np.sqrt(x1**2 + y1**2)
    r = 1.0 + params[0] * theta**2 + params[1] * theta**4 + params[2] * theta**6 + params[3] * theta**8
    centre_x, centre_y = (width // 2, height // 2) if middle else (cx, cy)
    mapx = (fx * x1 * r + centre_x).astype(np.float32)
    mapy = (fy * y1 * r + centre_y).astype(np.float32)
    mask = np.logical_and(np.logical_and(mapx > 0, mapy > 0), np.logical_and(mapx < width - 1, mapy < height - 1))
    y_indices, x_indices = np.nonzero(mask)
    y_min, y_max = y_indices.min(), y_indices.max() + 1
    x_min, x_max = x_indices.min(), x_indices.max() + 1
    K_undist = K.copy()
    K_undist[0, 2] -= x_min
    K_undist[1, 2] -= y_min
    roi = (int(x_min), int(y_min), int(x_max - x_min), int(y_max - y_min))
    return K_undist, (roi[2], roi[3]), mapx, mapy, roi, mask[y_min:y_max, x_min:x_max]
