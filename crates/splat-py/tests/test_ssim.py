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
"""

from __future__ import annotations

import numpy as np
import splat

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
