"""SSIM as the Gaussian-splatting trainers report it, against ports of their code.

`splat.compare` (and `splat compare`) reports two means of one SSIM map. Each is checked here
against a NumPy port of the code behind the numbers in the trainers' tables:

- 3DGS's `utils/loss_utils.py` `ssim` (what its `metrics.py` prints): `F.conv2d` of the images,
  their squares and product with the 11 × 11 Gaussian window of σ 1.5, zero padding 5,
  C1 = 0.01², C2 = 0.03², the mean of the map over every pixel and channel;
- torchmetrics' `StructuralSimilarityIndexMeasure(data_range=1.0)` (Nerfstudio's and gsplat's
  evaluations): the images padded by reflection, convolved without padding, and the map's padded
  border cropped before the mean.

Control, run by hand: a window of σ 1.4 in the ports misses splat's values by 1e-2,
against the tolerance of 1e-9 (f64 sums in another order).

`splat compare --background` composites an RGBA photograph as 3DGS's
`readCamerasFromTransforms` loads a NeRF-synthetic one; checked against a port of it. Control,
run by hand: rounding where 3DGS truncates to 8 bits misses it by RMSE 2.5e-3.
"""

from __future__ import annotations

import subprocess

import numpy as np
import splat
from PIL import Image

TOLERANCE = 1e-9


def gaussian_window(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """3DGS's `create_window`: the outer product of the normalised 1D Gaussian."""
    g = np.array([np.exp(-((x - size // 2) ** 2) / float(2 * sigma**2)) for x in range(size)])
    g = g / g.sum()
    return np.outer(g, g)


def conv2d(plane: np.ndarray, window: np.ndarray, padding: int) -> np.ndarray:
    """`F.conv2d` of one channel (cross-correlation), zero padding `padding`."""
    size = window.shape[0]
    padded = np.pad(plane, padding)
    h, w = padded.shape[0] - size + 1, padded.shape[1] - size + 1
    out = np.zeros((h, w))
    for dy in range(size):
        for dx in range(size):
            out += window[dy, dx] * padded[dy : dy + h, dx : dx + w]
    return out


def ssim_map(img1: np.ndarray, img2: np.ndarray, pad, padding: int) -> np.ndarray:
    """The SSIM map of (H, W, C) images, each channel through `pad` then `conv2d`."""
    window = gaussian_window()
    C1, C2 = 0.01**2, 0.03**2
    maps = []
    for c in range(img1.shape[2]):
        a, b = pad(img1[..., c].astype(np.float64)), pad(img2[..., c].astype(np.float64))
        mu1, mu2 = conv2d(a, window, padding), conv2d(b, window, padding)
        sigma1_sq = conv2d(a * a, window, padding) - mu1**2
        sigma2_sq = conv2d(b * b, window, padding) - mu2**2
        sigma12 = conv2d(a * b, window, padding) - mu1 * mu2
        maps.append(((2 * mu1 * mu2 + C1) * (2 * sigma12 + C2)) / ((mu1**2 + mu2**2 + C1) * (sigma1_sq + sigma2_sq + C2)))
    return np.stack(maps, axis=-1)


def ssim_3dgs(img1: np.ndarray, img2: np.ndarray) -> float:
    """3DGS's `ssim(img1, img2)`: zero padding 5, the mean of the whole map."""
    return float(ssim_map(img1, img2, lambda p: p, padding=5).mean())


def ssim_torchmetrics(img1: np.ndarray, img2: np.ndarray) -> float:
    """torchmetrics' SSIM: reflection padding 5, valid convolution, the padded border cropped."""
    full = ssim_map(img1, img2, lambda p: np.pad(p, 5, mode="reflect"), padding=0)
    return float(full[5:-5, 5:-5].mean())


def test_ssim_is_3dgss_and_torchmetrics(tmp_path):
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:37, 0:53]
    base = np.stack([np.sin(x / 5.0), np.cos(y / 7.0), (x + y) % 9 / 9.0], axis=-1) * 0.45 + 0.5
    pairs = [
        (base, base + rng.normal(0, 0.05, base.shape)),  # noise
        (base, np.roll(base, 2, axis=1)),  # a shift
        (base, base * 0.8 + 0.1),  # contrast
        (rng.random((16, 11, 3)), rng.random((16, 11, 3))),  # the smallest image with an inside
    ]
    for reference, test in pairs:
        a, b = reference.astype(np.float32), test.astype(np.float32)
        m = splat.compare(a, b)
        assert abs(m["ssim"] - ssim_3dgs(a, b)) < TOLERANCE, (m["ssim"], ssim_3dgs(a, b))
        assert abs(m["ssim_inside"] - ssim_torchmetrics(a, b)) < TOLERANCE, (m["ssim_inside"], ssim_torchmetrics(a, b))
    small = rng.random((10, 20, 3)).astype(np.float32)
    m = splat.compare(small, small * 0.9)
    assert m["ssim_inside"] is None and abs(m["ssim"] - ssim_3dgs(small, small * 0.9)) < TOLERANCE


def gaussian_splatting_photograph(path, white_background: bool) -> np.ndarray:
    """3DGS's `readCamerasFromTransforms` for one RGBA photograph, as 8-bit RGB. Its
    `Image.fromarray(np.array(arr * 255.0, dtype=np.byte), "RGB")` read the int8 bytes as
    uint8, which the `view` does here (Pillow 13 refuses int8 data)."""
    im_data = np.array(Image.open(path).convert("RGBA"))
    bg = np.array([1, 1, 1]) if white_background else np.array([0, 0, 0])
    norm_data = im_data / 255.0
    arr = norm_data[:, :, :3] * norm_data[:, :, 3:4] + bg * (1 - norm_data[:, :, 3:4])
    return np.array(arr * 255.0, dtype=np.byte).view(np.uint8)


def test_an_rgba_photograph_is_composited_as_3dgs_loads_it(tmp_path, splat_bin):
    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, (24, 32, 4)).astype(np.uint8)
    rgba[:4, :, 3] = 0  # the transparent border of a NeRF-synthetic photograph
    photograph = tmp_path / "r_0.png"
    Image.fromarray(rgba, "RGBA").save(photograph)
    for white, background in [(True, "1,1,1"), (False, "0,0,0")]:
        loaded = tmp_path / f"loaded-{white}.png"
        Image.fromarray(gaussian_splatting_photograph(photograph, white), "RGB").save(loaded)
        args = [splat_bin, "compare", str(photograph), str(loaded), "--background", background]
        out = subprocess.run(args, capture_output=True, text=True, check=True).stdout
        assert "RMSE       0.000000e0" in out, out
    # Without --background the colour is compared as stored, and a note says so.
    plain = subprocess.run([splat_bin, "compare", str(photograph), str(loaded)], capture_output=True, text=True)
    assert plain.returncode == 0 and "have alpha" in plain.stderr, plain.stderr
    assert "RMSE       0.000000e0" not in plain.stdout
