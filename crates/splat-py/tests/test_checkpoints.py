"""Trainers' checkpoints, read without PyTorch: gsplat's (simple_trainer's ckpt_STEP_rankR.pt),
Nerfstudio's of a splatfacto model (nerfstudio_models/step-STEP.ckpt), 3DGRUT's (ckpt_last.pt,
with its OmegaConf config, pickled here by OmegaConf itself) and 3DGS's (chkpnt30000.pth).

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
layout 3DGS's save_ply, gsplat's export, Nerfstudio's ns-export gaussian-splat and 3DGRUT's
PLYExporter write)
must give the same splats value for value; what is not such a checkpoint is refused by name.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import io
import pickle
import struct
import subprocess
import sys
import types
import warnings
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

    def _rebuild_parameter(*args):
        raise AssertionError("a stand-in: never called")

    for f in (_rebuild_tensor_v2, _rebuild_parameter):
        f.__module__, f.__qualname__ = "torch._utils", f.__name__
        setattr(utils, f.__name__, f)
    torch.FloatStorage, torch._utils = FloatStorage, utils
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
        offset = (self.view.__array_interface__["data"][0] - self.storage.base.__array_interface__["data"][0]) // 4
        return rebuild, (self.storage, offset, tuple(self.view.shape), stride, False, collections.OrderedDict())


class _Parameter:
    """An nn.Parameter of a tensor, pickled as torch pickles one."""

    def __init__(self, tensor: _Tensor):
        self.tensor = tensor

    def __reduce_ex__(self, protocol):
        rebuild = sys.modules["torch._utils"]._rebuild_parameter
        return rebuild, (self.tensor, True, collections.OrderedDict())


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


def refused(path) -> str:
    """The message splat refuses the scene at `path` with."""
    with pytest.raises(splat.SplatError) as e:
        splat.Scene.load(str(path))
    return str(e.value)


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


def state_dict(params: dict, storages: list[_Storage], views: dict | None = None) -> collections.OrderedDict:
    """An nn.Module's state_dict of `params`, each array a tensor over a new storage appended to
    `storages`: `views` replaces a tensor's view of its storage."""
    state = collections.OrderedDict()
    for name, array in params.items():
        storage = _Storage(str(len(storages)), array)
        storages.append(storage)
        state[name] = _Tensor(storage, (views or {}).get(name, storage.base.reshape(array.shape)))
    state._metadata = collections.OrderedDict([("", {"version": 1})])  # as nn.Module.state_dict
    return state


def with_a_near_splat(g: dict) -> dict:
    """`g` and one small opaque splat 0.1 in front of the camera of `near_camera`: gsplat's
    rasterizer draws it (its near plane is 0.01), the INRIA rasterizer culls it (0.2)."""
    near = {
        "means": np.array([[0.0, 0.0, 0.1]], np.float32),
        "scales": np.log(np.full((1, 3), 0.002, np.float32)),
        "rotations": np.array([[1.0, 0.0, 0.0, 0.0]], np.float32),
        "opacities": np.array([3.0], np.float32),
        "sh": np.full((1, *g["sh"].shape[1:]), 0.8, np.float32),
    }
    return {k: np.concatenate([v, near[k]]) for k, v in g.items()}


#: The camera the splats of `raw_gaussians` and `with_a_near_splat` are rendered from.
def near_camera():
    return splat.Camera.look_at((0, 0, 0), (0, 0, 4.5), up=(0, -1, 0), fov_y=45, width=48, height=36)


def save_checkpoint(path, params: dict, step: int = 29999, views: dict | None = None) -> None:
    """gsplat's checkpoint of `params`: `views` replaces a tensor's view of its storage."""
    storages = []
    torch_save({"step": step, "splats": state_dict(params, storages, views)}, path, storages)


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


def test_a_checkpoint_of_several_blocks_reads_whole(tmp_path):
    """The reader reads a checkpoint's storages 65,536 splats at a time (splat_io::torch's
    BLOCK), and every byte of each storage for its CRC-32, those no row needs too. A checkpoint
    of two blocks and a bit, its means a view at an offset into a larger storage (as torch saves
    a slice), reads as its .ply; a NaN in the second block is named by its index in the file; a
    byte flipped before or after the view fails the storage's CRC-32."""
    n, pad = 2 * 65536 + 3, 5
    g = raw_gaussians(np.random.default_rng(12), n, degree=1)
    storage = np.concatenate([np.ones(3 * pad), g["means"].ravel(), np.ones(3 * pad)]).astype(np.float32)
    params = {**gsplat_parameters(g), "means": storage}
    views = {"means": storage[3 * pad : 3 * (pad + n)].reshape(n, 3)}
    ckpt, ply = tmp_path / "big.pt", tmp_path / "big.ply"
    save_checkpoint(ckpt, params, views=views)
    write_3dgs_ply(ply, g)
    a, b = splat.Scene.load(str(ckpt)).to_arrays(), splat.Scene.load(str(ply)).to_arrays()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    whole = ckpt.read_bytes()
    with zipfile.ZipFile(ckpt) as z:
        info = z.getinfo("ckpt_29999_rank0/data/0")  # the means' storage
    name_len, extra_len = struct.unpack_from("<HH", whole, info.header_offset + 26)
    start = info.header_offset + 30 + name_len + extra_len
    for at in (start + 2, start + info.file_size - 2):  # before and after the view
        ckpt.write_bytes(whole[:at] + bytes([whole[at] ^ 0x01]) + whole[at + 1 :])
        with pytest.raises(splat.SplatError, match="data/0 fails its CRC-32"):
            splat.Scene.load(str(ckpt))
    scales = g["scales"].copy()
    scales[65536 + 70, 2] = np.nan
    save_checkpoint(ckpt, {**params, "scales": scales}, views=views)
    with pytest.raises(splat.SplatError, match=r"vertex 65606.*scales\[2\]"):
        splat.Scene.load(str(ckpt))


