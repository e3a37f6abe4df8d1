"""Flicker: how much the image changes from frame to frame where the
scene does not.

Static: the same view rendered ``--frames`` times, each by a fresh
renderer (photons, cache points and camera paths are seeded per photon,
point and sample, never per frame): the largest per-pixel standard
deviation over the frames (0 = identical images).

Orbit: the view turned ``--step`` degrees per frame about the scene's
vertical axis, the first full-resolution image of each view as the
viewport shows it (GI Preview, one sample per pixel), by one renderer:
with the cache records kept in world space across views (the default),
without (every view cached afresh, as the seed does), and the path tracer
(Reference mode) with as many samples as fit in the GI frame's time. The
statistic is the low-frequency change between consecutive frames: each
frame averaged over 8x8-pixel blocks, the mean absolute difference of
consecutive frames over the mean of the frames. The camera's own motion
changes the image too, by the same amount for every method; what one
method adds over another is its flicker.

    python bench/flicker.py FILE.blend [--size 320x180] [--frames 8] [--step 1.0]

Writes bench/results/flicker_NAME.json and .txt.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

import numpy as np

from bpy_render import load_bpy
from machine import describe
from report import write_results


def blocks(image: np.ndarray, size: int = 8) -> np.ndarray:
    """The image averaged over size x size blocks (the low frequencies)."""
    h, w = (image.shape[0] // size) * size, (image.shape[1] // size) * size
    return image[:h, :w, :3].reshape(h // size, size, w // size, size, 3).mean(axis=(1, 3))


def frame_change(frames: list[np.ndarray]) -> float:
    """Mean absolute change of the 8x8-block images between consecutive frames, over their mean."""
    low = [blocks(f) for f in frames]
    mean = float(np.mean([f.mean() for f in low])) or 1.0
    return float(np.mean([np.abs(b - a).mean() for a, b in zip(low, low[1:])])) / mean


def orbit(camera, degrees: float, center: np.ndarray):
    """``camera`` turned about the vertical axis through ``center``."""
    a = np.radians(degrees)
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    to_center, back = np.eye(4), np.eye(4)
    to_center[:3, 3], back[:3, 3] = -center, center
    return dataclasses.replace(camera, matrix=back @ turn @ to_center @ camera.matrix)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("blend")
    parser.add_argument("--size", default="320x180")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--step", type=float, default=1.0, help="degrees the view turns per frame")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    bpy = load_bpy()
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100

    from blender_addon.export import export_scene
    from gpu_core.device import get_device
    from gpu_core.renderer import Renderer
    from gpu_core.settings import preset

    exported = export_scene(bpy.context.evaluated_depsgraph_get())
    center = exported.triangles.reshape(-1, 3).mean(axis=0)
    device = get_device(None)
    gi = preset("preview", mode="gi", samples=1)
    name = os.path.splitext(os.path.basename(args.blend))[0]
    lines = [f"# {describe(device)}", f"# {name} at {width}x{height}, {args.frames} frames, {args.step} deg per frame"]

    Renderer(device).render(exported, gi)  # programs built before anything is timed
    static = [Renderer(device).render(exported, gi).passes["Combined"][..., :3] for _ in range(args.frames)]
    static_std = float(np.std(np.asarray(static, np.float64), axis=0).max())

    views = [dataclasses.replace(exported, camera=orbit(exported.camera, i * args.step, center))
             for i in range(args.frames)]

    def run(settings) -> tuple[list[np.ndarray], float]:
        renderer = Renderer(device)
        renderer.render(views[0], settings)  # photons and kd-tree ready, as in the viewport after its first image
        frames, seconds = [], []
        for view in views:
            began = time.perf_counter()
            frames.append(renderer.render(view, settings).passes["Combined"][..., :3])
            seconds.append(time.perf_counter() - began)
        return frames, statistics.median(seconds)

    kept, kept_s = run(gi)
    fresh, fresh_s = run(dataclasses.replace(gi, cache_reuse=False))
    probe = preset("preview", mode="reference", samples=1)
    _, one_sample_s = run(probe)
    samples = max(1, int(kept_s / max(one_sample_s, 1e-6)))
    traced, traced_s = run(dataclasses.replace(probe, samples=samples))
    result = {
        "machine": describe(device), "size": [width, height], "frames": args.frames, "step_degrees": args.step,
        "static_max_pixel_std": static_std,
        "orbit": {
            "gi_records_kept": {"frame_change": frame_change(kept), "frame_ms": kept_s * 1e3},
            "gi_every_view_afresh": {"frame_change": frame_change(fresh), "frame_ms": fresh_s * 1e3},
            "path_tracer_equal_time": {"frame_change": frame_change(traced), "frame_ms": traced_s * 1e3,
                                       "samples": samples},
        },
    }
    lines.append(f"static scene, {args.frames} frames: largest per-pixel std {static_std:.3g}")
    for label, row in result["orbit"].items():
        lines.append(f"orbit {label:24s} frame-to-frame low-frequency change {row['frame_change']:.4f}  "
                     f"({row['frame_ms']:.0f} ms per frame" + (f", {row['samples']} spp" if "samples" in row else "")
                     + ")")
    print("\n".join(lines))
    write_results(f"flicker_{name}", result, lines)


if __name__ == "__main__":
    main()
