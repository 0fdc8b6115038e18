"""Renders spread over a Ray cluster (https://www.ray.io): the views of a camera set, or the
frames of one view, as Ray tasks whose results equal the single-process render.

Every stochastic decision is keyed by (pixel, frame, particle, slot) and every frame by its
index in the run, so a view renders the same in any task, and the shares of a run's frames
(``frames="A..B"``) merge into the run: equal bit for bit where every frame is the same, within
one f32 ulp of the mean (the shares' means are rounded to f32 before the merge) where they
differ. The scene is put into Ray's object store once; each task rebuilds it from there.

Ray is not a dependency of the package: ``pip install ray`` where these functions run, and
``ray.init(...)`` (a local cluster by default) before calling them.
"""

from __future__ import annotations

from typing import Sequence

from . import Camera, Scene, SplatError, merge, render


def _render_task(scene: Scene, camera, options: dict) -> dict:
    return render(scene, camera, **options)


def _remote(cpus_per_task: int):
    try:
        import ray
    except ImportError as error:
        raise SplatError("splat.distributed needs Ray: pip install ray") from error
    if not ray.is_initialized():
        raise SplatError("Ray is not initialised: call ray.init() (a local cluster) or ray.init(address=...) first")
    return ray, ray.remote(num_cpus=cpus_per_task)(_render_task)


def _per_task(options: dict, cpus_per_task: int) -> dict:
    """Each task renders with as many threads as the CPUs Ray reserves for it (the image does
    not depend on the thread count)."""
    if "frames" in options or "all_cameras" in options:
        raise SplatError("give the views or the frame count as arguments, not frames= or all_cameras=")
    return {"threads": cpus_per_task, **options}


def render_views(scene: Scene, cameras: Sequence, *, cpus_per_task: int = 1, **options) -> list[dict]:
    """Render each of `cameras` (Camera objects, or (name, Camera) pairs as load_cameras
    gives them) as a Ray task with render()'s `options`; the results in the cameras' order."""
    ray, task = _remote(cpus_per_task)
    views = [c[1] if isinstance(c, tuple) else c for c in cameras]
    if not all(isinstance(v, Camera) for v in views):
        raise SplatError("cameras: give Camera objects (or the (name, Camera) pairs of load_cameras)")
    options = _per_task(options, cpus_per_task)
    shared = ray.put(scene)
    return ray.get([task.remote(shared, view, options) for view in views])


def render_frames(
    scene: Scene, camera=None, *, frames: int, tasks: int, cpus_per_task: int = 1, **options
) -> dict:
    """Render frames 0..`frames` of one view (the run seeded by seed=) as `tasks` Ray tasks of
    contiguous shares, merged: the render of ``render(scene, camera, spp=frames, ...)``."""
    if not 1 <= tasks <= frames:
        raise SplatError(f"tasks = {tasks}: give between 1 and frames = {frames} tasks")
    if "spp" in options:
        raise SplatError("give the frame count as frames=, not spp=")
    ray, task = _remote(cpus_per_task)
    options = _per_task(options, cpus_per_task)
    cuts = [frames * i // tasks for i in range(tasks + 1)]
    shared = ray.put(scene)
    shares = [task.remote(shared, camera, {**options, "frames": f"{a}..{b}"}) for a, b in zip(cuts, cuts[1:])]
    return merge(ray.get(shares))
