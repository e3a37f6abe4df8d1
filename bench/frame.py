"""One frame, stage by stage: every scene, two sizes, every preset, beside Cycles.

For each scene of ``blend_scenes/`` (``--scenes``), each size (``--sizes``,
square) and each preset (``--presets``): GPU GI in GI mode through the bpy
module (F12's path, export included), one warm-up render, then the median
of ``--repeats`` renders of the render call's wall time and of each stage's
milliseconds (the render's stats). In the same run Cycles renders the same
scene and size at the preset's samples (set up like the trade-off
benchmark's: box filter, no clamp, deep bounces, no denoiser), median of
``--repeats``. The Reference preset (1024 samples) is rendered once at each
size, and only at the sizes in ``--reference-sizes`` and for the scenes
in ``--reference-scenes`` (Cycles takes minutes at 1024 samples).

A newcomer's first frame, with every cache empty (ours and PoCL's), is
timed once per scene at the first size, Preview, in a fresh process: the
process's wall time and the render's stages.

The image kernel alone, in paths per second: the Reference mode (the path
tracer the GI mode's image kernel is) at the first size and 16 samples,
direct light only (no bounce of any kind, Cycles' Max Bounces 0) and with
deep bounces (12 and 12; Cycles as the reference), against Cycles' samples
per second on the same image; ours counted on the kernel's own time and on
the render call's, Cycles' on the render call's.

    python bench/frame.py [--scenes cornell_box ...] [--sizes 256 512]
        [--presets draft preview final reference] [--reference-scenes ...] [--repeats 3] [--no-cold] [--no-paths]
        [--tag TAG] [--quick]

Writes bench/results/frame[_TAG].json and .txt and the plot
bench/figures/frame[_TAG].png (stages of the first size's Preview frame).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from bpy_render import ROOT, load_bpy, open_scene, render
from machine import describe
from report import write_results

FIGURE = os.path.join(ROOT, "bench", "figures", "frame.png")
SCENES = sorted(name[:-6] for name in os.listdir(os.path.join(ROOT, "blend_scenes")) if name.endswith(".blend"))
PRESETS = ("draft", "preview", "final", "reference")


def ours(bpy, name: str, size: int, preset: str, repeats: int) -> dict:
    """Median wall time and stage milliseconds of GPU GI renders after a warm-up."""
    from blender_addon.final import LAST_RUN

    walls, stages = [], []
    for run in range(repeats + 1):
        scene = open_scene(bpy, name, size)
        scene.gpugi.mode = "GI"
        scene.gpugi.preset = preset.upper()
        _, seconds = render(bpy, scene, "GPUGI")
        if LAST_RUN.get("error"):
            raise RuntimeError(f"{name} {size} {preset}: {LAST_RUN['error']}")
        if run:  # the first render reads the kernels in; it is not timed
            walls.append(seconds)
            stages.append(LAST_RUN["stats"]["ms"])
    keys = [key for key in stages[0] if key not in ("export", "device")] + ["export"]
    return dict(seconds=statistics.median(walls),
                ms={key: statistics.median(s.get(key, 0.0) for s in stages) for key in keys},
                samples=int(LAST_RUN["stats"]["samples"]))


def cycles(bpy, name: str, size: int, samples: int, repeats: int, direct_only: bool = False) -> float:
    """Median wall time of Cycles renders at ``samples`` samples."""
    sys.path.insert(0, os.path.join(ROOT, "tests", "references"))
    from make_references import configure

    times = []
    for _ in range(repeats):
        scene = open_scene(bpy, name, size)
        configure(scene, size, samples, box_filter=True)
        scene.cycles.use_denoising = False
        if direct_only:
            scene.cycles.max_bounces = 0
        times.append(render(bpy, scene, "CYCLES")[1])
    return statistics.median(times)


def paths(bpy, name: str, size: int, repeats: int, direct_only: bool, samples: int = 16) -> dict:
    """Paths per second (millions) of the image kernel and of Cycles, same image."""
    from blender_addon.final import LAST_RUN

    walls, kernels = [], []
    for run in range(repeats + 1):
        scene = open_scene(bpy, name, size)
        settings = scene.gpugi
        settings.mode, settings.samples = "REFERENCE", samples
        settings.max_bounces = settings.diffuse_bounces = 0 if direct_only else 12
        _, seconds = render(bpy, scene, "GPUGI")
        if run:
            walls.append(seconds)
            kernels.append(LAST_RUN["stats"]["ms"]["render"] / 1e3)
    count = size * size * samples / 1e6
    cycles_seconds = cycles(bpy, name, size, samples, repeats, direct_only)
    return dict(kernel=count / statistics.median(kernels), call=count / statistics.median(walls),
                cycles=count / cycles_seconds)


def cold(name: str, size: int) -> dict:
    """A fresh process's first Preview frame with empty kernel caches."""
    with tempfile.TemporaryDirectory() as caches:
        env = dict(os.environ, POCL_CACHE_DIR=os.path.join(caches, "pocl"),
                   GPUGI_KERNEL_CACHE=os.path.join(caches, "kernels"))
        began = time.perf_counter()
        run = subprocess.run([sys.executable, os.path.abspath(__file__), "--first-frame", name, str(size)],
                             env=env, capture_output=True, text=True, timeout=3600)
        seconds = time.perf_counter() - began
    if run.returncode != 0:
        raise RuntimeError(f"cold {name}: {run.stderr[-2000:]}")
    result = json.loads(run.stdout.strip().splitlines()[-1])
    return dict(process_seconds=seconds, **result)


