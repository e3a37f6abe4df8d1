"""Where a kd-tree build's time goes: the device time of each of its
kernels, and its large-node stage level by level.

    python bench/kdtree_profile.py [--triangles 636160] [--case soup] [--repeats 3] [--device cpu] [--tag TAG]

Builds one mesh of ``bench/kdtree.py`` (a blob mesh of about
``--triangles``, or one of its worst cases by the start of its name) on a
queue with profiling on, the launched build (no one-work-item build, no
leaf blocks' effect on the stage times: blocks are made as the device
wants them). One warm-up build, then ``--repeats`` measured ones: per
kernel the median device time. Then, for one more build, each large-node
level: its active nodes, how many of them are divided at a spatial median,
cut off empty space or become leaves, its elements (every element of every
active node passes through the level's bounds, classification and
scatter), the elements that went to both sides of their node's plane
(straddlers kept on both), and the level's wall time (the queue finished
before and after), and the empty-space cuts its nodes chained before
their last decision (kdtree_build.cl, KdBuild_large_split_at). Writes ``bench/results/kdtree_profile[_TAG].txt``.
"""

from __future__ import annotations

import argparse
import collections
import os
import statistics
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from frame_profile import Profile, profiling_device  # noqa: E402
from kdtree import blob_mesh, worst_cases  # noqa: E402
from machine import describe  # noqa: E402

from gpu_core.accel import kdtree, kdtree_build  # noqa: E402

RESULTS = os.path.join(ROOT, "bench", "results")
KINDS = ("median", "cut low", "cut high", "leaf")  # kdtree_build.cl: KD_SPLIT_MEDIAN, KD_CUT_LOW, KD_CUT_HIGH, KD_SPLIT_NONE


def kernel_times(device, triangles: np.ndarray, repeats: int) -> tuple[dict, float]:
    """Median device ms per kernel over ``repeats`` builds, and the median build wall ms."""
    profile = Profile()
    profile.install()
    per_kernel, walls = collections.defaultdict(list), []
    for _ in range(repeats):
        profile.events.clear()
        profile.active = True
        began = time.perf_counter()
        kdtree.build(device, triangles)
        device.queue.finish()
        walls.append((time.perf_counter() - began) * 1e3)
        profile.active = False
        for name, ms in profile.kernel_times().items():
            per_kernel[name].append(ms)
    medians = {name: statistics.median(ms) for name, ms in per_kernel.items()}
    return dict(sorted(medians.items(), key=lambda item: -item[1])), statistics.median(walls)


def levels(device, triangles: np.ndarray) -> list[dict]:
    """One build's large-node levels (see the module's docstring)."""
    rows, build_class = [], kdtree_build._Build
    plain_level, plain_kernel = build_class._large_level, build_class.kernel

    def kernel(self, name):
        launch = plain_kernel(self, name)
        if name != "KdBuild_large_split":
            return launch

        def split(n, *args):
            launch(n, *args)
            # KdBuild_large_split's arguments: ..., n (6), max_depth, chain, node_split, node_mode (10), node_chain
            count, node_mode, node_chain = int(args[6]), args[10], args[11]
            kinds = device.read(node_mode, count, np.int32) >> 2
            rows[-1]["kinds"] = [int((kinds == k).sum()) for k in range(len(KINDS))]
            rows[-1]["chained"] = int(device.read(node_chain, count, np.int32).sum())
        return split

    def level(self):
        device.queue.finish()
        before = (self.active, self.elements, self.small_count, self.leaf_count)
        rows.append({"nodes": before[0], "elements": before[1]})
        began = time.perf_counter()
        plain_level(self)
        device.queue.finish()
        sent = self.elements + (self.small_count - before[2]) + (self.leaf_count - before[3])
        rows[-1].update(both_sides=sent - before[1], ms=(time.perf_counter() - began) * 1e3)

    build_class._large_level, build_class.kernel = level, kernel
    try:
        kdtree.build(device, triangles)
    finally:
        build_class._large_level, build_class.kernel = plain_level, plain_kernel
    return rows


def level_table(rows: list[dict]) -> str:
    lines = ["| level | nodes | chained cuts | " + " | ".join(KINDS) + " | elements | both sides | ms |",
             "|---" * (6 + len(KINDS)) + "|"]
    for i, r in enumerate(rows, 1):
        kinds = " | ".join(str(k) for k in r.get("kinds", [0] * len(KINDS)))
        lines.append(f"| {i} | {r['nodes']} | {r.get('chained', 0)} | {kinds} | {r['elements']} | {r['both_sides']} | "
                     f"{r['ms']:.2f} |")
    total = sum(r["elements"] for r in rows)
    both = sum(r["both_sides"] for r in rows)
    lines.append(f"| all {len(rows)} | | {sum(r.get('chained', 0) for r in rows)} |" + " |" * len(KINDS) + f" {total} | {both} | "
                 f"{sum(r['ms'] for r in rows):.1f} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--triangles", type=int, default=650_000, help="blob mesh size (default 650000: 636,160)")
    parser.add_argument("--case", default="", help="a worst case of bench/kdtree.py by the start of its name")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--device", default=None, help="OpenCL device spec (default: GPUGI_DEVICE, else the CPU)")
    parser.add_argument("--tag", default="")
    args = parser.parse_args()

    if args.case:
        name, triangles = next((k, v) for k, v in worst_cases().items() if k.startswith(args.case))
    else:
        triangles = blob_mesh(args.triangles)
        name = f"blob mesh of {len(triangles):,} triangles"
    triangles = np.ascontiguousarray(triangles, np.float32)
    device = profiling_device(args.device)
    # the launched build, whatever the size: the one-work-item build has no levels to show
    kdtree_build.SERIAL_MAX = 0
    tree = kdtree.build(device, triangles)  # warm-up: programs built, pool filled
    per_kernel, wall = kernel_times(device, triangles, args.repeats)
    rows = levels(device, triangles)
    stats = {k: tree.stats[k] for k in ("nodes", "leaves", "mean_leaf_size", "large_levels", "small_levels")}
    text = "\n".join([
        describe(device), f"{name}: build {wall:.1f} ms (median of {args.repeats}), {stats}",
        "kernels (device ms, medians): " + ", ".join(f"{k} {v:.2f}" for k, v in per_kernel.items() if v >= 0.05),
        f"large-node stage of one more build ({sum(r['ms'] for r in rows):.1f} ms):", level_table(rows)])
    print(text)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "kdtree_profile" + (f"_{args.tag}" if args.tag else "") + ".txt"), "w") as f:
        f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
