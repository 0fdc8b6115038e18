#!/usr/bin/env python3
"""Where a CPU render spends its time, by the source file of splat-core that each sample's
innermost inlined frame belongs to (the traversal, the decisions, the hit test are all inlined
into one function, so a profile by symbol says nothing).

    CARGO_PROFILE_RELEASE_DEBUG=line-tables-only CARGO_TARGET_DIR=target/prof \
        cargo build --release -p splat-cli
    perf record -o perf.data target/prof/release/splat render SCENE --method stochastic ...
    python3 xtask/perf_by_source.py perf.data target/prof/release/splat

Needs perf, nm and addr2line (binutils). Prints each part's share of the samples taken in the
binary (the kernel's and the C library's are listed apart).
"""

import collections
import subprocess
import sys

# splat-core source files (as their path ends) and the part of a render they are.
PARTS = [
    ("bvh/wide.rs", "BVH traversal (4-wide node tests, stack)"),
    ("bvh/mod.rs", "BVH traversal (4-wide node tests, stack)"),
    ("bvh/build.rs", "BVH build"),
    ("rng.rs", "decisions (xxhash32, PCG)"),
    ("hit.rs", "particle hit test (Eq. 2, the response)"),
    ("kernel.rs", "particle hit test (Eq. 2, the response)"),
    ("trace/stochastic.rs", "the method's visitor (ids, bounds, best hits)"),
    ("trace/kbuffer.rs", "the method's visitor (ids, bounds, best hits)"),
    ("trace/mod.rs", "the method's visitor (ids, bounds, best hits)"),
    ("composite.rs", "shading and compositing (SH, Eq. 3)"),
    ("sh.rs", "shading and compositing (SH, Eq. 3)"),
    ("frame.rs", "frame loop, camera rays, accumulation"),
    ("camera.rs", "frame loop, camera rays, accumulation"),
    ("camera_sampling.rs", "frame loop, camera rays, accumulation"),
]


def run(args):
    return subprocess.run(args, capture_output=True, text=True, check=True).stdout


def main(data, binary):
    symbols = {}
    for line in run(["nm", binary]).splitlines():
        parts = line.split()
        if len(parts) == 3:
            symbols[parts[2]] = int(parts[0], 16)
    samples = collections.Counter()
    elsewhere = collections.Counter()
    bases = collections.Counter()
    for line in run(["perf", "script", "-i", data, "--no-demangle", "-F", "ip,sym,symoff,dso"]).splitlines():
        parts = line.split()
        if len(parts) < 3:
            continue
        ip, symoff, dso = int(parts[0], 16), parts[1], parts[-1]
        if not dso.endswith("/" + binary.rsplit("/", 1)[-1] + ")"):
            elsewhere[dso.strip("()").rsplit("/", 1)[-1]] += 1
            continue
        sym, _, off = symoff.rpartition("+0x")
        if sym in symbols:
            bases[ip - int(off, 16) - symbols[sym]] += 1
        samples[ip] += 1
    if not bases:
        sys.exit("no sample of the binary could be placed (was it built with line tables?)")
    base = bases.most_common(1)[0][0]
    ips = list(samples)
    out = run(["addr2line", "-i", "-a", "-e", binary] + [hex(ip - base) for ip in ips]).splitlines()
    frames, chains = None, []
    for line in out:
        if line.startswith("0x"):
            frames = []
            chains.append(frames)
        else:
            frames.append(line)
    parts = collections.Counter()
    for ip, chain in zip(ips, chains):
        part = "other (std, rayon, the CLI)"
        for location in chain:
            path = location.split(" ")[0].rsplit(":", 1)[0]
            if "splat-core/src/" in path:
                tail = path.split("splat-core/src/", 1)[1]
                part = next((p for f, p in PARTS if tail == f), "splat-core: " + tail)
                break
        parts[part] += samples[ip]
    total = sum(samples.values()) + sum(elsewhere.values())
    print(f"{total} samples; in {binary.rsplit('/', 1)[-1]}: {sum(samples.values())}")
    for part, n in parts.most_common():
        print(f"{100 * n / total:5.1f} %  {part}")
    for dso, n in elsewhere.most_common(4):
        print(f"{100 * n / total:5.1f} %  ({dso})")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