def first_frame(name: str, size: int) -> None:
    """(In the fresh process) render once and print the render's time and stages."""
    bpy = load_bpy()
    from blender_addon.final import LAST_RUN

    scene = open_scene(bpy, name, size)
    scene.gpugi.mode = "GI"
    scene.gpugi.preset = "PREVIEW"
    _, seconds = render(bpy, scene, "GPUGI")
    print(json.dumps(dict(seconds=seconds, ms=LAST_RUN["stats"]["ms"])))


def stage_line(ms: dict) -> str:
    return " ".join(f"{key} {value:.0f}" for key, value in ms.items() if value >= 0.5)


def plot(rows: list[dict], size: int, path: str) -> None:
    """Stacked stage times of each scene's Preview frame at ``size``, Cycles' time beside."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picked = [r for r in rows if r["size"] == size and r["preset"] == "preview"]
    if not picked:
        return
    stages = list(dict.fromkeys(key for r in picked for key in r["ms"]))
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for i, row in enumerate(picked):
        bottom = 0.0
        for j, stage in enumerate(stages):
            value = row["ms"].get(stage, 0.0) / 1e3
            ax.bar(i - 0.2, value, 0.4, bottom=bottom, color=plt.cm.tab20(j % 20), label=stage if i == 0 else None)
            bottom += value
        ax.bar(i + 0.2, row["cycles_seconds"], 0.4, color="0.3", label="Cycles, same samples" if i == 0 else None)
    ax.set_xticks(range(len(picked)), [r["scene"] for r in picked], rotation=30, ha="right")
    ax.set_ylabel("seconds")
    ax.set_title(f"one Preview frame at {size}x{size}: GPU GI stages (left), Cycles (right)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=SCENES, choices=SCENES)
    parser.add_argument("--sizes", nargs="+", type=int, default=[256, 512])
    parser.add_argument("--presets", nargs="+", default=list(PRESETS), choices=PRESETS)
    parser.add_argument("--reference-sizes", nargs="*", type=int, default=[256])
    parser.add_argument("--reference-scenes", nargs="*", default=["box_torus", "caustics", "cornell_box"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-cold", action="store_true", help="skip the first frames with empty caches")
    parser.add_argument("--no-paths", action="store_true", help="skip the image kernel's paths per second")
    parser.add_argument("--quick", action="store_true", help="the Cornell box at 128 px, Preview, one repeat")
    parser.add_argument("--tag", default="", help="suffix of the output files (frame_TAG.txt), for partial runs")
    parser.add_argument("--first-frame", nargs=2, metavar=("SCENE", "SIZE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.first_frame:
        first_frame(args.first_frame[0], int(args.first_frame[1]))
        return
    if args.quick:
        args.scenes, args.sizes, args.presets, args.repeats = ["cornell_box"], [128], ["preview"], 1
    bpy = load_bpy()
    from gpu_core.device import get_device

    lines = [f"machine: {describe(get_device())}; GI mode; medians of {args.repeats} warm renders "
             "(Reference: 1); Cycles at the same samples"]
    print(lines[0], flush=True)
    rows, firsts, rates = [], [], []
    for name in args.scenes:
        if not args.no_cold:
            first = cold(name, args.sizes[0])
            firsts.append(dict(scene=name, size=args.sizes[0], **first))
            line = (f"{name} {args.sizes[0]} first frame, empty caches: process {first['process_seconds']:.1f} s, "
                    f"render {first['seconds']:.1f} s ({stage_line(first['ms'])})")
            print(line, flush=True)
            lines.append(line)
        for direct_only in () if args.no_paths else (True, False):
            rate = paths(bpy, name, args.sizes[0], args.repeats, direct_only)
            rates.append(dict(scene=name, size=args.sizes[0], direct_only=direct_only, **rate))
            line = (f"{name} {args.sizes[0]} image kernel, {'direct light' if direct_only else 'deep bounces'}, "
                    f"16 spp: {rate['kernel']:.2f} M paths/s (render call {rate['call']:.2f}), Cycles "
                    f"{rate['cycles']:.2f} ({rate['kernel'] / rate['cycles']:.2f}x)")
            print(line, flush=True)
            lines.append(line)
        for size in args.sizes:
            for preset in args.presets:
                if preset == "reference" and (size not in args.reference_sizes
                                              or name not in args.reference_scenes):
                    continue
                repeats = 1 if preset == "reference" else args.repeats
                result = ours(bpy, name, size, preset, repeats)
                cycles_seconds = cycles(bpy, name, size, result["samples"], repeats)
                row = dict(scene=name, size=size, preset=preset, cycles_seconds=cycles_seconds, **result)
                rows.append(row)
                line = (f"{name} {size} {preset}: {result['seconds']:.2f} s, Cycles {result['samples']} spp "
                        f"{cycles_seconds:.2f} s ({cycles_seconds / result['seconds']:.2f}x); "
                        f"{stage_line(result['ms'])}")
                print(line, flush=True)
                lines.append(line)
    suffix = "_quick" if args.quick else f"_{args.tag}" if args.tag else ""
    write_results(f"frame{suffix}", dict(machine=lines[0], rows=rows, first_frames=firsts, paths=rates), lines)
    figure = FIGURE.replace(".png", f"{suffix}.png")
    plot(rows, args.sizes[0], figure)
    print(f"plot: {figure}")


if __name__ == "__main__":
    main()
