"""Bad input raises splat.SplatError naming the problem (never a crash of the interpreter);
the z-test from Python accepts an unbiased estimator and rejects a 2 % bias injected into it;
compare's metrics."""

from __future__ import annotations

import numpy as np
import pytest
import splat

N = 8


def arrays(**changes):
    rng = np.random.default_rng(3)
    base = {
        "means": rng.normal(size=(N, 3)) + [0, 0, 4],
        "scales": np.full((N, 3), 0.2),
        "rotations": np.tile([1.0, 0, 0, 0], (N, 1)),
        "opacities": np.full(N, 0.5),
        "colors": np.full((N, 3), 0.5),
    }
    base.update(changes)
    return base


def means_with_nan():
    means = arrays()["means"].copy()
    means[5, 1] = np.nan
    return means


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"means": np.zeros((N, 2))}, r"means has shape \(8, 2\); expected \(N, 3\)"),
        ({"scales": np.zeros((N - 1, 3))}, r"scales has shape \(7, 3\); expected \(8, 3\)"),
        ({"rotations": np.zeros((N, 3))}, r"rotations has shape \(8, 3\); expected \(8, 4\)"),
        ({"opacities": np.zeros((N, 1))}, r"opacities has shape \(8, 1\); expected \(8,\)"),
        ({"means": means_with_nan()}, r"splat 5: .*mean"),
        ({"rotations": np.zeros((N, 4))}, r"splat 0: .*quaternion"),
        ({"opacities": np.full(N, 1.5)}, r"splat 0: opacity 1.5 is outside \[0, 1\]"),
        ({"scales": np.full((N, 3), -0.1)}, r"splat 0: .*scale"),
        ({"colors": None, "sh": np.zeros((N, 5, 3))}, r"sh has 5 coefficients"),
        ({"colors": None, "sh": np.zeros((N, 3))}, r"sh has shape \(8, 3\); expected \(8, K, 3\)"),
        ({"colors": None}, r"give sh \(N, K, 3\) or colors"),
        ({"means": np.array([["a", "b", "c"]] * N)}, r"means has dtype <U1"),
        ({"means": np.zeros((0, 3)), "scales": np.zeros((0, 3)), "rotations": np.zeros((0, 4)),
          "opacities": np.zeros(0), "colors": np.zeros((0, 3))}, r"no splats"),
    ],
)
def test_bad_arrays_are_refused_naming_the_problem(changes, message):
    with pytest.raises(splat.SplatError, match=message):
        splat.Scene.from_arrays(**arrays(**changes))


@pytest.mark.parametrize(
    "options, message",
    [
        ({"method": "nope"}, r"invalid value 'nope' for 'method='"),
        ({"methd": "exact"}, r"(?s)unexpected argument 'methd=' found.*'method='"),
        ({"method": "kbuffer", "k": 0}, r"k \(PARTICLES_SPP\) = 0 is outside 1..=64"),
        ({"spp": -1}, r"invalid value '-1' for 'spp='"),
        ({"output": "x.png"}, r"output= is not an option here"),
        ({"depth": "depth.npy"}, r"depth= takes True or False"),
        ({"width": 0}, r"width"),
        ({"early_stop": 3}, r"early_stop="),
        ({"pipeline": "raster", "method": "exact"}, r"method= exact is not a raster method"),
        ({"pipeline": "path", "method": "raster-sorted"}, r"not a Gaussian estimator of the path tracer"),
        ({"camera": "/nonexistent/cameras.json"}, r"/nonexistent/cameras.json"),
    ],
)
def test_bad_options_are_refused_naming_the_problem(options, message):
    with pytest.raises(splat.SplatError, match=message):
        splat.render(splat.Scene.demo(), **{"width": 8, "height": 6, "backend": "cpu", **options})


def test_other_bad_calls_are_refused():
    scene = splat.Scene.demo()
    camera = splat.Camera.look_at((0, 0, -3), (0, 0, 0), width=8, height=6)
    with pytest.raises(splat.SplatError, match="give the camera once"):
        splat.render(scene, camera, eye=(0, 0, 1), target=(0, 0, 0))
    with pytest.raises(splat.SplatError, match="expected a splat.Scene"):
        splat.render("scene.ply")
    with pytest.raises(splat.SplatError, match="eye and target coincide"):
        splat.Camera.look_at((1, 2, 3), (1, 2, 3))
    with pytest.raises(splat.SplatError, match=r"K is .*no skew"):
        splat.Camera.from_matrices(np.eye(4, dtype=np.float32), np.eye(3, dtype=np.float32) * 2, 8, 6)
    with pytest.raises(splat.SplatError, match=r"viewmat has shape \(3, 3\)"):
        splat.Camera.from_matrices(np.eye(3, dtype=np.float32), np.eye(3, dtype=np.float32), 8, 6)
    with pytest.raises(splat.SplatError, match="No such file|cannot|not found|reading"):
        splat.Scene.load("/nonexistent/scene.ply")
    with pytest.raises(splat.SplatError, match="images differ in size"):
        splat.compare(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))
    with pytest.raises(splat.SplatError, match=r"holds NaN"):
        splat.compare(np.zeros((4, 4, 3)), np.full((4, 4, 3), np.nan))
    with pytest.raises(splat.SplatError, match=r"expected an image"):
        splat.compare(np.zeros(4), np.zeros(4))
    with pytest.raises(splat.SplatError, match=r"the variance image is 4×4, the mean 5×4"):
        splat.z_test(np.zeros((4, 5, 3)), np.zeros((4, 4, 3)), np.zeros((4, 5, 3)), frames=4)
    with pytest.raises(splat.SplatError, match="frames= must be at least 1"):
        splat.z_test(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), frames=0)