@pytest.mark.filterwarnings("ignore:.*distributed training split these splats:UserWarning")
def test_a_distributed_runs_ranks_read_together(tmp_path, splat_bin):
    """gsplat's distributed training gives rank r the splats r, r + R, r + 2R, … (simple_trainer's
    points[world_rank::world_size]), and each rank saves ckpt_STEP_rankR.pt; its evaluation
    concatenates the ranks' splats in rank order. Any rank's file reads as that whole; a
    missing rank is refused by name, not read as part of the scene."""
    g = raw_gaussians(np.random.default_rng(17), 30, degree=1)
    ranks = 3
    for rank in range(ranks):
        share = {k: v[rank::ranks] for k, v in g.items()}
        save_checkpoint(tmp_path / f"ckpt_6999_rank{rank}.pt", gsplat_parameters(share))
    save_checkpoint(tmp_path / "ckpt_2999_rank0.pt", gsplat_parameters(g))  # another step: not a rank of it
    ply = tmp_path / "concatenated.ply"
    write_3dgs_ply(ply, {k: np.concatenate([v[r::ranks] for r in range(ranks)]) for k, v in g.items()})
    expected = splat.Scene.load(str(ply)).to_arrays()
    for rank in range(ranks):
        a = splat.Scene.load(str(tmp_path / f"ckpt_6999_rank{rank}.pt")).to_arrays()
        for name in a:
            np.testing.assert_array_equal(a[name], expected[name], err_msg=f"rank {rank}: {name}")
    info = subprocess.run([splat_bin, "info", str(tmp_path / "ckpt_6999_rank1.pt")], capture_output=True, text=True)
    assert info.returncode == 0 and "particles  30" in info.stdout, info.stdout
    assert "between 3 ranks" in info.stderr and "ckpt_6999_rank2.pt" in info.stderr, info.stderr
    assert len(splat.Scene.load(str(tmp_path / "ckpt_2999_rank0.pt"))) == 30
    (tmp_path / "ckpt_6999_rank1.pt").unlink()
    message = refused(tmp_path / "ckpt_6999_rank2.pt")
    assert "3 ranks, and ckpt_6999_rank1.pt is missing" in message, message
    # A file named like a rank that is another trainer's reads as itself; beside it, gsplat's
    # rank is refused rather than read with it (the reader once returned rank 0's file for
    # whichever rank was asked for).
    save_splatfacto_checkpoint(tmp_path / "ckpt_6999_rank0.pt", g)
    save_checkpoint(tmp_path / "ckpt_6999_rank1.pt", gsplat_parameters({k: v[1::ranks] for k, v in g.items()}))
    assert len(splat.Scene.load(str(tmp_path / "ckpt_6999_rank0.pt"))) == 30
    message = refused(tmp_path / "ckpt_6999_rank1.pt")
    assert "not another rank of ckpt_6999_rank1.pt: a Splatfacto checkpoint" in message, message


