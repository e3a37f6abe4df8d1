"""F12, animation frames, `blender -b` and material previews: one full render."""

from __future__ import annotations

import time

import numpy as np

from gpu_core.device import get_device
from gpu_core.errors import GpuGiError, RenderCancelled
from gpu_core.renderer import Renderer

from .export import ExportError, export_scene

# What the last final render did, for the command line and tests.
LAST_RUN: dict = {}


def render_final(engine, depsgraph) -> None:
    """Export, render on the device and write the passes; errors are reported."""
    scene = depsgraph.scene
    LAST_RUN.clear()
    settings = scene.gpugi.render_settings(preview=engine.is_preview, transparent=scene.render.film_transparent)
    started = time.perf_counter()
    try:
        engine.update_stats("", "GPU GI: exporting scene")
        gscene = export_scene(depsgraph, should_stop=engine.test_break)
        export_ms = (time.perf_counter() - started) * 1e3
        device = get_device(scene.gpugi.device or None)
        if engine.test_break():
            raise RenderCancelled("render cancelled")

        def progress(fraction: float, message: str) -> None:
            engine.update_progress(fraction)
            engine.update_stats("", f"GPU GI: {message}")

        result = Renderer(device).render(gscene, settings, progress=progress, should_stop=engine.test_break)
    except RenderCancelled:
        LAST_RUN["cancelled"] = True
        return
    except (GpuGiError, ExportError) as err:
        _fail(engine, str(err))
        return
    except Exception as err:  # never let a traceback reach Blender's render job
        _fail(engine, f"internal error ({type(err).__name__}): {err}")
        return
    result.stats["ms"] = {"export": export_ms, **result.stats["ms"]}
    _write_passes(engine, result.passes)
    for warning in result.warnings:
        engine.report({"WARNING"}, f"GPU GI: {warning}")
    LAST_RUN.update(stats=result.stats, warnings=result.warnings)
    engine.update_stats("", "GPU GI: " + format_stage_times(result.stats["ms"]))


def format_stage_times(ms: dict) -> str:
    return ", ".join(f"{name} {value:.0f} ms" for name, value in ms.items())


def _fail(engine, message: str) -> None:
    LAST_RUN["error"] = message
    engine.report({"ERROR"}, f"GPU GI: {message}")
    engine.error_set(f"GPU GI: {message}")


def _write_passes(engine, passes: dict) -> None:
    combined = passes["Combined"]
    height, width = combined.shape[:2]
    result = engine.begin_result(0, 0, width, height)
    try:
        layer = result.layers[0]
        for name, pixels in passes.items():
            target = layer.passes.find_by_name(name, "")
            if target is None:
                continue
            flat = np.ascontiguousarray(pixels, np.float32).reshape(height * width, -1)
            if flat.shape[1] != target.channels:
                continue
            target.rect.foreach_set(flat.ravel())
    finally:
        engine.end_result(result)
