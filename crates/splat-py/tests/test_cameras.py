"""transforms.json cameras read as the trainers that write and read them do.

Each test ports the reference trainer's own code path, independently of the Rust reader:
3DGS's NeRF-synthetic reader (`scene/dataset_readers.py` `readCamerasFromTransforms`,
`utils/graphics_utils.py` `getWorld2View2`, `fov2focal`, `focal2fov`) and Nerfstudio's
(`nerfstudio_dataparser.py`'s intrinsics, `splatfacto.py`'s `get_viewmat`), and compares
their world-to-camera matrices and intrinsics with `splat.load_cameras`'.
"""

from __future__ import annotations

import json
import math
import struct
import zlib

import numpy as np
import pytest
import splat

# f32 storage of the camera (rotation, translation, intrinsics) against the ports' f64.
TOLERANCE = 2e-5


def random_c2w(rng: np.random.Generator) -> np.ndarray:
    """A camera-to-world matrix (OpenGL axes) of a random rotation and centre."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    c2w = np.eye(4)
    c2w[:3, :3] = q
    c2w[:3, 3] = rng.uniform(-5, 5, size=3)
    return c2w


def write_png(path, width: int, height: int) -> None:
    """A black RGB PNG, written by hand (signature, IHDR, IDAT, IEND)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = b"".join(b"\x00" + bytes(3 * width) for _ in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")
    )


# 3DGS's graphics_utils.
def fov2focal(fov, pixels):
    return pixels / (2 * math.tan(fov / 2))


def focal2fov(focal, pixels):
    return 2 * math.atan(pixels / (2 * focal))


def getWorld2View2(R, t):
    Rt = np.zeros((4, 4))
    Rt[:3, :3] = R.transpose()
    Rt[:3, 3] = t
    Rt[3, 3] = 1.0
    return Rt


def gaussian_splatting_blender(contents: dict, sizes: list[tuple[int, int]]):
    """3DGS's readCamerasFromTransforms, then the view matrix and focal lengths it renders with."""
    fovx = contents["camera_angle_x"]
    out = []
    for idx, frame in enumerate(contents["frames"]):
        c2w = np.array(frame["transform_matrix"])
        c2w[:3, 1:3] *= -1
        w2c = np.linalg.inv(c2w)
        R = np.transpose(w2c[:3, :3])
        T = w2c[:3, 3]
        width, height = sizes[idx]
        fovy = focal2fov(fov2focal(fovx, width), height)
        K = np.array([[fov2focal(fovx, width), 0, width / 2], [0, fov2focal(fovy, height), height / 2], [0, 0, 1]])
        out.append((frame["file_path"], getWorld2View2(R, T), K, (width, height)))
    return out


def splatfacto_viewmat(c2w: np.ndarray) -> np.ndarray:
    """splatfacto's get_viewmat, in numpy."""
    R = c2w[:3, :3]
    T = c2w[:3, 3:4]
    R = R * np.array([[1, -1, -1]])
    R_inv = R.T
    T_inv = -R_inv @ T
    viewmat = np.zeros((4, 4))
    viewmat[3, 3] = 1.0
    viewmat[:3, :3] = R_inv
    viewmat[:3, 3:4] = T_inv
    return viewmat


def nerfstudio(meta: dict):
    """Nerfstudio's dataparser (intrinsics at the top level, else the frame's), without its
    orientation and scale normalisation, then splatfacto's view matrix."""
    out = []
    for frame in meta["frames"]:
        key = lambda name: meta[name] if name in meta else frame[name]  # noqa: E731
        K = np.array([[key("fl_x"), 0, key("cx")], [0, key("fl_y"), key("cy")], [0, 0, 1]])
        c2w = np.array(frame["transform_matrix"], dtype=np.float64)[:3, :4]
        out.append((frame["file_path"], splatfacto_viewmat(c2w), K, (int(key("w")), int(key("h")))))
    return out


def assert_same_views(path, expected) -> None:
    views = dict(splat.load_cameras(path))
    assert list(views) == [name for name, *_ in expected]
    for name, viewmat, K, size in expected:
        camera = views[name]
        assert (camera.width, camera.height) == size, name
        np.testing.assert_allclose(camera.viewmat, viewmat, atol=TOLERANCE * max(1, np.abs(viewmat).max()))
        np.testing.assert_allclose(camera.K, K, rtol=TOLERANCE)


def test_nerf_synthetic_frames_are_3dgs_cameras(tmp_path):
    rng = np.random.default_rng(7)
    (tmp_path / "train").mkdir()
    sizes = [(40, 30), (32, 32), (24, 36)]
    frames = []
    for i, (width, height) in enumerate(sizes):
        write_png(tmp_path / "train" / f"r_{i}.png", width, height)
        frames.append({"file_path": f"./train/r_{i}", "rotation": 0.012, "transform_matrix": random_c2w(rng).tolist()})
    contents = {"camera_angle_x": 0.6911112070083618, "frames": frames}
    (tmp_path / "transforms_train.json").write_text(json.dumps(contents))
    assert_same_views(tmp_path / "transforms_train.json", gaussian_splatting_blender(contents, sizes))


def test_nerfstudio_frames_are_splatfacto_cameras(tmp_path):
    rng = np.random.default_rng(8)
    frames = [{"file_path": f"images/frame_{i:05}.jpg", "transform_matrix": random_c2w(rng).tolist()} for i in range(3)]
    for i, frame in enumerate(frames):
        frame.update({"fl_x": 300.0 + i, "fl_y": 310.0 - i, "cx": 160.5 + i, "cy": 119.25})
    meta = {"w": 320, "h": 240, "camera_model": "OPENCV", "frames": frames}
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    # A folder holding transforms.json is read as the file.
    assert_same_views(tmp_path, nerfstudio(meta))
    assert all(camera.is_pinhole for _, camera in splat.load_cameras(tmp_path))

    # ns-process-data's layout: the intrinsics once, at the top level, with a distortion.
    for frame in frames:
        for key in ("fl_x", "fl_y", "cx", "cy"):
            del frame[key]
    meta.update({"fl_x": 250.0, "fl_y": 250.0, "cx": 150.0, "cy": 110.0, "k1": -0.05, "p2": 0.001})
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    assert_same_views(tmp_path / "transforms.json", nerfstudio(meta))
    assert not any(camera.is_pinhole for _, camera in splat.load_cameras(tmp_path))

    # A key in both places that differs is read one way by Nerfstudio (the file's) and another
    # by Brush (the frame's): refused.
    frames[1]["fl_x"] = 260.0
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(splat.SplatError, match="fl_x 260.0 differs from the file's 250.0"):
        splat.load_cameras(tmp_path)
