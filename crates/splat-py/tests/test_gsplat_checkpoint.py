"""gsplat's checkpoints (simple_trainer's ckpt_STEP_rankR.pt), read without PyTorch.

The files here are written as torch.save writes them (torch/serialization.py's `_save`,
PyTorch 2.x), without torch: a pickle at torch's default protocol 2 of gsplat's
{"step": step, "splats": splats.state_dict()}, in which each tensor is a call of
torch._utils._rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks) and each
storage the persistent id ("storage", torch.FloatStorage, key, location, numel); the storages'
little-endian bytes as ARCHIVE/data/KEY beside ARCHIVE/byteorder, ARCHIVE/version and
ARCHIVE/.data/serialization_id; in a Zip64 archive, as PyTorch's writer always makes one
(CPython's zipfile with its Zip64 limits at zero). The globals are stand-ins, which pickle
records by module and name as it records torch's own.

A checkpoint and the .ply of the same parameters (conftest's independent 3DGS writer, the
layout gsplat's export writes) must give the same splats value for value; what is not a
gsplat checkpoint is refused by name.
"""

from __future__ import annotations

import collections
import contextlib
import io
import pickle
import subprocess
import sys
import types
import zipfile

import numpy as np
import pytest

import splat
from conftest import raw_gaussians, write_3dgs_ply


@contextlib.contextmanager
def _torch_names():
    """Modules torch and torch._utils holding the names torch.save's pickle refers to."""
    saved = {name: sys.modules.get(name) for name in ("torch", "torch._utils")}
    torch = types.ModuleType("torch")
    utils = types.ModuleType("torch._utils")

    class FloatStorage:
        pass

    FloatStorage.__module__, FloatStorage.__qualname__ = "torch", "FloatStorage"

    def _rebuild_tensor_v2(*args):
        raise AssertionError("a stand-in: never called")

    _rebuild_tensor_v2.__module__, _rebuild_tensor_v2.__qualname__ = "torch._utils", "_rebuild_tensor_v2"
    torch.FloatStorage, torch._utils, utils._rebuild_tensor_v2 = FloatStorage, utils, _rebuild_tensor_v2
    sys.modules.update({"torch": torch, "torch._utils": utils})
    try:
        yield torch
    finally:
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module


class _Storage:
    """A storage: the elements of an array, in memory order."""

    def __init__(self, key: str, base: np.ndarray):
        self.key, self.base = key, np.ascontiguousarray(base, dtype="<f4")


