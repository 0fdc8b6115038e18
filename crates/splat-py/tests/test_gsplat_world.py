"""gsplat's normalised world, against a port of gsplat's own parser.

gsplat's `simple_trainer` trains, by default (`normalize_world_space=True`), in the world its
COLMAP parser makes (`examples/datasets/colmap.py`, `Parser(normalize=True)`, with
`examples/datasets/normalize.py`):
- `similarity_from_cameras` of the camera poses;
- then `align_principal_axes` of the 3D points, read as float32;
- then a half turn about x where the points' median z is above their mean z.

`splat.load_cameras(sparse, gsplat_world=scene)` moves a COLMAP model's cameras into that
world, so that the trainer's exported splats render as gsplat renders them. The port below
does the eigendecomposition with numpy, as gsplat does. numpy's eigenvector signs then decide
between the two frames splat can only tell apart by where the 3D points lie on the splats.

Each capture is checked in both frames: splats where gsplat puts the points, and splats a half
turn about z from there (the frame the other eigenvector signs give). The splats are the points
themselves, and a set made to look trained: half the points pruned, the rest cloned 5 times
with a jitter of σ = 0.02 (the median camera is 1 away). Every camera must equal
gsplat's within 1e-6, rotation and translation, in a world where the median camera is 1 from
the centre (the float32 cameras differ by 3e-8 and 6e-8). The first capture takes the half turn
about x (its median z is above its mean z); the others do not.

Controls (asserted): gsplat's normalisation with its scale 1 % off (translations 0.012–0.014
off), with its `strict_scaling`, and with `center_method="poses"` each miss by more than 1e-3.
The tolerance would catch a scale off by about 1e-6.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import splat


def similarity_from_cameras(c2w: np.ndarray, strict_scaling: bool = False, center_method: str = "focus") -> np.ndarray:
    """gsplat's `similarity_from_cameras` (normalize.py)."""
    t = c2w[:, :3, 3]
    R = c2w[:, :3, :3]
    ups = np.sum(R * np.array([0, -1.0, 0]), axis=-1)
    world_up = np.mean(ups, axis=0)
    world_up /= np.linalg.norm(world_up)
    up_camspace = np.array([0.0, -1.0, 0.0])
    c = (up_camspace * world_up).sum()
    cross = np.cross(world_up, up_camspace)
    skew = np.array([[0.0, -cross[2], cross[1]], [cross[2], 0.0, -cross[0]], [-cross[1], cross[0], 0.0]])
    if c > -1:
        R_align = np.eye(3) + skew + (skew @ skew) * 1 / (1 + c)
    else:
        R_align = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    R = R_align @ R
    fwds = np.sum(R * np.array([0, 0.0, 1.0]), axis=-1)
    t = (R_align @ t[..., None])[..., 0]
    if center_method == "focus":
        nearest = t + (fwds * -t).sum(-1)[:, None] * fwds
        translate = -np.median(nearest, axis=0)
    else:
        translate = -np.median(t, axis=0)
    transform = np.eye(4)
    transform[:3, 3] = translate
    transform[:3, :3] = R_align
    scale_fn = np.max if strict_scaling else np.median
    scale = 1.0 / scale_fn(np.linalg.norm(t + translate, axis=-1))
    transform[:3, :] *= scale
    return transform


def align_principal_axes(point_cloud: np.ndarray) -> np.ndarray:
    """gsplat's `align_principal_axes` (normalize.py)."""
    centroid = np.median(point_cloud, axis=0)
    covariance_matrix = np.cov(point_cloud - centroid, rowvar=False)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance_matrix)
    eigenvectors = eigenvectors[:, eigenvalues.argsort()[::-1]]
    if np.linalg.det(eigenvectors) < 0:
        eigenvectors[:, 0] *= -1
    transform = np.eye(4)
    transform[:3, :3] = eigenvectors.T
    transform[:3, 3] = -eigenvectors.T @ centroid
    return transform


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def transform_cameras(matrix: np.ndarray, camtoworlds: np.ndarray) -> np.ndarray:
    camtoworlds = np.einsum("nij, ki -> nkj", camtoworlds, matrix)
    scaling = np.linalg.norm(camtoworlds[:, 0, :3], axis=1)
    camtoworlds[:, :3, :3] = camtoworlds[:, :3, :3] / scaling[:, None, None]
    return camtoworlds


