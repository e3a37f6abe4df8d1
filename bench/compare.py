"""Stage times of this working tree against a git revision, measured in turns.

    python bench/compare.py REV [--scenes cornell_box box_torus] [--preset preview]
                                [--size 256] [--repeats 5] [--rounds 2] [--device cpu]
                                [--tag TAG]

Checks REV out in a temporary git worktree (or, where REV is a folder
holding a ``gpu_core``, takes that tree as it is: a copy on a machine
without git) and renders the snapshots of
``bench/frame_snapshot.py save`` (``.cache/snapshots/``) through each
tree's own ``gpu_core``, alternating the two, ``--rounds`` times: each turn
a fresh process, one warm-up render, then the median of ``--repeats`` of
each stage's milliseconds (no denoiser). On a shared, noisy machine turns
that alternate put the same load on both sides; a change smaller than the
spread between rounds of one side is not a change. Each turn prints the
``gpu_core`` it imported, so that the two sides are known to differ (a
script that imports a module of this repository's ``bench/`` before
``gpu_core`` gets this tree's package whatever its working directory).
Writes bench/results/compare_REV[_TAG].txt (REV a folder: its name).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from dataclasses import replace

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results")
SNAPSHOTS = os.path.join(ROOT, ".cache", "snapshots")
GI_STAGES = ("photons", "shading_points", "sample_points", "cut", "gather", "interpolate", "caustics")


def measure(tree: str, snapshot: str, preset: str, size: int, repeats: int, device_spec: str | None) -> dict:
    """Median stage milliseconds of ``repeats`` renders through the gpu_core
    of ``tree`` (this process imports it before anything else of the repository)."""
    sys.path.insert(0, tree)  # imported here, first: the package of ``tree``, not of this file's tree
    import gpu_core
    from gpu_core.device import get_device
    from gpu_core.renderer import Renderer

    sys.path.insert(1, os.path.join(ROOT, "bench"))
    from frame_snapshot import load

    shot = load(snapshot)
    scene, settings = shot["exports"][size], replace(shot["settings"][preset], denoise=False)
    device = get_device(device_spec)
    Renderer(device).render(scene, settings)  # warm-up: programs built, launch shapes seen
    runs = [Renderer(device).render(scene, settings).stats["ms"] for _ in range(repeats)]
    stages = {name: statistics.median(run.get(name, 0.0) for run in runs) for name in runs[0]}
    return dict(gpu_core=os.path.dirname(gpu_core.__file__), stages=stages)


def turn(tree: str, args, scene: str) -> dict:
    """One measuring process for ``tree``."""
    command = [sys.executable, os.path.abspath(__file__), "--measure", tree, "--snapshot",
               os.path.join(SNAPSHOTS, f"{scene}.pkl"), "--preset", args.preset, "--size", str(args.size),
               "--repeats", str(args.repeats)] + (["--device", args.device] if args.device else [])
    done = subprocess.run(command, capture_output=True, text=True, cwd=tree)
    if done.returncode != 0:
        sys.exit(f"measuring {scene} in {tree} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def summary(name: str, rows: list[dict]) -> str:
    """One side's line: per stage the medians of its rounds, then the sum
    of the GI stages (the kd-tree, which the image needs too, left out)."""
    def rounds(values) -> str:
        return "/".join(f"{v:.1f}" for v in values)

    keys = list(rows[0]["stages"])
    cells = [f"{k} {rounds(r['stages'].get(k, 0.0) for r in rows)}" for k in keys]
    gi = rounds(sum(r["stages"].get(k, 0.0) for k in GI_STAGES) for r in rows)
    return f"{name}: " + ", ".join(cells) + f" | GI stages {gi}"


def compare(base: str, args) -> list[str]:
    """Per scene, ``args.rounds`` rounds of a turn of ``base`` then one of
    this tree; the two sides' summary lines."""
    lines = []
    for scene in args.scenes:
        sides = {"base": [], "this": []}
        for _ in range(args.rounds):
            for side, tree in (("base", base), ("this", ROOT)):
                row = turn(tree, args, scene)
                if not os.path.realpath(row["gpu_core"]).startswith(os.path.realpath(tree)):
                    sys.exit(f"the {side} turn imported {row['gpu_core']}, not the gpu_core of {tree}")
                sides[side].append(row)
        for side, rows in sides.items():
            lines.append(summary(f"{scene} {side}", rows))
            print(lines[-1], flush=True)
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("rev", nargs="?", help="the git revision (or a folder holding a gpu_core) to compare with")
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "box_torus"])
    parser.add_argument("--preset", default="preview", choices=("draft", "preview", "final"))
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--device", default=None, help="OpenCL device spec (default: GPUGI_DEVICE, else the CPU)")
    parser.add_argument("--tag", default="", help="suffix of the output file")
    parser.add_argument("--measure", metavar="TREE", help=argparse.SUPPRESS)
    parser.add_argument("--snapshot", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.snapshot, args.preset, args.size, args.repeats, args.device)))
        return 0
    if not args.rev:
        parser.error("a git revision to compare with is needed")
    missing = [s for s in args.scenes if not os.path.exists(os.path.join(SNAPSHOTS, f"{s}.pkl"))]
    if missing:
        sys.exit(f"no snapshot of {', '.join(missing)}: run bench/frame_snapshot.py save first")
    from machine import describe

    lines = [describe(), f"{args.preset} at {args.size}², medians of {args.repeats} renders per turn, "
             f"{args.rounds} rounds, turns alternating; this tree against {args.rev}"]
    print("\n".join(lines), flush=True)
    if os.path.isdir(os.path.join(args.rev, "gpu_core")):
        lines += compare(os.path.abspath(args.rev), args)
        name = os.path.basename(os.path.normpath(args.rev))
    else:
        with tempfile.TemporaryDirectory(prefix="gpugi-compare-") as scratch:
            base = os.path.join(scratch, "base")
            subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", "-q", base, args.rev], check=True)
            try:
                lines += compare(base, args)
            finally:
                subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", base], check=False)
        name = args.rev.replace("/", "_")
    os.makedirs(RESULTS, exist_ok=True)
    path = os.path.join(RESULTS, f"compare_{name}{'_' + args.tag if args.tag else ''}.txt")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {os.path.relpath(path, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
