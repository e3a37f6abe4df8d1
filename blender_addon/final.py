"""F12, animation frames, `blender -b` and material previews: one full render.

Export on Blender's render thread, render with gpu_core in batches (Esc is
polled between them), then write the passes into Blender's render result.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

import numpy as np

from gpu_core.errors import DeviceError, GpuGiError, RenderCancelled

from .export import export_scene
from .device_memory import free_unused_device_memory, release_unused_later, render_started
from .opencl_devices import survey
from .passes import enabled_passes, wants_denoising_passes, wants_light_passes
from .status import format_samples, format_stage_times, mode_line

# What the last final render in this process did: the command line and the
# tests read it ("stats", "warnings", "passes", "error", "cancelled").
LAST_RUN: dict = {}
# Called with each status line a render shows ("compiling kernels 3/9"):
# the command line prints them.
STATUS_LISTENERS: list[Callable[[str], None]] = []
# With Blender's Persistent Data on, the renderer of each scene stays between
# renders (an animation's frames), holding what a later render can reuse:
# the scene on the device, the kd-tree, the photon maps.
_HELD: dict[str, object] = {}
_HELD_LOCK = threading.Lock()
# Within one render job (an animation's frames, between Blender's render_init
# and render_complete or render_cancel) the renderer of each scene is kept
# whatever Persistent Data says: a fly-through traces its photons and builds
# its kd-tree once while only the camera moves. None outside a job.
_JOB: dict[str, object] | None = None


def render_final(engine, depsgraph) -> None:
    """Export, render on the device and write the passes; errors are reported, never raised."""
    LAST_RUN.clear()
    scene = depsgraph.scene
    try:
        result = _render(engine, depsgraph)
        written = write_passes(engine, result.passes, depsgraph.view_layer)
    except RenderCancelled:
        LAST_RUN["cancelled"] = True
        engine.update_stats("", "GPU GI | cancelled")
        return
    except GpuGiError as err:
        _fail(engine, str(err))
        return
    except Exception as err:  # a traceback must never reach Blender's render job
        _fail(engine, f"internal error ({type(err).__name__}): {err}")
        return
    if not engine.is_preview:
        for warning in result.warnings:
            engine.report({"WARNING"}, f"GPU GI: {warning}")
    LAST_RUN.update(stats=result.stats, warnings=result.warnings, passes=written, scene=scene.name)
    engine.update_memory_stats(memory_used=result.stats.get("device_bytes", 0) / 2**20)
    engine.update_stats("", f"GPU GI | {mode_line(result.stats)} | samples {format_samples(result.stats)} | "
                        + format_stage_times(result.stats["ms"]))


def _render(engine, depsgraph):
    """Export and render; the result's stats get the export and device stages."""
    scene = depsgraph.scene
    settings = scene.gpugi.render_settings(preview=engine.is_preview, transparent=scene.render.film_transparent)
    if not engine.is_preview:
        settings.light_passes = wants_light_passes(depsgraph.view_layer)
        settings.denoising_passes = wants_denoising_passes(depsgraph.view_layer)
    engine.update_stats("", "GPU GI | exporting scene")
    started = time.perf_counter()
    gscene = export_scene(depsgraph, camera_object=engine.camera_override, should_stop=engine.test_break)
    export_ms = (time.perf_counter() - started) * 1e3
    if engine.test_break():
        raise RenderCancelled("render cancelled")
    engine.update_stats("", "GPU GI | opening the OpenCL device")
    started = time.perf_counter()
    device = open_device(scene)
    device_ms = (time.perf_counter() - started) * 1e3

    def progress(fraction: float, message: str) -> None:
        engine.update_progress(fraction)
        engine.update_stats("", f"GPU GI | {message}")
        for listener in STATUS_LISTENERS:
            listener(message)

    renderer = (_renderer(scene, device, persistent=scene.render.use_persistent_data) if not engine.is_preview
                else _fresh_renderer(device))
    result = renderer.render(gscene, settings, progress=progress, should_stop=engine.test_break)
    result.stats["ms"] = {"export": export_ms, "device": device_ms, **result.stats["ms"]}
    return result


def _renderer(scene, device, persistent: bool):
    """The renderer of ``scene``: the one held from its last render when
    ``persistent`` (on the same device); else the one of this render job
    (an animation's earlier frames), or a fresh one outside a job; without
    ``persistent`` nothing stays held after the job (Persistent Data off
    gives its device memory back)."""
    from gpu_core.renderer import Renderer

    with _HELD_LOCK:
        if not persistent:
            _HELD.clear()
        kept = _HELD if persistent else _JOB
        if kept is None:
            return Renderer(device)
        held = kept.get(scene.name)
        if held is None or held.device is not device:
            held = kept[scene.name] = Renderer(device)
        return held


def _fresh_renderer(device):
    """A renderer for one material preview (never kept)."""
    from gpu_core.renderer import Renderer

    return Renderer(device)


def job_started(*_args) -> None:
    """Blender's render_init: frames from now on share their scene's renderer."""
    global _JOB
    with _HELD_LOCK:
        _JOB = {}
    render_started()


def job_ended(*_args) -> None:
    """Blender's render_complete or render_cancel: the job's renderers are
    dropped, and the device memory they let go goes back to the drivers
    (device_memory.py: a CPU device's once no render comes for a while)."""
    global _JOB
    with _HELD_LOCK:
        _JOB = None
    release_unused_later()


def release_held() -> None:
    """Drop every held renderer and give the device memory no renderer holds
    back to the driver now (the add-on is disabled)."""
    global _JOB
    with _HELD_LOCK:
        _JOB = None
        _HELD.clear()
    free_unused_device_memory()


def open_device(scene):
    """The OpenCL device a render of ``scene`` uses (its own setting, else the
    preferences' choice); with no OpenCL at all, a one-line DeviceError
    saying what to install."""
    if survey().problem:
        raise DeviceError(survey().problem)
    from gpu_core.device import get_device

    from .preferences import device_spec

    return get_device(device_spec(scene))


def write_passes(engine, passes: dict, view_layer) -> list[str]:
    """Write the passes the view layer has enabled; returns the names written.

    The result window is the render border (or the whole image), which is
    also the size of every pass gpu_core returns.
    """
    combined = passes["Combined"]
    height, width = combined.shape[:2]
    wanted = {spec.name for spec in enabled_passes(view_layer)}
    written = []
    complete = False
    result = engine.begin_result(0, 0, width, height, layer=view_layer.name)
    try:
        if (result.resolution_x, result.resolution_y) != (width, height):
            raise GpuGiError(
                f"the render result is {result.resolution_x}x{result.resolution_y} pixels "
                f"but the image is {width}x{height}; the border window was computed differently"
            )
        layer = result.layers[0]
        for name, pixels in passes.items():
            target = layer.passes.find_by_name(name, "") if name in wanted else None
            if target is None:
                continue
            flat = np.ascontiguousarray(pixels, np.float32).reshape(height * width, -1)
            if flat.shape[1] != target.channels:
                raise GpuGiError(f"pass {name} has {flat.shape[1]} channels, Blender expects {target.channels}")
            target.rect.foreach_set(flat.ravel())
            written.append(name)
        complete = True
    finally:
        engine.end_result(result, cancel=not complete)
    return written


def _fail(engine, message: str) -> None:
    LAST_RUN["error"] = message
    engine.report({"ERROR"}, f"GPU GI: {message}")
    engine.error_set(f"GPU GI: {message}")
