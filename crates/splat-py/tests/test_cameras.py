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


# What ns-process-data writes as applied_transform (colmap_utils.colmap_to_json), and what
# Nerfstudio assumes for a file without one beside colmap/sparse/0.
APPLIED = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0]]
LEGACY_APPLIED = [[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0]]


def nerfstudio_run(meta: dict, folder, orientation: np.ndarray, scale_factor: float):
    """Nerfstudio's dataparser on `meta` (nerfstudio_dataparser.py): the poses oriented by
    `orientation` (what auto_orient_and_center_poses returns) and their centres scaled, the
    dataparser_transforms.json it saves (save_dataparser_transform), and splatfacto's view
    matrices of the training poses."""
    poses = np.array([frame["transform_matrix"] for frame in meta["frames"]], dtype=np.float64)
    poses = orientation @ poses
    poses[:, :3, 3] *= scale_factor
    applied_transform = None
    if "applied_transform" in meta:
        applied_transform = np.array(meta["applied_transform"], dtype=np.float64)
    elif (folder / "colmap/sparse/0").exists():
        applied_transform = np.array(LEGACY_APPLIED, dtype=np.float64)
    if applied_transform is not None:
        dataparser_transform = orientation @ np.concatenate([applied_transform, [[0, 0, 0, 1]]], 0)
    else:
        dataparser_transform = orientation
    if "applied_scale" in meta:
        scale_factor *= float(meta["applied_scale"])
    saved = {"transform": dataparser_transform.tolist(), "scale": float(scale_factor)}
    expected = []
    for frame, pose in zip(meta["frames"], poses):
        K = np.array([[meta["fl_x"], 0, meta["cx"]], [0, meta["fl_y"], meta["cy"]], [0, 0, 1]])
        expected.append((frame["file_path"], splatfacto_viewmat(pose), K, (meta["w"], meta["h"])))
    return saved, expected


def test_a_nerfstudio_runs_dataparser_transforms_give_splatfactos_training_cameras(tmp_path):
    rng = np.random.default_rng(9)
    frames = [{"file_path": f"images/frame_{i:05}.jpg", "transform_matrix": random_c2w(rng).tolist()} for i in range(4)]
    base = {"w": 64, "h": 48, "fl_x": 50.0, "fl_y": 52.0, "cx": 31.5, "cy": 24.5, "frames": frames}
    cases = {
        "ns-process-data": {"applied_transform": APPLIED},
        "applied scale": {"applied_transform": APPLIED, "applied_scale": 2.5},
        "legacy": {},
        "none": {},
    }
    for case, extra in cases.items():
        folder = tmp_path / case.replace(" ", "-")
        (folder / "run").mkdir(parents=True)
        if case == "legacy":
            (folder / "colmap/sparse/0").mkdir(parents=True)
        meta = {**base, **extra}
        (folder / "transforms.json").write_text(json.dumps(meta))
        orientation = random_c2w(rng)[:3, :]
        saved, expected = nerfstudio_run(meta, folder, orientation, float(rng.uniform(0.05, 0.5)))
        (folder / "run/dataparser_transforms.json").write_text(json.dumps(saved))
        views = dict(splat.load_cameras(folder, dataparser_transforms=folder / "run/dataparser_transforms.json"))
        for name, viewmat, K, _ in expected:
            np.testing.assert_allclose(views[name].viewmat, viewmat, atol=TOLERANCE, err_msg=case)
            np.testing.assert_allclose(views[name].K, K, rtol=TOLERANCE, err_msg=case)

    (tmp_path / "cameras.json").write_text("[]")
    with pytest.raises(splat.SplatError, match="move a transforms.json's cameras"):
        splat.load_cameras(tmp_path / "cameras.json", dataparser_transforms=tmp_path / "none/run/dataparser_transforms.json")