class _Tensor:
    """A tensor viewing a storage as `view` (its shape and strides), pickled as torch pickles one."""

    def __init__(self, storage: _Storage, view: np.ndarray):
        self.storage, self.view = storage, view

    def __reduce_ex__(self, protocol):
        rebuild = sys.modules["torch._utils"]._rebuild_tensor_v2
        stride = tuple(s // 4 for s in self.view.strides)
        return rebuild, (self.storage, 0, tuple(self.view.shape), stride, False, collections.OrderedDict())


def torch_save(obj, path, storages: list[_Storage], archive: str = "ckpt_29999_rank0") -> None:
    """`obj` (with _Tensor leaves over `storages`) as torch.save writes it."""
    with _torch_names() as torch:

        class Pickler(pickle.Pickler):
            def persistent_id(self, o):
                if isinstance(o, _Storage):
                    return ("storage", torch.FloatStorage, o.key, "cuda:0", o.base.size)
                return None

        buffer = io.BytesIO()
        Pickler(buffer, protocol=2).dump(obj)
    limits = (zipfile.ZIP64_LIMIT, zipfile.ZIP_FILECOUNT_LIMIT)
    zipfile.ZIP64_LIMIT = zipfile.ZIP_FILECOUNT_LIMIT = 0
    try:
        with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
            z.writestr(f"{archive}/data.pkl", buffer.getvalue())
            z.writestr(f"{archive}/byteorder", "little")
            for s in storages:
                z.writestr(f"{archive}/data/{s.key}", s.base.tobytes())
            z.writestr(f"{archive}/version", "3\n")
            z.writestr(f"{archive}/.data/serialization_id", "1234567890")
    finally:
        zipfile.ZIP64_LIMIT, zipfile.ZIP_FILECOUNT_LIMIT = limits


def gsplat_parameters(g: dict) -> dict:
    """conftest's raw Gaussians as gsplat's splats (sh0 and shN apart)."""
    return {
        "means": g["means"],
        "scales": g["scales"],
        "quats": g["rotations"],
        "opacities": g["opacities"],
        "sh0": g["sh"][:, :1, :],
        "shN": g["sh"][:, 1:, :],
    }


def save_checkpoint(path, params: dict, step: int = 29999, views: dict | None = None) -> None:
    """gsplat's checkpoint of `params`: `views` replaces a tensor's view of its storage."""
    storages, state = [], collections.OrderedDict()
    for key, (name, array) in enumerate(params.items()):
        storage = _Storage(str(key), array)
        storages.append(storage)
        view = (views or {}).get(name, storage.base.reshape(array.shape))
        state[name] = _Tensor(storage, view)
    state._metadata = collections.OrderedDict([("", {"version": 1})])  # as nn.Module.state_dict
    torch_save({"step": step, "splats": state}, path, storages)


@pytest.mark.parametrize("degree", [0, 3])
def test_a_checkpoint_holds_what_its_ply_export_holds(tmp_path, splat_bin, degree):
    g = raw_gaussians(np.random.default_rng(11 + degree), 64, degree=degree)
    ckpt, ply = tmp_path / "ckpt_29999_rank0.pt", tmp_path / "export.ply"
    save_checkpoint(ckpt, gsplat_parameters(g))
    write_3dgs_ply(ply, g)
    from_ckpt, from_ply = splat.Scene.load(str(ckpt)), splat.Scene.load(str(ply))
    assert len(from_ckpt) == 64 and from_ckpt.sh_degree == degree
    a, b = from_ckpt.to_arrays(), from_ply.to_arrays()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    # And the activations themselves, in numpy: exp, the sigmoid, the normalised quaternion.
    np.testing.assert_allclose(a["scales"], np.exp(g["scales"].astype(np.float64)), rtol=1e-6)
    np.testing.assert_allclose(a["opacities"], 1 / (1 + np.exp(-g["opacities"].astype(np.float64))), rtol=1e-6)
    q = g["rotations"] / np.linalg.norm(g["rotations"], axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(np.sum(a["rotations"] * q, axis=1)), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(a["sh"], g["sh"])
    # The CLI: info names the step, and convert writes the checkpoint as the very file it writes
    # of the .ply export.
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert info.returncode == 0 and "gsplat checkpoint (step 29999)" in info.stdout, info
    for source in (ckpt, ply):
        done = subprocess.run([splat_bin, "convert", str(source), str(source) + ".out.ply"], capture_output=True)
        assert done.returncode == 0, done.stderr
    assert (tmp_path / f"{ckpt.name}.out.ply").read_bytes() == (tmp_path / f"{ply.name}.out.ply").read_bytes()


def test_what_is_not_a_gsplat_checkpoint_is_refused_by_name(tmp_path):
    g = gsplat_parameters(raw_gaussians(np.random.default_rng(5), 16, degree=1))

    def refused(path) -> str:
        with pytest.raises(splat.SplatError) as e:
            splat.Scene.load(str(path))
        return str(e.value)

    # A transposed view of the means (torch's .t() keeps the storage, swaps the strides).
    path = tmp_path / "strided.pt"
    transposed = g["means"].T.copy()
    save_checkpoint(path, {**g, "means": transposed}, views={"means": transposed.T})
    assert "not row-major" in refused(path)
    # Trained with --app_opt: features and colours for an appearance network, no sh0.
    path = tmp_path / "app.pt"
    app = {k: v for k, v in g.items() if k not in ("sh0", "shN")}
    app.update(features=np.zeros((16, 32), np.float32), colors=np.zeros((16, 3), np.float32))
    save_checkpoint(path, app)
    assert "app_opt" in refused(path)
    # A NaN opacity, named with its splat.
    path = tmp_path / "nan.pt"
    opacities = g["opacities"].copy()
    opacities[7] = np.nan
    save_checkpoint(path, {**g, "opacities": opacities})
    message = refused(path)
    assert "vertex 7" in message and "opacities" in message, message
    # Another shape than gsplat's.
    path = tmp_path / "shape.pt"
    save_checkpoint(path, {**g, "quats": g["quats"][:, :3].copy()})
    assert "\"quats\" has shape [16, 3], expected [16, 4]" in refused(path)
    # Not gsplat's (no splats), truncated, and not a zip archive (PyTorch's legacy format).
    path = tmp_path / "model.pt"
    torch_save({"model": 1, "optimizer": 2}, path, [])
    assert "no \"splats\"" in refused(path) and "model, optimizer" in refused(path)
    whole = tmp_path / "whole.pt"
    save_checkpoint(whole, g)
    cut = tmp_path / "cut.pt"
    cut.write_bytes(whole.read_bytes()[:-300])
    assert "zip" in refused(cut)
    legacy = tmp_path / "legacy.pt"
    legacy.write_bytes(pickle.dumps({"splats": 1}, protocol=2))
    assert "legacy format" in refused(legacy)


def test_damaged_checkpoints_are_refused_never_misread(tmp_path):
    """Every truncation of a small checkpoint is refused; every byte flipped in turn gives a file
    that is refused with a SplatError or, where the byte is one no reader needs (a time stamp,
    a version, the name of a record splat does not read, a header's copy of what the central
    directory says), reads as the same splats. No panic, no other splats. (cargo-fuzz runs the
    same reader over arbitrary bytes: fuzz/fuzz_targets/checkpoint.rs.)"""
    g = gsplat_parameters(raw_gaussians(np.random.default_rng(8), 2, degree=1))
    whole = tmp_path / "whole.pt"
    save_checkpoint(whole, g)
    data = whole.read_bytes()
    expected = splat.Scene.load(str(whole)).to_arrays()
    damaged = tmp_path / "damaged.pt"

    def load(variant: bytes):
        damaged.write_bytes(variant)
        try:
            return splat.Scene.load(str(damaged)).to_arrays()
        except splat.SplatError:
            return None

    for n in range(len(data)):
        assert load(data[:n]) is None, f"{n} of {len(data)} bytes read"
    refused = 0
    for i in range(len(data)):
        arrays = load(data[:i] + bytes([data[i] ^ 0xFF]) + data[i + 1 :])
        if arrays is None:
            refused += 1
            continue
        for name in expected:
            np.testing.assert_array_equal(arrays[name], expected[name], err_msg=f"byte {i} flipped: {name}")
    # Every byte of the pickle and of the storages is under a CRC-32.
    assert refused > 0.5 * len(data), f"{refused} of {len(data)} flips refused"
