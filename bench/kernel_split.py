"""The GI stages' kernels against the image's, in device time: the ratio the
target "GI stages no more than the image" asks about, without the host's
noise.

    python bench/kernel_split.py [--scenes cornell_box box_torus light_area] [--preset preview]
                                 [--repeats 5] [--device cpu] [--tag TAG]

Renders the snapshots of ``bench/frame_snapshot.py save`` (``.cache/snapshots/``,
256²) through this tree's gpu_core on a queue with profiling on (as
``bench/frame_profile.py``): one warm-up render, then ``--repeats`` renders,
each a fresh renderer as F12 has. Per render, every kernel's device time
(its profiling event, start to end) goes to one of three sums: the image
(``Image_*`` kernels), the scene's kd-tree build (kernels launched from
``accel/kdtree_build.py``) and the GI stages (every other kernel: photons,
point trees, cache points, cut, gather, interpolation, caustics). Prints the
medians and the ratio GI / image. On a shared host the device time of the
kernels is steadier than the stages' wall time; run it in two trees in
turns (``git worktree``) to compare two revisions. Writes
bench/results/kernel_split[_TAG].json and .txt.
"""

from __future__ import annotations

import argparse
import collections
import os
import statistics
import sys
from dataclasses import replace

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from frame_profile import Profile, profiling_device  # noqa: E402
from frame_snapshot import SNAPSHOTS, load  # noqa: E402
from machine import describe  # noqa: E402
from report import write_results  # noqa: E402

from gpu_core.renderer import Renderer  # noqa: E402


def part(where: str, kernel: str) -> str:
    """Which sum a kernel launched from module ``where`` goes to."""
    if kernel.startswith("Image_"):
        return "image"
    return "kdtree" if where.startswith("accel/kdtree_build.py") else "gi"


def split(device, profile: Profile, scene, settings, repeats: int) -> dict:
    """Median device milliseconds of each part over ``repeats`` renders."""
    Renderer(device).render(scene, settings)
    sums = collections.defaultdict(list)
    for _ in range(repeats):
        profile.events.clear()
        profile.active = True
        Renderer(device).render(scene, settings)
        device.queue.finish()
        profile.active = False
        per_part = collections.Counter()
        for where, kernel, event in profile.events:
            per_part[part(where, kernel)] += (event.profile.end - event.profile.start) * 1e-6
        for name in ("gi", "image", "kdtree"):
            sums[name].append(per_part[name])
    return {name: statistics.median(values) for name, values in sums.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "box_torus", "light_area"])
    parser.add_argument("--preset", default="preview", choices=("draft", "preview", "final"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default=None)
    parser.add_argument("--tag", default="")
    args = parser.parse_args()
    profile = Profile()
    profile.install()
    device = profiling_device(args.device)
    machine = describe(device)
    lines = [machine, f"{args.preset} at 256², device ms, medians of {args.repeats} renders", "",
             "| scene | GI stages' kernels | image kernels | kd-tree build | GI / image |",
             "| --- | ---: | ---: | ---: | ---: |"]
    rows = []
    for name in args.scenes:
        shot = load(os.path.join(SNAPSHOTS, name + ".pkl"))
        ms = split(device, profile, shot["exports"][256], replace(shot["settings"][args.preset], denoise=False),
                   args.repeats)
        rows.append(dict(scene=name, **ms, ratio=ms["gi"] / max(ms["image"], 1e-9)))
        lines.append(f"| {name} | {ms['gi']:.1f} | {ms['image']:.1f} | {ms['kdtree']:.1f} | {rows[-1]['ratio']:.2f} |")
        print(lines[-1], flush=True)
    write_results("kernel_split" + (f"_{args.tag}" if args.tag else ""), rows, lines)


if __name__ == "__main__":
    main()