def gsplat_normalize(camtoworlds: np.ndarray, points: np.ndarray, scale_error: float = 0.0, **similarity) -> tuple:
    """The normalising branch of gsplat's `Parser`: (camtoworlds, points, transform)."""
    T1 = similarity_from_cameras(camtoworlds, **similarity)
    T1[:3, :] *= 1.0 + scale_error
    camtoworlds = transform_cameras(T1, camtoworlds)
    points = transform_points(T1, points)
    T2 = align_principal_axes(points)
    camtoworlds = transform_cameras(T2, camtoworlds)
    points = transform_points(T2, points)
    transform = T2 @ T1
    if np.median(points[:, 2]) > np.mean(points[:, 2]):
        T3 = np.diag([1.0, -1.0, -1.0, 1.0])
        camtoworlds = transform_cameras(T3, camtoworlds)
        points = transform_points(T3, points)
        transform = T3 @ transform
    return camtoworlds, points, transform


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation of a unit quaternion (w, x, y, z), as COLMAP's readers build it."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quaternion(r: np.ndarray) -> np.ndarray:
    """A unit quaternion (w, x, y, z) of the rotation `r`, from its largest component
    (Shepperd's method)."""
    trace = np.trace(r)
    candidates = [1 + trace, 1 + 2 * r[0, 0] - trace, 1 + 2 * r[1, 1] - trace, 1 + 2 * r[2, 2] - trace]
    k = int(np.argmax(candidates))
    s = 2 * np.sqrt(candidates[k])
    if k == 0:
        q = [s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif k == 1:
        q = [(r[2, 1] - r[1, 2]) / s, s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif k == 2:
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s]
    else:
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4]
    return np.array(q)


def capture(rng: np.random.Generator, folder: Path, camera: str = "PINHOLE 64 48 60 60 32 24") -> tuple:
    """A COLMAP text model in `folder`: 30 cameras around a lopsided scene (a ground patch, a
    box off its centre), the whole turned, moved and scaled at random; returns gsplat's
    camtoworlds (from the quaternions as written) and its float32 points."""
    ground = np.column_stack([rng.uniform(-2, 2, 3000), np.ones(3000), rng.uniform(-1.2, 1.2, 3000)])
    box = np.array([0.5, 0.1, 0.2]) + rng.uniform(0, 0.8, (2500, 3))
    local = np.vstack([ground, box]) + rng.normal(0, 0.01, (5500, 3))
    turn = quaternion_matrix(rng.normal(size=4))
    shift, size = rng.normal(0, 3, 3), rng.uniform(0.3, 5.0)
    points = size * local @ turn.T + shift
    lines, c2ws = [], []
    for i in range(30):
        angle = 2 * np.pi * i / 30 + rng.uniform(-0.05, 0.05)
        eye = np.array([3.5 * np.cos(angle), rng.uniform(-2.0, -1.0), 3.5 * np.sin(angle)])
        forward = -eye / np.linalg.norm(eye)
        right = np.cross([0, 1, 0], forward)
        right /= np.linalg.norm(right)
        c2w_local = np.column_stack([right, np.cross(forward, right), forward])
        q = matrix_quaternion((turn @ c2w_local).T)
        R = quaternion_matrix(q)  # world-to-camera, as the model's readers rebuild it
        centre = size * turn @ eye + shift
        t = -R @ centre
        numbers = " ".join(repr(float(v)) for v in [*q, *t])
        lines.append(f"{i + 1} {numbers} 1 view_{i:02d}.png\n\n")
        c2w = np.eye(4)
        c2w[:3, :3], c2w[:3, 3] = R.T, -R.T @ t
        c2ws.append(c2w)
    folder.mkdir(parents=True)
    (folder / "cameras.txt").write_text(f"1 {camera}\n")
    (folder / "images.txt").write_text("".join(lines))
    rows = [f"{k + 1} {float(x)!r} {float(y)!r} {float(z)!r} 128 128 128 0.5\n" for k, (x, y, z) in enumerate(points)]
    (folder / "points3D.txt").write_text("".join(rows))
    return np.stack(c2ws), points.astype(np.float32)