def test_a_gsplat_runs_config_names_its_world(tmp_path, splat_bin):
    """simple_trainer writes its config as RESULT/cfg.yml (yaml.dump of its dataclass: top-level
    scalars, lists, its strategy as a tagged object) beside RESULT/ckpts/: where it trained in
    its normalised world (the default), the checkpoint's note says so, with the data folder and
    factor; where not, nothing is said."""
    import dataclasses

    import yaml

    @dataclasses.dataclass
    class DefaultStrategy:
        prune_opa: float = 0.005
        refine_every: int = 100

    @dataclasses.dataclass
    class Config:
        data_dir: str = "data/360_v2/garden"
        data_factor: int = 4
        normalize_world_space: bool = True
        antialiased: bool = False
        near_plane: float = 0.01
        eval_steps: list = dataclasses.field(default_factory=lambda: [7000, 30000])
        strategy: DefaultStrategy = dataclasses.field(default_factory=DefaultStrategy)
        result_dir: str = "results/garden"

    g = raw_gaussians(np.random.default_rng(3), 8, degree=1)
    (tmp_path / "ckpts").mkdir()
    ckpt = tmp_path / "ckpts" / "ckpt_29999_rank0.pt"
    save_checkpoint(ckpt, gsplat_parameters(g))
    for normalize, expected in [(True, True), (False, False)]:
        (tmp_path / "cfg.yml").write_text(yaml.dump(vars(Config(normalize_world_space=normalize))))
        info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
        note = (
            "normalize_world_space: true) from data/360_v2/garden: the cameras of its COLMAP model line up with them "
            "through splat's gsplat-world option, its images downscaled by 4 (splat's data-factor option)"
        )
        assert info.returncode == 0 and (note in info.stderr) == expected, info.stderr
    # gsplat rasterized the splats (its footprint and near plane) in its classic mode, or where
    # the run says antialiased: true, through its antialiased filter: each renders as its .ply
    # with that preset. The controls: the .ply without a preset (3DGS's rasterizer) and the
    # other mode differ.
    g = with_a_near_splat(g)
    save_checkpoint(ckpt, gsplat_parameters(g))
    ply = tmp_path / "export.ply"
    write_3dgs_ply(ply, g)
    camera = near_camera()
    images = {}
    for antialiased, preset, name in [(True, "gsplat-antialiased", "antialiased"), (False, "gsplat", "3dgs")]:
        (tmp_path / "cfg.yml").write_text(yaml.dump(vars(Config(antialiased=antialiased))))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = splat.Scene.load(str(ckpt))
        assert scene.screen_filter == name and scene.trained["preset"] == preset, (scene.screen_filter, scene.trained)
        images[name] = splat.render(scene, camera, method="raster-sorted")["color"]
        as_ply = splat.render(splat.Scene.load(str(ply), preset=preset), camera, method="raster-sorted", preset=preset)
        np.testing.assert_array_equal(images[name], as_ply["color"], err_msg=name)
    plain = splat.render(splat.Scene.load(str(ply)), camera, method="raster-sorted")["color"]
    assert not np.array_equal(images["3dgs"], plain) and not np.array_equal(images["antialiased"], images["3dgs"])
    # A run that set its near_plane culled there (the near splat, 0.1 in front, at 0.2): the
    # checkpoint renders as its .ply with the gsplat preset and that plane, and splat convert
    # names the flags that render the .ply so. The control: gsplat's default plane (0.01), which
    # draws the near splat.
    (tmp_path / "cfg.yml").write_text(yaml.dump(vars(Config(near_plane=0.2))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = splat.Scene.load(str(ckpt))
    assert scene.trained["near_plane"] == pytest.approx(0.2), scene.trained
    culled = splat.render(scene, camera, method="raster-sorted")["color"]
    as_ply = splat.render(splat.Scene.load(str(ply)), camera, method="raster-sorted", preset="gsplat", near_plane=0.2)
    np.testing.assert_array_equal(culled, as_ply["color"])
    assert not np.array_equal(culled, images["3dgs"])
    convert = [splat_bin, "convert", str(ckpt), str(tmp_path / "converted.ply")]
    converted = subprocess.run(convert, capture_output=True, text=True)
    assert converted.returncode == 0, converted.stderr
    assert "render it with --preset gsplat --near-plane 0.2" in converted.stderr, converted.stderr
    # A preset given to render() names its screen filter too, as splat render's does.
    as_preset = splat.render(splat.Scene.load(str(ply)), camera, method="raster-sorted", preset="gsplat-antialiased")
    np.testing.assert_array_equal(as_preset["color"], images["antialiased"])
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert "antialiased: true" not in info.stderr, info.stderr
    (tmp_path / "cfg.yml").write_text(yaml.dump(vars(Config(antialiased=True))))
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert "says antialiased: true): the splatting methods apply its screen filter" in info.stderr, info.stderr


def test_what_is_not_a_gsplat_checkpoint_is_refused_by_name(tmp_path):
    g = gsplat_parameters(raw_gaussians(np.random.default_rng(5), 16, degree=1))

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
    assert 'neither "splats"' in refused(path) and "model, optimizer" in refused(path)
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


SPLATFACTO = ["means", "scales", "quats", "features_dc", "features_rest", "opacities"]


@dataclasses.dataclass
class SplatfactoModelConfig:
    """The settings of Nerfstudio's SplatfactoModelConfig that splat reads, with its defaults."""

    rasterize_mode: str = "classic"
    sh_degree: int = 3
    background_color: str = "random"


@dataclasses.dataclass
class VanillaPipelineConfig:
    model: SplatfactoModelConfig = dataclasses.field(default_factory=SplatfactoModelConfig)


@dataclasses.dataclass
class TrainerConfig:
    """A splatfacto run's config, as ns-train writes it to RUN/config.yml (yaml.dump of it):
    the model's settings nested in the pipeline's."""

    method_name: str = "splatfacto"
    max_num_iterations: int = 30000
    pipeline: VanillaPipelineConfig = dataclasses.field(default_factory=VanillaPipelineConfig)


def save_splatfacto_checkpoint(path, g: dict, prefix: str = "_model.gauss_params.") -> list[str]:
    """Nerfstudio's checkpoint of a splatfacto model of conftest's raw Gaussians `g` (its
    trainer's torch.save of step, pipeline, optimizers, schedulers and scalers): the splats
    under `prefix`, beside a camera optimizer; one Adam optimizer a parameter, its two moments
    stored as tensors; the schedulers' state, whose learning rates are one list shared by two
    places. Returns the archive's entries of the moments."""
    storages = []
    params = {
        "means": g["means"],
        "scales": g["scales"],
        "quats": g["rotations"],
        # At SH degree 0 splatfacto trains a colour logit: conftest's DC values serve as one.
        "features_dc": g["sh"][:, 0, :].copy(),
        "features_rest": g["sh"][:, 1:, :].copy(),
        "opacities": g["opacities"][:, None].copy(),
    }
    pipeline = collections.OrderedDict((prefix + name, params[name]) for name in SPLATFACTO)
    pipeline["_model.camera_optimizer.pose_adjustment"] = np.zeros((4, 6), np.float32)
    pipeline = state_dict(pipeline, storages)
    betas = (0.9, 0.999)  # Adam's default, one tuple shared by every optimizer
    optimizers, moment_entries = {}, []
    for k, name in enumerate(SPLATFACTO):
        moments = [np.full(params[name].shape, 0.25, np.float32), np.full(params[name].shape, 0.5, np.float32)]
        first = len(storages)
        state = state_dict({"step": np.array(29999.0, np.float32), "exp_avg": moments[0], "exp_avg_sq": moments[1]}, storages)
        group = {"lr": 1.6e-4, "betas": betas, "eps": 1e-15, "weight_decay": 0, "amsgrad": False, "params": [k]}
        optimizers[name] = {"state": {0: dict(state)}, "param_groups": [group]}
        moment_entries += [f"step-000029999/data/{key}" for key in range(first + 1, first + 3)]
    rates = [1.6e-6]
    schedulers = {"means": {"base_lrs": rates, "last_epoch": 29999, "_last_lr": rates}}
    scalers = {"scale": 65536.0, "growth_factor": 2.0, "backoff_factor": 0.5, "growth_interval": 2000, "_growth_tracker": 0}
    root = {"step": 29999, "pipeline": pipeline, "optimizers": optimizers, "schedulers": schedulers, "scalers": scalers}
    torch_save(root, path, storages, archive="step-000029999")
    return moment_entries


def flip_first_bytes(path, entries: list[str]) -> None:
    """Flip the first byte of each of the archive's `entries`, so that each fails its CRC-32."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        for name in entries:
            info = z.getinfo(name)
            name_len, extra_len = struct.unpack_from("<HH", data, info.header_offset + 26)
            data[info.header_offset + 30 + name_len + extra_len] ^= 0xFF
    path.write_bytes(bytes(data))


def splatfacto_export(g: dict) -> dict:
    """What ns-export gaussian-splat writes of the model (nerfstudio/scripts/exporter.py, the
    default sh_coeffs mode), as conftest's raw Gaussians: its shs_0 is the DC coefficient, or
    at SH degree 0 RGB2SH(sigmoid(features_dc)) (nerfstudio/utils/spherical_harmonics.py)."""
    if g["sh"].shape[1] > 1:
        return g
    rgb = 1 / (1 + np.exp(-g["sh"][:, :1, :].astype(np.float64)))
    return {**g, "sh": ((rgb - 0.5) / 0.28209479177387814).astype(np.float32)}


@pytest.mark.parametrize("degree", [0, 3])
def test_a_splatfacto_checkpoint_holds_what_ns_export_writes(tmp_path, splat_bin, degree):
    g = raw_gaussians(np.random.default_rng(21 + degree), 48, degree=degree)
    ckpt, ply = tmp_path / "step-000029999.ckpt", tmp_path / "splat.ply"
    save_splatfacto_checkpoint(ckpt, g)
    write_3dgs_ply(ply, splatfacto_export(g))
    from_ckpt, from_ply = splat.Scene.load(str(ckpt)), splat.Scene.load(str(ply))
    assert len(from_ckpt) == 48 and from_ckpt.sh_degree == degree
    a, b = from_ckpt.to_arrays(), from_ply.to_arrays()
    for name in a:
        if name == "sh" and degree == 0:
            # The sigmoid and RGB2SH in f32 (splat) against f64 rounded once (this export).
            np.testing.assert_allclose(a[name], b[name], rtol=1e-6, atol=1e-6, err_msg=name)
        else:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert info.returncode == 0 and "Nerfstudio splatfacto checkpoint (step 29999)" in info.stdout, info
    assert "dataparser_transforms.json" not in info.stderr, info.stderr
    # In its run's folder (RUN/nerfstudio_models/step-STEP.ckpt), the run's dataparser transforms
    # beside it are named.
    run = tmp_path / "2026-12-05_101500"
    (run / "nerfstudio_models").mkdir(parents=True)
    (run / "dataparser_transforms.json").write_text('{"transform": [], "scale": 1.0}')
    ckpt.rename(run / "nerfstudio_models" / ckpt.name)
    ckpt = run / "nerfstudio_models" / ckpt.name
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    expected = f"{run / 'dataparser_transforms.json'} moves the cameras of its transforms.json there"
    assert info.returncode == 0 and expected in info.stderr, info.stderr
    # splatfacto rasterizes through gsplat, in the mode the run's config.yml names (ns-train's
    # yaml.dump of its TrainerConfig, the model's config nested in the pipeline's): each renders
    # as its .ply with that mode's preset. The controls: the two images differ, and the classic
    # mode's from the .ply's without a preset (3DGS's rasterizer culls the near splat).
    import yaml

    save_splatfacto_checkpoint(ckpt, with_a_near_splat(g))
    write_3dgs_ply(ply, splatfacto_export(with_a_near_splat(g)))
    camera = near_camera()
    images = {}
    for mode, preset, name in [("antialiased", "gsplat-antialiased", "antialiased"), ("classic", "gsplat", "3dgs")]:
        config = TrainerConfig(pipeline=VanillaPipelineConfig(SplatfactoModelConfig(rasterize_mode=mode)))
        (run / "config.yml").write_text(yaml.dump(config))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = splat.Scene.load(str(ckpt))
        assert scene.screen_filter == name and scene.trained["preset"] == preset, mode
        images[name] = splat.render(scene, camera, method="raster-sorted")["color"]
        # splatfacto's default background_color, random, evaluates over Viser's colour.
        ply_scene, background = splat.Scene.load(str(ply), preset=preset), scene.trained["background"]
        as_ply = splat.render(ply_scene, camera, method="raster-sorted", preset=preset, background=background)
        # Within 2e-6: at degree 0 the colours differ by the f32 rounding checked above.
        np.testing.assert_allclose(images[name], as_ply["color"], atol=2e-6, err_msg=mode)
    assert np.abs(images["antialiased"] - images["3dgs"]).max() > 1e-3
    plain = splat.render(splat.Scene.load(str(ply)), camera, method="raster-sorted", background=background)["color"]
    assert np.abs(images["3dgs"] - plain).max() > 1e-3
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert "config.yml says rasterize_mode: antialiased" not in info.stderr, info.stderr
    antialiased = TrainerConfig(pipeline=VanillaPipelineConfig(SplatfactoModelConfig("antialiased")))
    (run / "config.yml").write_text(yaml.dump(antialiased))
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert "config.yml says rasterize_mode: antialiased): the splatting methods apply" in info.stderr, info.stderr
    # Checkpoints before the parameter dict, and of a distributed run, read the same; the
    # optimizer's moments are never read (damaged, they change nothing).
    for variant, prefix in [("old", "_model."), ("ddp", "module._model.gauss_params."), ("moments", None)]:
        path = tmp_path / f"{variant}.ckpt"
        moments = save_splatfacto_checkpoint(path, g, **({"prefix": prefix} if prefix else {}))
        if prefix is None:
            flip_first_bytes(path, moments)
        c = splat.Scene.load(str(path)).to_arrays()
        for name in a:
            np.testing.assert_array_equal(c[name], a[name], err_msg=f"{variant}: {name}")


def test_what_is_not_a_splatfacto_checkpoint_is_refused_by_name(tmp_path):
    g = raw_gaussians(np.random.default_rng(6), 8, degree=1)

    # A nerfacto checkpoint: a pipeline of fields and proposal networks, no splats.
    path = tmp_path / "nerfacto.ckpt"
    storages = []
    fields = {f"_model.field.mlp_base.params{k}": np.zeros(4, np.float32) for k in range(8)}
    torch_save({"step": 29999, "pipeline": state_dict(fields, storages)}, path, storages)
    message = refused(path)
    assert "no splatfacto model" in message and "_model.field.mlp_base.params0" in message, message
    assert "and 2 more" in message, message
    # A splatfacto checkpoint without its opacities.
    path = tmp_path / "partial.ckpt"
    storages = []
    params = {"_model.gauss_params.means": g["means"], "_model.gauss_params.scales": g["scales"]}
    torch_save({"step": 1, "pipeline": state_dict(params, storages)}, path, storages)
    assert 'no "_model.gauss_params.quats"' in refused(path)
    # features_dc of gsplat's shape (N, 1, 3), not splatfacto's (N, 3).
    path = tmp_path / "shape.ckpt"
    storages = []
    params = {"_model.gauss_params." + name: a for name, a in [
        ("means", g["means"]), ("scales", g["scales"]), ("quats", g["rotations"]), ("features_dc", g["sh"][:, :1, :]),
        ("features_rest", g["sh"][:, 1:, :]), ("opacities", g["opacities"][:, None])]}
    torch_save({"step": 1, "pipeline": state_dict(params, storages)}, path, storages)
    assert '"features_dc" has shape [8, 1, 3], expected [8, 3]' in refused(path)


def grut_config(
    method: str = "3dgrt", degree: int = 4, density: str = "sigmoid", normalize: bool = False, background: str = "black"
):
    """A 3DGRUT run's config (the settings of configs/base_gs.yaml and configs/render/*.yaml that
    splat reads, among others), as Hydra hands it to the trainer: an OmegaConf DictConfig in
    struct mode."""
    from omegaconf import OmegaConf

    conf = OmegaConf.create(
        {
            "model": {
                "density_activation": density,
                "scale_activation": "exp",
                "default_density": 0.1,
                "progressive_training": {"init_n_features": 0, "max_n_features": 3, "increase_frequency": 1000},
                "background": {"name": "background-color", "color": background},
            },
            "render": {
                "method": method,
                "particle_kernel_degree": degree,
                "particle_kernel_min_response": 0.0113,
                "particle_kernel_min_alpha": "${div:1.0,255.0}",
                "primitive_type": "instances",
                "pipeline_type": "reference",
                "backward_pipeline_type": "${render.pipeline_type}Bwd",
            },
            "out_dir": "runs",
            "experiment_name": "bonsai",
            "dataset": {
                "type": "colmap",
                "downsample_factor": 4,
                "test_split_interval": 8,
                "normalize_world_space": normalize,
            },
            "optimizer": {"params": {"positions": {"lr": 1.6e-4}, "density": {"lr": 5e-2}}},
            "writer": {"use_wandb": False, "tags": ["a", "b"]},
        }
    )
    OmegaConf.set_struct(conf, True)
    return conf


def save_grut_checkpoint(path, g: dict, config=None, feature_type: str = "sh") -> None:
    """3DGRUT's checkpoint of conftest's raw Gaussians `g`: its trainer's torch.save of the
    model's get_model_parameters() (the parameters as nn.Parameters, the background module's
    state, the optimizer's state, the config, the feature type), the step and the epoch."""
    n, storages = len(g["means"]), []
    params = {
        "positions": g["means"],
        "rotation": g["rotations"],
        "scale": g["scales"],
        "density": g["opacities"][:, None].copy(),
        "features_albedo": g["sh"][:, 0, :].copy(),
        "features_specular": g["sh"][:, 1:, :].reshape(n, -1).copy(),  # coefficient by coefficient
    }
    tensors = state_dict(params, storages)
    root = {name: _Parameter(tensors[name]) for name in ("positions", "rotation", "scale", "density")}
    moments = state_dict({"exp_avg": np.zeros((n, 3), np.float32), "exp_avg_sq": np.zeros((n, 3), np.float32)}, storages)
    root.update(
        background=state_dict({"color": np.zeros(3, np.float32)}, storages),
        n_active_features=3,
        max_n_features=3,
        progressive_training=True,
        scene_extent=2.5,
        optimizer={"state": {0: dict(moments)}, "param_groups": [{"lr": 1.6e-4, "params": [0], "name": "positions"}]},
        feature_type=feature_type,
        particle_feature_dim=3 * g["sh"].shape[1],
        ray_feature_dim=3,
        features_albedo=_Parameter(tensors["features_albedo"]),
        features_specular=_Parameter(tensors["features_specular"]),
        global_step=30000,
        epoch=9,
    )
    if config is not None:
        root["config"] = config
    torch_save(root, path, storages, archive="ckpt_last")


@pytest.mark.filterwarnings("ignore:.*3DGRT trained these particles:UserWarning")
@pytest.mark.parametrize("degree", [1, 3])
def test_a_3dgrut_checkpoint_holds_what_its_ply_export_holds(tmp_path, splat_bin, degree):
    g = raw_gaussians(np.random.default_rng(31 + degree), 40, degree=degree)
    ckpt, ply = tmp_path / "ckpt_last.pt", tmp_path / "export_last.ply"
    save_grut_checkpoint(ckpt, g, grut_config())
    write_3dgs_ply(ply, g)  # 3DGRUT's PLYExporter: the parameters before activation, f_rest channel-major
    from_ckpt, from_ply = splat.Scene.load(str(ckpt)), splat.Scene.load(str(ply))
    assert len(from_ckpt) == 40 and from_ckpt.sh_degree == degree
    a, b = from_ckpt.to_arrays(), from_ply.to_arrays()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    with pytest.warns(UserWarning, match="they render as it renders them, with the 3dgrt preset, where no other"):
        splat.Scene.load(str(ckpt))
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert info.returncode == 0 and "3DGRUT checkpoint (step 30000)" in info.stdout, info
    assert "trained    through 3DGRT's ray tracer, kernel degree 4, cutoff 2.9972σ" in info.stdout, info
    assert "3DGRT trained these particles" in info.stderr and "with the 3dgrt preset" in info.stderr, info.stderr
    # 3DGUT's config, and one of 3DGRT's at another kernel degree: each note names its preset;
    # a run in gsplat's normalised world, or of surfels, is said to be.
    surfels = grut_config()
    surfels.render.primitive_type = "trisurfel"
    for config, expected in [
        (grut_config("3dgut", 2), "with the 3dgut preset, where no other"),
        (grut_config("3dgrt", 8), "the 3dgrt preset and the kernel the run set (degree 8, cut off at 2.998"),
        (None, "does not say how 3DGRUT rendered these particles"),
        (grut_config(normalize=True), "where splat's gsplat-world option moves them"),
        (surfels, "as flat surfels (its render.primitive_type trisurfel)"),
    ]:
        save_grut_checkpoint(ckpt, g, config)
        info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
        assert info.returncode == 0 and expected in info.stderr, info.stderr


def test_a_3dgrut_checkpoint_renders_as_its_renderer_drew_it(tmp_path, splat_bin):
    """The config beside a 3DGRUT checkpoint's particles names the renderer and kernel they were
    trained through: the checkpoint renders as its .ply export does with that renderer's preset
    (3DGRT: kernel degree 4; 3DGUT: splatting evaluates each particle along its ray), or with the
    kernel the run set; a preset chosen overrides it. The controls: the .ply rendered without a
    preset (what the checkpoint gave before its config was read) differs in every case."""
    g = raw_gaussians(np.random.default_rng(77), 40, degree=1)
    ckpt, ply = tmp_path / "ckpt_last.pt", tmp_path / "export_last.ply"
    write_3dgs_ply(ply, g)
    from_ply = splat.Scene.load(str(ply))
    camera = near_camera()

    def image(scene, **options):
        return splat.render(scene, camera, **options)["color"]

    def load(config):
        save_grut_checkpoint(ckpt, g, config)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return splat.Scene.load(str(ckpt))

    # exp(-4.5 (c/3)^8) = 0.0113, in f32 as the reader computes it.
    cutoff8 = float(np.float32(3.0) * np.float32((np.log(1.0 / np.float32(0.0113)) / 4.5) ** (1.0 / 8.0)))
    for config, method, preset, as_ply in [
        (grut_config("3dgrt", 4), "exact", "3dgrt", {"preset": "3dgrt"}),
        (grut_config("3dgut", 2), "raster-sorted", "3dgut", {"preset": "3dgut"}),
        (grut_config("3dgrt", 8), "exact", "3dgrt", {"kernel_degree": 8, "cutoff": cutoff8}),
    ]:
        scene = load(config)
        degree = config.render.particle_kernel_degree
        cutoff = 3.0 * (np.log(1 / 0.0113) / 4.5) ** (1 / degree)  # where the kernel falls to 0.0113
        kernel = {"kernel_degree": degree, "cutoff": pytest.approx(cutoff, rel=1e-6)}
        assert scene.trained == {"preset": preset, **kernel, "background": None, "near_plane": pytest.approx(0.2)}
        rendered = image(scene, method=method)
        np.testing.assert_array_equal(rendered, image(from_ply, method=method, **as_ply), err_msg=f"{preset} {degree}")
        assert not np.array_equal(rendered, image(from_ply, method=method)), f"{preset} {degree}: the control"
    as_3dgs = image(load(grut_config()), method="exact", preset="3dgs")
    np.testing.assert_array_equal(as_3dgs, image(from_ply, method="exact"))
    assert load(None).trained is None and from_ply.trained is None
    np.testing.assert_array_equal(image(load(None), method="exact"), image(from_ply, method="exact"))
    # The CLI reads the same kernel: its image of the checkpoint is the .ply's with the preset.
    images = []
    save_grut_checkpoint(ckpt, g, grut_config())
    for scene, options in [(ckpt, []), (ply, ["--preset", "3dgrt"])]:
        out = tmp_path / f"{scene.stem}.npy"
        args = [splat_bin, "render", str(scene), "--method", "exact", "--eye", "0,0,0", "--target", "0,0,4.5"]
        args += ["--up", "0,-1,0", "--fov", "45", "--width", "48", "--height", "36", "-o", str(out), *options]
        run = subprocess.run(args, capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
        images.append(np.load(out))
    np.testing.assert_array_equal(images[0], images[1])
    # Converted, the particles lose their config: splat convert says what renders them as it did.
    for config in [grut_config(), grut_config("3dgrt", 8)]:
        save_grut_checkpoint(ckpt, g, config)
        converted = tmp_path / "converted.ply"
        run = subprocess.run([splat_bin, "convert", str(ckpt), str(converted)], capture_output=True, text=True)
        assert run.returncode == 0 and "cannot record that its splats were trained through" in run.stderr, run.stderr
        flags = run.stderr.split("render it with ")[1].splitlines()[0].split()
        options = {flags[i][2:].replace("-", "_"): flags[i + 1] for i in range(0, len(flags), 2)}
        np.testing.assert_array_equal(
            image(splat.Scene.load(str(converted)), method="exact", **options), image(load(config), method="exact")
        )
    save_grut_checkpoint(ckpt, g, grut_config())
    # A world's splats render with one kernel: a world of the checkpoint alone keeps its
    # renderer; one that adds splats trained otherwise renders with the default, and says so.
    alone, mixed = tmp_path / "alone.toml", tmp_path / "mixed.toml"
    alone.write_text(f'[[splats]]\nfile = "{ckpt.name}"\n')
    mixed.write_text(f'[[splats]]\nfile = "{ckpt.name}"\n\n[[splats]]\nfile = "{ply.name}"\n')
    assert splat.Scene.load(str(alone)).trained == load(grut_config()).trained
    with pytest.warns(UserWarning, match="splats.1. names no renderer but splats.0. was trained through 3DGRT's"):
        assert splat.Scene.load(str(mixed)).trained is None


def test_what_splat_cannot_render_of_3dgrut_is_refused_by_name(tmp_path):
    g = raw_gaussians(np.random.default_rng(9), 8, degree=1)

    path = tmp_path / "nht.pt"
    save_grut_checkpoint(path, g, grut_config(), feature_type="nht")
    assert "nht features" in refused(path)
    path = tmp_path / "softplus.pt"
    save_grut_checkpoint(path, g, grut_config(density="softplus"))
    assert 'model.density_activation "softplus", where a splat\'s is sigmoid' in refused(path)
    # 3DGRT's linear kernel (degree 0), and degree 6, which its tracer renders as degree 2.
    for degree in [0, 6]:
        save_grut_checkpoint(path, g, grut_config(degree=degree))
        assert f"render.particle_kernel_degree {degree}, a kernel splat does not render" in refused(path)


def save_inria_checkpoint(path, g: dict) -> None:
    """3DGS's checkpoint of conftest's raw Gaussians `g`, as train.py saves it at
    --checkpoint_iterations: torch.save((gaussians.capture(), iteration)), the capture the
    active SH degree, the parameters (nn.Parameters), the densification statistics, the
    optimizer's state and the spatial learning rate's scale."""
    n, storages = len(g["means"]), []
    params = {
        "_xyz": g["means"],
        "_features_dc": g["sh"][:, :1, :].copy(),
        "_features_rest": g["sh"][:, 1:, :].copy(),
        "_scaling": g["scales"],
        "_rotation": g["rotations"],
        "_opacity": g["opacities"][:, None].copy(),
        "max_radii2D": np.zeros(n, np.float32),
        "xyz_gradient_accum": np.zeros((n, 1), np.float32),
        "denom": np.zeros((n, 1), np.float32),
    }
    t = state_dict(params, storages)
    groups = [{"params": [k], "lr": 0.0, "name": name, "eps": 1e-15} for k, name in enumerate(["xyz", "f_dc"])]
    capture = (
        round(g["sh"].shape[1] ** 0.5) - 1,  # the active SH degree: all of them, at 30000
        *(_Parameter(t[name]) for name in ["_xyz", "_features_dc", "_features_rest", "_scaling", "_rotation", "_opacity"]),
        t["max_radii2D"],
        t["xyz_gradient_accum"],
        t["denom"],
        {"state": {}, "param_groups": groups},
        4.2,
    )
    torch_save((capture, 30000), path, storages, archive="chkpnt30000")


@pytest.mark.parametrize("degree", [0, 3])
def test_a_3dgs_checkpoint_holds_what_its_save_ply_writes(tmp_path, splat_bin, degree):
    g = raw_gaussians(np.random.default_rng(41 + degree), 24, degree=degree)
    ckpt, ply = tmp_path / "chkpnt30000.pth", tmp_path / "point_cloud.ply"
    save_inria_checkpoint(ckpt, g)
    write_3dgs_ply(ply, g)
    a, b = splat.Scene.load(str(ckpt)).to_arrays(), splat.Scene.load(str(ply)).to_arrays()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    info = subprocess.run([splat_bin, "info", str(ckpt)], capture_output=True, text=True)
    assert info.returncode == 0 and "3DGS checkpoint (step 30000)" in info.stdout, info
    # A pair that is not 3DGS's capture and iteration is refused, not misread.
    path = tmp_path / "pair.pth"
    torch_save(((1, 2, 3), 30000), path, [])
    assert "nor 3DGS's (capture, iteration)" in refused(path)


def test_a_runs_background_is_the_one_its_evaluation_composites_over(tmp_path):
    """The colour a run's evaluation composites its splats over renders behind them: 3DGS's -w
    (its model folder's cfg_args, beside its iterations' .ply and its checkpoints), splatfacto's
    background_color (white; random, which evaluates over Viser's colour) and 3DGRUT's
    model.background.color white. Each renders as the plain .ply over that colour; the
    controls: the runs without it render over black, as the plain .ply does."""
    g = raw_gaussians(np.random.default_rng(5), 24, degree=1)
    camera = near_camera()
    plain = tmp_path / "plain.ply"
    write_3dgs_ply(plain, g)

    def load(path):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return splat.Scene.load(str(path))

    def image(scene, **options):
        return splat.render(scene, camera, method="exact", **options)["color"]

    black, white = image(load(plain)), image(load(plain), background=(1, 1, 1))
    assert np.abs(white - black).max() > 0.5
    # 3DGS: MODEL/cfg_args beside MODEL/point_cloud/iteration_30000/point_cloud.ply and
    # MODEL/chkpnt30000.pth.
    model = tmp_path / "model"
    iteration = model / "point_cloud" / "iteration_30000"
    iteration.mkdir(parents=True)
    write_3dgs_ply(iteration / "point_cloud.ply", g)
    save_inria_checkpoint(model / "chkpnt30000.pth", g)
    for flag, expected in [(True, white), (False, black)]:
        (model / "cfg_args").write_text(
            f"Namespace(data_device='cuda', depths='', eval=True, images='images', model_path='{model}', "
            f"resolution=-1, sh_degree=3, source_path='/data/nerf_synthetic/lego', train_test_exp=False, "
            f"white_background={flag})"
        )
        for path in [iteration / "point_cloud.ply", model / "chkpnt30000.pth"]:
            scene = load(path)
            np.testing.assert_array_equal(image(scene), expected, err_msg=f"{path.name}, white_background={flag}")
            assert (scene.trained or {}).get("background") == ((1.0, 1.0, 1.0) if flag else None), scene.trained
    # splatfacto: RUN/config.yml beside RUN/nerfstudio_models/.
    import yaml

    run = tmp_path / "run"
    (run / "nerfstudio_models").mkdir(parents=True)
    ckpt = run / "nerfstudio_models" / "step-000029999.ckpt"
    save_splatfacto_checkpoint(ckpt, g)
    viser = (0.1490, 0.1647, 0.2157)
    for color, background in [("white", (1.0, 1.0, 1.0)), ("random", viser), ("black", None)]:
        config = TrainerConfig(pipeline=VanillaPipelineConfig(SplatfactoModelConfig(background_color=color)))
        (run / "config.yml").write_text(yaml.dump(config))
        scene = load(ckpt)
        assert scene.trained["background"] == (None if background is None else pytest.approx(background)), color
        expected = black if background is None else image(load(plain), background=scene.trained["background"])
        np.testing.assert_array_equal(image(scene), expected, err_msg=color)
    # 3DGRUT: its config, in its checkpoint.
    grut = tmp_path / "ckpt_last.pt"
    for color, expected in [("white", white), ("black", black), ("random", black)]:
        save_grut_checkpoint(grut, g, grut_config(degree=2, background=color))
        scene = load(grut)
        np.testing.assert_array_equal(image(scene, kernel_degree=2, cutoff=3), expected, err_msg=color)
