"""A trainer's split of a capture's views, against ports of the trainers' own code.

`splat.load_cameras(path, split=...)` keeps the views a trainer trains on or holds out, in its
order. The ports: 3DGS's `readColmapSceneInfo` with `--eval` (sorted COLMAP names, llffhold 8;
gsplat's `test_every` 8 holds out the same) and Nerfstudio's `nerfstudio-data` dataparser
(frames sorted by path, `get_train_eval_split_fraction` with its default 0.9).

Control, run by hand: a fraction split whose training indices are rounded instead of
floored by `numpy.linspace(..., dtype=int)` fails the 10-, 11-, 37- and 123-view files.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import splat


def nerfstudio_split(file_paths: list[str], data_dir: Path, split: str) -> list[str]:
    """Nerfstudio's dataparser: frames sorted by `data_dir / file_path`, then
    `get_train_eval_split_fraction(image_filenames, 0.9)`."""
    fnames = [data_dir / Path(p) for p in file_paths]
    inds = np.argsort(fnames)
    ordered = [file_paths[i] for i in inds]
    num_images = len(ordered)
    num_train_images = math.ceil(num_images * 0.9)
    i_all = np.arange(num_images)
    i_train = np.linspace(0, num_images - 1, num_train_images, dtype=int)
    i_eval = np.setdiff1d(i_all, i_train)
    indices = i_train if split == "train" else i_eval
    return [ordered[i] for i in indices]


def gaussian_splatting_split(names: list[str], split: str) -> list[str]:
    """3DGS's llffhold 8 over the sorted names."""
    cam_names = sorted(names)
    return [n for idx, n in enumerate(cam_names) if (idx % 8 == 0) == (split == "test")]


def transforms_file(path: Path, file_paths: list[str]) -> None:
    frames = [{"file_path": p, "transform_matrix": np.eye(4).tolist()} for p in file_paths]
    meta = {"fl_x": 100.0, "fl_y": 100.0, "cx": 32.0, "cy": 24.0, "w": 64, "h": 48, "frames": frames}
    path.write_text(json.dumps(meta))


@pytest.mark.parametrize("n", [2, 10, 11, 37, 123])
def test_nerfstudio_splits_are_its_dataparsers(tmp_path, n):
    rng = np.random.default_rng(n)
    paths = [f"./images/frame_{k:05d}.png" for k in rng.permutation(n)]
    paths[0] = "images/frame_99999.jpg"  # a path without "./" sorts by its parts
    path = tmp_path / "transforms.json"
    transforms_file(path, paths)
    for ours, theirs in [("nerfstudio-train", "train"), ("nerfstudio-eval", "eval")]:
        expected = nerfstudio_split(paths, tmp_path, theirs)
        if not expected:
            with pytest.raises(splat.SplatError, match="is empty"):
                splat.load_cameras(path, split=ours)
            continue
        names = [name for name, _ in splat.load_cameras(path, split=ours)]
        assert names == expected, (n, ours)


def test_a_file_that_names_its_own_split_is_refused_nerfstudios(tmp_path):
    path = tmp_path / "transforms.json"
    transforms_file(path, [f"images/{k}.png" for k in range(12)])
    meta = json.loads(path.read_text())
    meta["train_filenames"], meta["test_filenames"] = ["images/0.png"], ["images/1.png"]
    path.write_text(json.dumps(meta))
    with pytest.raises(splat.SplatError, match="names its own split .train_filenames, test_filenames."):
        splat.load_cameras(path, split="nerfstudio-eval")
    assert len(splat.load_cameras(path, split="3dgs-test")) == 2


@pytest.mark.parametrize("n", [1, 8, 9, 30])
def test_3dgs_splits_are_its_llff_hold(tmp_path, n):
    rng = np.random.default_rng(n)
    names = [f"IMG_{k:04d}.JPG" for k in rng.permutation(n)]
    folder = tmp_path / "sparse"
    folder.mkdir()
    (folder / "cameras.txt").write_text("1 PINHOLE 64 48 100 100 32 24\n")
    images = "".join(f"{i + 1} 1 0 0 0 0 0 0 1 {name}\n\n" for i, name in enumerate(names))
    (folder / "images.txt").write_text(images)
    for ours, theirs in [("3dgs-test", "test"), ("3dgs-train", "train")]:
        expected = gaussian_splatting_split(names, theirs)
        if not expected:
            with pytest.raises(splat.SplatError, match="is empty"):
                splat.load_cameras(folder, split=ours)
            continue
        assert [name for name, _ in splat.load_cameras(folder, split=ours)] == expected, (n, ours)
    with pytest.raises(splat.SplatError, match="expected one of 3dgs-test"):
        splat.load_cameras(folder, split="test")