def splats_at(means: np.ndarray) -> splat.Scene:
    n = len(means)
    return splat.Scene.from_arrays(
        means=np.ascontiguousarray(means, dtype=np.float32),
        scales=np.full((n, 3), 0.005, np.float32),
        rotations=np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1)),
        opacities=np.full(n, 0.5, np.float32),
        sh=np.zeros((n, 1, 3), np.float32),
        log_scales=False,
        logit_opacities=False,
    )


def worst(views: list, camtoworlds: np.ndarray) -> tuple[float, float]:
    """The largest rotation and translation differences between `views` and gsplat's cameras."""
    viewmats = np.stack([np.asarray(camera.viewmat, np.float64) for _, camera in views])
    expected = np.linalg.inv(camtoworlds)
    return (
        float(np.abs(viewmats[:, :3, :3] - expected[:, :3, :3]).max()),
        float(np.abs(viewmats[:, :3, 3] - expected[:, :3, 3]).max()),
    )


HALF_TURN = np.diag([-1.0, -1.0, 1.0, 1.0])


@pytest.mark.parametrize("seed", range(4))
def test_cameras_move_into_gsplats_world_in_either_frame(tmp_path, seed):
    rng = np.random.default_rng(seed)
    sparse = tmp_path / "sparse" / "0"
    c2ws, points = capture(rng, sparse)
    camtoworlds, normalised, _ = gsplat_normalize(c2ws, points)
    jitter = rng.normal(0, 1e-4, normalised.shape)
    kept = np.repeat(normalised[rng.random(len(normalised)) < 0.5], 5, axis=0)
    trained = kept + rng.normal(0, 0.02, kept.shape)
    for means in [normalised + jitter, trained]:
        for frame in [np.eye(4), HALF_TURN]:
            views = splat.load_cameras(sparse, gsplat_world=splats_at(transform_points(frame, means)))
            assert [name for name, _ in views] == [f"view_{i:02d}.png" for i in range(30)]
            rotation, translation = worst(views, transform_cameras(frame, camtoworlds.copy()))
            assert rotation < 1e-6 and translation < 1e-6, (rotation, translation)
    splats = splats_at(normalised + jitter)
    views = splat.load_cameras(sparse, gsplat_world=splats)
    for control in [{"scale_error": 0.01}, {"strict_scaling": True}, {"center_method": "poses"}]:
        rotation, translation = worst(views, gsplat_normalize(c2ws, points, **control)[0])
        assert translation > 1e-3, (control, translation)


def test_gsplats_parser_transform_given_as_the_world_transform(tmp_path):
    """gsplat's `parser.transform` itself, as an array, as numpy.save and numpy.savetxt write it,
    moves the cameras where gsplat's parser moves them (both frames: no splats are needed), from
    the COLMAP model and from a cameras.json of its views; a matrix 1 % off in scale (a
    control) misses; a matrix that is no similarity is refused."""
    rng = np.random.default_rng(5)
    sparse = tmp_path / "sparse" / "0"
    c2ws, points = capture(rng, sparse)
    camtoworlds, _, transform = gsplat_normalize(c2ws, points)
    entries = [
        {"id": i, "img_name": f"view_{i:02d}", "width": 64, "height": 48, "fx": 60.0, "fy": 60.0,
         "position": c2w[:3, 3].tolist(), "rotation": c2w[:3, :3].tolist()}
        for i, c2w in enumerate(c2ws)
    ]
    as_json = tmp_path / "cameras.json"
    as_json.write_text(json.dumps(entries))
    for k, frame in enumerate([np.eye(4), HALF_TURN]):
        given = frame @ transform
        expected = transform_cameras(frame, camtoworlds.copy())
        np.save(tmp_path / f"given{k}.npy", given)
        np.savetxt(tmp_path / f"given{k}.txt", given)
        for world in [given, tmp_path / f"given{k}.npy", str(tmp_path / f"given{k}.txt")]:
            rotation, translation = worst(splat.load_cameras(sparse, world_transform=world), expected)
            assert rotation < 1e-6 and translation < 1e-6, (world, rotation, translation)
        rotation, translation = worst(splat.load_cameras(as_json, world_transform=given), expected)
        assert rotation < 1e-5 and translation < 1e-5, (rotation, translation)
    off = transform.copy()
    off[:3, :] *= 1.01
    _, translation = worst(splat.load_cameras(sparse, world_transform=off), camtoworlds)
    assert translation > 1e-3, translation
    sheared = transform.copy()
    sheared[0, :3] += 0.1 * sheared[1, :3]  # a shear: the determinant stays
    with pytest.raises(splat.SplatError, match="not a rotation times one scale"):
        splat.load_cameras(sparse, world_transform=sheared)
    with pytest.raises(splat.SplatError, match=r"shape \(3, 3\)"):
        splat.load_cameras(sparse, world_transform=np.eye(3))
    with pytest.raises(splat.SplatError, match="moves the cameras by itself"):
        splat.load_cameras(sparse, world_transform=transform, gsplat_world=splats_at(points))


