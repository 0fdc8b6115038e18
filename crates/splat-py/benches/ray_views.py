"""Ray against one process: 64 views of the bonsai capture rendered by splat.render in this
process (all cores to each view) and as 64 Ray tasks on a local cluster (one core to each),
with the overhead of a Ray task measured on tasks that render nothing.

    target/python/bin/python crates/splat-py/benches/ray_views.py [--cpus N] [--views N]

Prints wall times, the speed-up and the overhead per task; the ratio, not the times, is the
result (the same run, the same machine)."""

from __future__ import annotations

import argparse
import os
import time

import ray
import splat
from splat import distributed

parser = argparse.ArgumentParser()
parser.add_argument("--cpus", type=int, default=os.cpu_count())
parser.add_argument("--views", type=int, default=64)
parser.add_argument("--capture", default="target/assets/bonsai-7k-mini.splat")
parser.add_argument("--size", default="160x100")
args = parser.parse_args()
width, height = map(int, args.size.split("x"))

scene = splat.Scene.load(args.capture)
views = [
    splat.Camera.look_at((4 * (i / args.views - 0.5), -1.5, 4), (0, 0.5, 0), up=(0, -1, 0), width=width, height=height)
    for i in range(args.views)
]
options = {"method": "stochastic", "spp": 4, "seed": 1, "backend": "cpu"}

start = time.perf_counter()
local = [splat.render(scene, view, threads=args.cpus, **options) for view in views]
one_process = time.perf_counter() - start

os.environ.setdefault("RAY_AUTH_MODE", "disabled")
ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False, configure_logging=False)
distributed.render_views(scene, views[: args.cpus], **options)  # workers started and warm
start = time.perf_counter()
remote = distributed.render_views(scene, views, **options)
on_ray = time.perf_counter() - start


@ray.remote(num_cpus=1)
def nothing(scene_ref):
    return 0


shared = ray.put(scene)
ray.get([nothing.remote(shared) for _ in range(args.cpus)])
start = time.perf_counter()
ray.get([nothing.remote(shared) for _ in range(args.views)])
overhead = (time.perf_counter() - start) * args.cpus / args.views
ray.shutdown()

same = all((a["color"] == b["color"]).all() for a, b in zip(local, remote))
print(f"{args.views} views of {len(scene)} splats at {width}x{height}, stochastic 4 spp, {args.cpus} CPUs")
print(f"one process ({args.cpus} threads a view): {one_process:.2f} s")
print(f"Ray ({args.views} tasks, 1 CPU each):     {on_ray:.2f} s   speed-up {one_process / on_ray:.2f}x")
print(f"Ray task overhead (a task that renders nothing, scene from the object store): {1000 * overhead:.1f} ms")
print(f"images equal bit for bit: {same}")
