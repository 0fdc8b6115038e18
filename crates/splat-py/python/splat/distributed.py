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
from . import render_views as render_views_here


def _render_task(scene: Scene, camera, options: dict) -> dict:
    return render(scene, camera, **options)


def _render_views_task(scene: Scene, cameras: list, options: dict) -> list[dict]:
    return render_views_here(scene, cameras, **options)


def _remote(cpus_per_task: int, function=_render_task):
    try:
        import ray
    except ImportError as error:
        raise SplatError("splat.distributed needs Ray: pip install ray") from error
    if not ray.is_initialized():
        raise SplatError("Ray is not initialised: call ray.init() (a local cluster) or ray.init(address=...) first")
    return ray, ray.remote(num_cpus=cpus_per_task)(function)


def _per_task(options: dict, cpus_per_task: int) -> dict:
    """Each task renders with as many threads as the CPUs Ray reserves for it (the image does
    not depend on the thread count)."""
    if "frames" in options or "all_cameras" in options:
        raise SplatError("give the views or the frame count as arguments, not frames= or all_cameras=")
    return {"threads": cpus_per_task, **options}


def render_views(
    scene: Scene, cameras: Sequence, *, cpus_per_task: int = 1, views_per_task: int = 1, **options
) -> list[dict]:
    """Render each of `cameras` (Camera objects, or (name, Camera) pairs as load_cameras
    gives them) with render()'s `options`, `views_per_task` consecutive views a Ray task; the
    results in the cameras' order. A task renders its views with splat.render_views, so it
    prepares the scene (its BVH, or its GPU arrays) once for all of them: more views a task pay
    that once where a scene is large, fewer spread the views wider."""
    if views_per_task < 1:
        raise SplatError(f"views_per_task = {views_per_task}: give at least 1")
    ray, task = _remote(cpus_per_task, _render_views_task)
    views = [c[1] if isinstance(c, tuple) else c for c in cameras]
    if not all(isinstance(v, Camera) for v in views):
        raise SplatError("cameras: give Camera objects (or the (name, Camera) pairs of load_cameras)")
    options = _per_task(options, cpus_per_task)
    shared = ray.put(scene)
    batches = [views[i : i + views_per_task] for i in range(0, len(views), views_per_task)]
    rendered = ray.get([task.remote(shared, batch, options) for batch in batches])
    return [view for batch in rendered for view in batch]


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
