"""How fast Esc stops a render, stage by stage.

The scene (``large_scene`` by default, exported through the add-on) is
rendered once in GI mode at the preset to learn its stages' timeline (the
render's stage timers, in the order they ran). Then it is rendered again and
again by a fresh renderer (so every stage runs), with a stop requested
``delay`` seconds after the render starts, for delays stepping through the
whole render: the latency is the time from the request to the
RenderCancelled exception, and it is put down to the stage running when the
request was made. The worst and median latency per stage are printed.

    python bench/cancel.py [--scene large_scene] [--size 256] [--preset preview] [--step 0.05] [--quick]

Writes bench/results/cancel[_quick].txt and .json.
"""

from __future__ import annotations

import argparse
import statistics
import time

from bpy_render import load_bpy, open_scene
from machine import describe
from report import write_results


def timeline(ms: dict) -> list[tuple[str, float, float]]:
    """(stage, start s, end s) from a render's stage milliseconds, in the order they ran."""
    out, start = [], 0.0
    for stage, value in ms.items():
        out.append((stage, start, start + value / 1e3))
        start += value / 1e3
    return out


def stage_at(stages: list[tuple[str, float, float]], t: float) -> str:
    return next((name for name, start, end in stages if start <= t < end), "after the stages")


def cancelled_after(device, scene, settings, delay: float) -> float | None:
    """Seconds from a stop requested ``delay`` s into a fresh render to
    RenderCancelled; None when the render finished first."""
    from gpu_core.errors import RenderCancelled
    from gpu_core.renderer import Renderer

    began = time.perf_counter()
    try:
        Renderer(device).render(scene, settings, should_stop=lambda: time.perf_counter() - began >= delay)
    except RenderCancelled:
        return time.perf_counter() - began - delay
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="large_scene")
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--preset", default="preview", choices=["draft", "preview", "final", "reference"])
    parser.add_argument("--step", type=float, default=0.05, help="seconds between two requested stops")
    parser.add_argument("--quick", action="store_true", help="the Cornell box at 64 px, Draft, steps of 0.1 s")
    args = parser.parse_args()
    if args.quick:
        args.scene, args.size, args.preset, args.step = "cornell_box", 64, "draft", 0.1
    bpy = load_bpy()
    from blender_addon.export import export_scene
    from gpu_core.device import get_device
    from gpu_core.renderer import Renderer

    blend = open_scene(bpy, args.scene, args.size)
    blend.gpugi.mode, blend.gpugi.preset = "GI", args.preset.upper()
    settings = blend.gpugi.render_settings()
    scene = export_scene(bpy.context.evaluated_depsgraph_get())
    device = get_device()
    Renderer(device).render(scene, settings)  # programs built and loaded: not part of what is measured
    stages = timeline(Renderer(device).render(scene, settings).stats["ms"])
    total = stages[-1][2]
    by_stage: dict[str, list[float]] = {}
    delay = 0.0
    while delay < total:
        latency = cancelled_after(device, scene, settings, delay)
        if latency is not None:
            by_stage.setdefault(stage_at(stages, delay), []).append(latency)
        delay += args.step
    lines = [f"machine: {describe(device)}; {args.scene} {args.size}x{args.size} px, {args.preset}; render "
             f"{total:.2f} s; a stop every {args.step:.2f} s; latency from the request to RenderCancelled"]
    rows = []
    for name, start, end in stages:
        found = by_stage.get(name, [])
        if not found:
            continue
        rows.append(dict(stage=name, requests=len(found), worst_ms=max(found) * 1e3,
                         median_ms=statistics.median(found) * 1e3, stage_ms=(end - start) * 1e3))
        lines.append(f"{name:16s} {(end - start) * 1e3:7.0f} ms long, {len(found):3d} stops: worst "
                     f"{max(found) * 1e3:6.0f} ms, median {statistics.median(found) * 1e3:6.0f} ms")
    worst = max(rows, key=lambda r: r["worst_ms"]) if rows else None
    if worst:
        lines.append(f"worst: {worst['worst_ms']:.0f} ms in {worst['stage']} (target 250 ms)")
    print("\n".join(lines))
    write_results("cancel_quick" if args.quick else "cancel", dict(machine=lines[0], rows=rows), lines)


if __name__ == "__main__":
    main()