def test_splats_outside_gsplats_world_and_other_camera_files_are_refused(tmp_path):
    rng = np.random.default_rng(9)
    sparse = tmp_path / "sparse" / "0"
    _, points = capture(rng, sparse)
    with pytest.raises(splat.SplatError, match="the splats lie in the COLMAP model's own world"):
        splat.load_cameras(sparse, gsplat_world=splats_at(points))
    transforms = tmp_path / "transforms.json"
    transforms.write_text('{"fl_x": 60, "fl_y": 60, "cx": 32, "cy": 24, "w": 64, "h": 48, "frames": []}')
    with pytest.raises(splat.SplatError, match="gsplat normalises the world of a COLMAP model"):
        splat.load_cameras(transforms, gsplat_world=splats_at(points))
    (sparse / "points3D.txt").unlink()
    with pytest.raises(splat.SplatError, match="points3D.txt"):
        splat.load_cameras(sparse, gsplat_world=splats_at(points))


def test_gsplats_evaluation_cameras_with_every_option(tmp_path):
    """gsplat's test views of a distorted capture read from images_2/: its parser's K / 2 with the
    sides floored, OpenCV's pinhole of that (cropped, c kept), the normalised world of all views,
    then every 8th view by name (`test_every` 8)."""
    import cv2

    rng = np.random.default_rng(4)
    sparse = tmp_path / "sparse" / "0"
    fx, fy, cx, cy, k1, k2, p1, p2 = 60.0, 61.0, 33.25, 23.5, -0.12, 0.02, 0.001, -0.002
    c2ws, points = capture(rng, sparse, f"OPENCV 65 49 {fx} {fy} {cx} {cy} {k1} {k2} {p1} {p2}")
    camtoworlds, normalised, _ = gsplat_normalize(c2ws, points)
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    K[:2, :] /= 2
    size = (65 // 2, 49 // 2)
    params = np.array([k1, k2, p1, p2], dtype=np.float32)
    K_undist, roi = cv2.getOptimalNewCameraMatrix(K, params, size, 0)
    options = {"split": "3dgs-test", "data_factor": 2, "image_size": size, "undistort": "gsplat"}
    views = splat.load_cameras(sparse, gsplat_world=splats_at(normalised), **options)
    assert [name for name, _ in views] == [f"view_{i:02d}.png" for i in range(0, 30, 8)]
    rotation, translation = worst(views, camtoworlds[::8])
    assert rotation < 1e-6 and translation < 1e-6, (rotation, translation)
    # Control: the world of the test views alone is another.
    assert worst(views, gsplat_normalize(c2ws[::8], points)[0])[1] > 1e-3
    for _, camera in views:
        assert (camera.width, camera.height) == (roi[2], roi[3])
        np.testing.assert_allclose(camera.K, K_undist, rtol=0, atol=1e-3)