def test_a_truncated_file_is_refused(tmp_path):
    path = tmp_path / "cut.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nend_header\n\x00\x00")
    with pytest.raises(splat.SplatError, match="cut.ply"):
        splat.Scene.load(path)


def test_compare_measures_what_splat_compare_measures():
    rng = np.random.default_rng(1)
    a = rng.uniform(size=(32, 32, 3)).astype(np.float32)
    same = splat.compare(a, a)
    assert same["rmse"] == 0 and same["psnr"] == float("inf") and same["ssim"] == pytest.approx(1.0)
    assert same["flip"] == pytest.approx(0.0, abs=1e-6)
    b = a + 0.1
    far = splat.compare(a, b)
    assert far["rmse"] == pytest.approx(0.1, rel=1e-5) and far["psnr"] == pytest.approx(20.0, rel=1e-4)
    assert far["flip"] > 0


def z_fixture():
    """40 overlapping Gaussians of opacity 0.3 to 0.9 and colours 0.2 to 0.9 filling most of a
    64 × 48 view: no particle so faint or so dark that its rare picks make the variance of a
    finite run a poor estimate (the demo scene at a few thousand pixels has such particles)."""
    rng = np.random.default_rng(5)
    n = 40
    means = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-0.75, 0.75, n), rng.uniform(3.5, 5.5, n)])
    arrays = {
        "means": means,
        "scales": rng.uniform(0.15, 0.45, (n, 3)),
        "rotations": rng.normal(size=(n, 4)),
        "opacities": rng.uniform(0.3, 0.9, n),
        "colors": rng.uniform(0.2, 0.9, (n, 3)),
    }
    camera = splat.Camera.look_at((0, 0, 0), (0, 0, 4.5), up=(0, -1, 0), fov_y=45, width=64, height=48)
    return arrays, camera


# The suites' budget (docs/power.md): F = 256 frames for the mean; the variance from an
# independent run of 4 F (the second stage of the suites' two-stage test), pooled with the mean
# run's own.
FRAMES = 256


def test_the_z_test_accepts_an_unbiased_estimator_and_rejects_a_two_percent_bias():
    """Algorithm 1's mean over 256 frames passes against the exact image; the same estimator
    rendering the scene with every opacity × 1.02 (every α it computes 2 % high: the power
    study's smallest asserted error, docs/power.md) is rejected, and so is 3DGRT's biased depth
    sampling. Measured over seeds 1–8 of this fixture: the unbiased global statistic 0.9–1.9
    and spread ≤ 2.2; × 1.02 global 7.3–9.5 (rejected 8 of 8); × 1.01 global 3.4–5.4 (rejected
    4 of 8): the smallest bias this budget detects reliably is opacity × 1.02."""
    arrays, camera = z_fixture()
    scene = splat.Scene.from_arrays(**arrays)
    reference = splat.render(scene, camera, method="exact", backend="cpu")["color"]
    variance = splat.render(scene, camera, method="stochastic", spp=4 * FRAMES, seed=101, backend="cpu")["variance"]

    def z_test(rendered):
        own = {"mean_variance": rendered["variance"], "variance_frames": 4 * FRAMES}
        return splat.z_test(rendered["color"], variance, reference, frames=FRAMES, **own)

    def stochastic(scene, **options):
        return splat.render(scene, camera, spp=FRAMES, seed=1, backend="cpu", **{"method": "stochastic", **options})

    unbiased = z_test(stochastic(scene))
    assert unbiased["passes"], unbiased
    assert unbiased["tested"] >= 96

    biased = z_test(stochastic(splat.Scene.from_arrays(**dict(arrays, opacities=arrays["opacities"] * 1.02))))
    assert not biased["passes"], biased
    assert any(f.startswith("global") for f in biased["failures"]), biased

    depth_sampling = z_test(stochastic(scene, method="depth-sampling-k", k=1))
    assert not depth_sampling["passes"], depth_sampling

    # The power table's row for these biases: the exact expectation of each biased estimator
    # (the exact render of the scaled scene) says which is visible at this budget.
    def expected(factor):
        scaled = splat.Scene.from_arrays(**dict(arrays, opacities=arrays["opacities"] * factor))
        expectation = splat.render(scaled, camera, method="exact", backend="cpu")["color"]
        return splat.power(expectation, variance, reference, frames=FRAMES)

    two, half, none = expected(1.02), expected(1.005), expected(1.0)
    assert two["visible"] and two["global"] > 6, two
    assert not half["visible"], half
    assert none["global"] == 0 and not none["visible"], none
