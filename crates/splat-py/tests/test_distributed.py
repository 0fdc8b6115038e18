"""Past one machine from Python: shares of a run merged equal the run; scenes and cameras
pickle exactly; a local Ray cluster (2 CPUs, real worker processes) renders a camera set and
the frames of one view equal to the single-process render."""

from __future__ import annotations

import os
import pickle

import numpy as np
import pytest
import splat
from conftest import missing, raw_gaussians

WIDTH, HEIGHT = 32, 24


def ulps(a: np.ndarray, b: np.ndarray) -> int:
    """The largest distance in units of the last place between two float32 arrays."""
    ia, ib = a.astype(np.float32).view(np.int32).astype(np.int64), b.astype(np.float32).view(np.int32).astype(np.int64)
    return int(np.abs(ia - ib).max())


@pytest.fixture(scope="module")
def scene():
    return splat.Scene.from_arrays(**raw_gaussians(np.random.default_rng(2), 40), log_scales=True, logit_opacities=True)


def camera(i: int = 0) -> splat.Camera:
    return splat.Camera.look_at((0.2 * i, 0, 0), (0, 0, 4.5), up=(0, -1, 0), width=WIDTH, height=HEIGHT)


def test_shares_merge_into_the_run(scene):
    """render(frames="A..B") shares merged (in any order) equal the run within one ulp of the
    mean; a deterministic render bit for bit; shares of another seed are refused."""
    options = {"method": "stochastic", "seed": 9, "backend": "cpu"}
    whole = splat.render(scene, camera(), spp=10, **options)
    shares = [splat.render(scene, camera(), frames=f, **options) for f in ("6..10", "0..4", "4..6")]
    merged = splat.merge(shares)
    assert (merged["first"], merged["count"]) == (0, 10) and (whole["first"], whole["count"]) == (0, 10)
    assert ulps(merged["color"], whole["color"]) <= 1
    np.testing.assert_allclose(merged["variance"], whole["variance"], rtol=1e-5, atol=1e-9)
    # The merged variance gives the z-test one run's variance gives.
    reference = splat.render(scene, camera(), method="exact", backend="cpu")["color"]
    variance = splat.render(scene, camera(), spp=40, seed=11, method="stochastic", backend="cpu")["variance"]
    one, joined = (splat.z_test(r["color"], variance, reference, 10, r["variance"], 40) for r in (whole, merged))
    for key in ("global", "spread", "outliers", "variance"):
        assert joined[key] == pytest.approx(one[key], rel=1e-4, abs=1e-6), key
    other = splat.render(scene, camera(), frames="10..12", method="stochastic", seed=8, backend="cpu")
    with pytest.raises(splat.SplatError, match="shares of different renders"):
        splat.merge([merged, other])
    exact = [splat.render(scene, camera(), method="exact", frames=f, backend="cpu") for f in ("0..3", "3..5")]
    assert [e["count"] for e in exact] == [1, 1]
    with pytest.raises(splat.SplatError, match="leave frames 1..3 out"):
        splat.merge(exact)


def test_scenes_and_cameras_pickle_exactly(scene, tmp_path):
    for original in (scene, splat.Scene.demo()):
        copy = pickle.loads(pickle.dumps(original))
        a = splat.render(original, camera(), method="exact", backend="cpu")["color"]
        np.testing.assert_array_equal(splat.render(copy, camera(), method="exact", backend="cpu")["color"], a)
    view = camera(3)
    copy = pickle.loads(pickle.dumps(view))
    np.testing.assert_array_equal(copy.viewmat, view.viewmat)
    np.testing.assert_array_equal(copy.K, view.K)


@pytest.fixture(scope="module")
def ray_cluster():
    """A local Ray cluster of 2 CPUs with real worker processes."""
    try:
        import ray
    except ImportError:
        missing("ray is not installed: pip install -r crates/splat-py/requirements-test.txt")
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def test_ray_renders_a_camera_set_equal_to_one_process(scene, ray_cluster):
    """Eight views as Ray tasks: each equal bit for bit to its render in this process, and the
    tasks ran in other processes."""
    from splat import distributed

    views = [camera(i) for i in range(8)]
    options = {"method": "stochastic", "spp": 4, "seed": 3, "backend": "cpu"}
    remote = distributed.render_views(scene, views, **options)
    batched = distributed.render_views(scene, views, views_per_task=3, **options)
    assert len(remote) == len(batched) == 8
    for view, result, in_batch in zip(views, remote, batched):
        here = splat.render(scene, view, **options)["color"]
        np.testing.assert_array_equal(result["color"], here)
        np.testing.assert_array_equal(in_batch["color"], here, err_msg="a view of a batch of 3 differs")
    with pytest.raises(splat.SplatError, match="views_per_task = 0"):
        distributed.render_views(scene, views, views_per_task=0)

    @ray_cluster.remote
    def pid():
        return os.getpid()

    assert os.getpid() not in set(ray_cluster.get([pid.remote() for _ in range(4)]))


def test_ray_renders_the_frames_of_one_view_equal_to_one_process(scene, ray_cluster):
    """64 frames as 4 tasks of 16, merged: the 64-frame render within one ulp of the mean."""
    from splat import distributed

    options = {"method": "stochastic", "seed": 5, "backend": "cpu"}
    merged = distributed.render_frames(scene, camera(1), frames=64, tasks=4, **options)
    whole = splat.render(scene, camera(1), spp=64, **options)
    assert merged["count"] == 64
    assert ulps(merged["color"], whole["color"]) <= 1
    np.testing.assert_allclose(merged["variance"], whole["variance"], rtol=1e-5, atol=1e-9)
    with pytest.raises(splat.SplatError, match="give between 1 and frames"):
        distributed.render_frames(scene, camera(1), frames=4, tasks=8)
