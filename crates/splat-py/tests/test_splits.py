"""A trainer's split of a capture's views, against ports of the trainers' own code.

`splat.load_cameras(path, split=...)` keeps the views a trainer trains on or holds out, in its
order. The ports: 3DGS's `readColmapSceneInfo` with `--eval` (sorted COLMAP names, llffhold 8;
gsplat's `test_every` 8 holds out the same) and Nerfstudio's `nerfstudio-data` dataparser
(frames sorted by path, `get_train_eval_split_fraction` with its default 0.9, or the file's
own `train_filenames` and `test_filenames`).

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


def nerfstudio_listed_split(file_paths: list[str], data_dir: Path, meta: dict, split: str) -> list[str]:
    """Nerfstudio's dataparser for a file that names its own split lists: frames sorted by
    `data_dir / file_path`, those whose path `{split}_filenames` names; its RuntimeErrors."""
    fnames = [data_dir / Path(p) for p in file_paths]
    inds = np.argsort(fnames)
    image_filenames = [fnames[i] for i in inds]
    has_split_files_spec = any(f"{split}_filenames" in meta for split in ("train", "val", "test"))
    if f"{split}_filenames" in meta:
        split_filenames = set(data_dir / Path(x) for x in meta[f"{split}_filenames"])
        unmatched_filenames = split_filenames.difference(image_filenames)
        if unmatched_filenames:
            raise RuntimeError(f"Some filenames for split {split} were not found: {unmatched_filenames}.")
        indices = [i for i, path in enumerate(image_filenames) if path in split_filenames]
    elif has_split_files_spec:
        raise RuntimeError(f"The dataset's list of filenames for split {split} is missing.")
    return [file_paths[inds[i]] for i in indices]


def test_a_files_own_split_lists_are_nerfstudios_splits(tmp_path):
    rng = np.random.default_rng(7)
    paths = [f"./images/frame_{k:05d}.png" for k in rng.permutation(20)]
    path = tmp_path / "transforms.json"
    transforms_file(path, paths)
    meta = json.loads(path.read_text())
    # The lists spell some paths without "./", as paths compare by their parts.
    shuffled = [p if k % 2 else p[2:] for k, p in enumerate(rng.permutation(paths))]
    meta["train_filenames"], meta["val_filenames"], meta["test_filenames"] = shuffled[:13], shuffled[13:16], shuffled[16:]
    path.write_text(json.dumps(meta))
    for ours, theirs in [("nerfstudio-train", "train"), ("nerfstudio-eval", "test")]:
        names = [name for name, _ in splat.load_cameras(path, split=ours)]
        assert names == nerfstudio_listed_split(paths, tmp_path, meta, theirs), ours
    # 3DGS has no split lists: its llff hold splits the same file.
    assert len(splat.load_cameras(path, split="3dgs-test")) == 3
    # A missing list, and a listed path no frame has, are refused as Nerfstudio refuses them.
    del meta["test_filenames"]
    path.write_text(json.dumps(meta))
    with pytest.raises(RuntimeError, match="split test is missing"):
        nerfstudio_listed_split(paths, tmp_path, meta, "test")
    with pytest.raises(splat.SplatError, match="not test_filenames"):
        splat.load_cameras(path, split="nerfstudio-eval")
    meta["train_filenames"].append("images/elsewhere.png")
    path.write_text(json.dumps(meta))
    with pytest.raises(RuntimeError, match="were not found"):
        nerfstudio_listed_split(paths, tmp_path, meta, "train")
    with pytest.raises(splat.SplatError, match="train_filenames names 1 path.s. no frame has, such as images/elsewhere.png"):
        splat.load_cameras(path, split="nerfstudio-train")


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
