"""Soak: many F12 renders in one process, host memory sampled.

Renders a scene of ``blend_scenes/`` ``--renders`` times through Blender's
render operator (the add-on's F12 path: export, renderer, passes written),
moving the camera a little each time and changing the first light's power
every tenth render, with Persistent Data off (every render starts afresh
and gives its device memory back) or on (``--persistent``: one renderer
kept). Prints the resident memory every ``--every`` renders and the
growth from the first sample to the last.

    python bench/soak.py [--scene cornell_box] [--size 64] [--renders 200] [--every 20] [--persistent]

Writes bench/results/soak[_persistent].json and .txt.
"""

from __future__ import annotations

import argparse
import gc
import time

from bpy_render import load_bpy, open_scene
from machine import describe
from report import write_results


def rss_mb() -> float:
    import os

    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="cornell_box")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--renders", type=int, default=200)
    parser.add_argument("--every", type=int, default=20)
    parser.add_argument("--persistent", action="store_true")
    args = parser.parse_args()
    bpy = load_bpy()
    scene = open_scene(bpy, args.scene, args.size)
    scene.render.engine = "GPUGI"
    scene.gpugi.mode, scene.gpugi.preset = "GI", "PREVIEW"
    scene.render.use_persistent_data = args.persistent
    light = next((o.data for o in scene.objects if o.type == "LIGHT"), None)
    from blender_addon.final import LAST_RUN

    samples, errors, began = [], 0, time.perf_counter()
    for number in range(1, args.renders + 1):
        scene.camera.location.x += 0.01 if number % 2 else -0.01
        if light is not None and number % 10 == 0:
            light.energy *= 1.1 if number % 20 else 1 / 1.1
        bpy.ops.render.render(scene=scene.name)
        errors += bool(LAST_RUN.get("error"))
        if number % args.every == 0 or number == 1:
            gc.collect()
            samples.append({"renders": number, "rss_mb": round(rss_mb(), 1),
                            "device_mb": round(LAST_RUN.get("stats", {}).get("device_bytes", 0) / 2**20, 1)})
            print(samples[-1], flush=True)
    seconds = time.perf_counter() - began
    growth = samples[-1]["rss_mb"] - samples[1]["rss_mb"] if len(samples) > 1 else 0.0
    lines = [f"# {describe()}",
             f"# {args.scene} {args.size}x{args.size}, Preview GI, persistent data {'on' if args.persistent else 'off'}",
             *[str(s) for s in samples],
             f"{args.renders} renders in {seconds:.0f} s, {errors} errors; resident memory from render "
             f"{samples[1]['renders'] if len(samples) > 1 else 1} to {args.renders}: {growth:+.1f} MB"]
    print(lines[-1])
    write_results("soak" + ("_persistent" if args.persistent else ""),
                  {"machine": describe(), "samples": samples, "errors": errors, "seconds": seconds,
                   "growth_mb": growth}, lines)


if __name__ == "__main__":
    main()
