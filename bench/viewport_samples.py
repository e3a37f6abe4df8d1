"""How soon the Rendered viewport's image of one view is done, and how good
it is then, at each Viewport Noise Threshold.

    python bench/viewport_samples.py [--scenes cornell_box box_torus light_area user_content]
                                     [--thresholds 0 0.005 0.01 0.02 0.05 0.1] [--samples 32] [--repeats 3]

For each scene of ``bench/frame_snapshot.py save`` (``.cache/snapshots/``, the
add-on's export at 256², GI mode, Preview's knobs, a one-pixel box filter as
the references have) the viewport's own worker (blender_addon.viewport
ViewportSession: the coarse pass, then full passes of 1, 1, 2, 4, ... samples
continuing one film) renders the view on a fresh renderer until it is done:
Viewport Samples taken, or every pixel settled below the threshold. Per
threshold: the median wall time from the request to the last image, the
mean samples a pixel took, and the last image's error against Cycles' long
reference (``bench/results/reference_NAME_256_4096.npy``, made by
``bench/tradeoff.py``): relative RMSE of display values and HDR-FLIP.
Threshold 0 is every pixel taking every sample. The first render of a scene
(kernel builds) is not timed. Writes bench/results/viewport_samples[_TAG].json
and .txt.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from frame_snapshot import SNAPSHOTS, load  # noqa: E402
from machine import describe  # noqa: E402
from report import RESULTS, write_results  # noqa: E402
from tradeoff import hdr_flip, relative_rmse  # noqa: E402
from test_gi_vs_cycles import display  # noqa: E402

from blender_addon.viewport import Job, ViewportSession  # noqa: E402
from gpu_core.device import get_device  # noqa: E402
from gpu_core.renderer import Renderer  # noqa: E402
from gpu_core.scene.model import FILTER_BOX  # noqa: E402


def view_done(device, scene, settings) -> tuple[float, np.ndarray, dict]:
    """One view rendered by the viewport's worker on a fresh renderer until
    it is done: seconds, the last image, the last pass's stats."""
    session = ViewportSession(lambda: None, make_renderer=lambda spec: Renderer(device))
    began = time.perf_counter()
    session.update_scene(Job(scene=scene, settings=settings, device_spec=None), signature=("view", 0))
    while session.busy:
        time.sleep(0.002)
    seconds = time.perf_counter() - began
    image, _ = session.latest()
    stats = session.stats
    session.stop()
    if session.error:
        raise RuntimeError(session.error)
    return seconds, image, stats


def run_scene(device, name: str, args) -> list[dict]:
    shot = load(os.path.join(SNAPSHOTS, name + ".pkl"))
    scene = shot["exports"][256]
    scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, filter_kind=FILTER_BOX,
                                                                  filter_width=1.0))
    reference = np.load(os.path.join(RESULTS, f"reference_{name}_256_4096.npy"))
    base = dataclasses.replace(shot["settings"]["preview"], samples=args.samples, denoise=False)
    view_done(device, scene, base)  # kernels built, caches warm
    rows = []
    for threshold in args.thresholds:
        settings = dataclasses.replace(base, preview_noise_threshold=threshold)
        runs = [view_done(device, scene, settings) for _ in range(args.repeats)]
        seconds, image, stats = runs[-1]
        held = stats["accumulated"]
        rgb = image[..., :3]
        row = dict(scene=name, threshold=threshold, seconds=statistics.median(r[0] for r in runs),
                   spread=[min(r[0] for r in runs), max(r[0] for r in runs)], samples=held["samples"],
                   mean_samples=held["mean_samples"], settled=held["converged"],
                   error=relative_rmse(display(rgb), display(reference)), flip=hdr_flip(rgb, reference))
        rows.append(row)
        print(f"{name} threshold {threshold:g}: {row['seconds']:.2f} s, {row['mean_samples']:.1f} of "
              f"{row['samples']} samples a pixel, display error {row['error']:.4f}, HDR-FLIP {row['flip']:.4f}",
              flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "box_torus", "light_area", "user_content"])
    parser.add_argument("--thresholds", nargs="+", type=float, default=[0.0, 0.005, 0.01, 0.02, 0.05, 0.1])
    parser.add_argument("--samples", type=int, default=32, help="Viewport Samples")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--device", default=None)
    parser.add_argument("--tag", default="")
    args = parser.parse_args()
    device = get_device(args.device)
    machine = describe(device)
    print(machine, flush=True)
    rows = [row for name in args.scenes for row in run_scene(device, name, args)]
    lines = [machine, f"Viewport Samples {args.samples}, 256², Preview's GI knobs, medians of {args.repeats}", "",
             "| scene | threshold | seconds (spread) | samples a pixel | display error | HDR-FLIP |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['threshold']:g} | {r['seconds']:.2f} ({r['spread'][0]:.2f}–"
                     f"{r['spread'][1]:.2f}) | {r['mean_samples']:.1f} / {r['samples']} | {r['error']:.4f} | "
                     f"{r['flip']:.4f} |")
    write_results("viewport_samples" + (f"_{args.tag}" if args.tag else ""), rows, lines)
    print("\n".join(lines[2:]))


if __name__ == "__main__":
    main()
