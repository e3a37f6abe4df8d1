"""When the device memory renders let go goes back to the drivers.

A renderer's buffers come from its device's pool (gpu_core's Device.empty)
and go back to the pool when the renderer is dropped. When a render job
ends or a Rendered viewport closes, a GPU's unused memory goes back to its
driver at once, as Cycles frees its memory; a CPU device's (host memory)
stays in the pool for the next render RELEASE_AFTER_S, then goes back unless
a render has started since. A render into fresh buffers pays for the first
touch of their pages: F12 of the Cornell box at 256² (default settings, no
denoiser) 570-577 -> 505-519 ms, of the large scene 739-754 -> 646-652 ms
with the pool kept (README, "Using it": Animations). The release is a
Blender timer; where Blender runs none (background mode) the process ends
first.
"""

from __future__ import annotations

import sys
import threading

RELEASE_AFTER_S = 30.0
_RENDERS_STARTED = 0  # render jobs and viewport renders so far: a pending release skips itself when one started since
_LOCK = threading.Lock()


def free_unused_device_memory(keep_host_memory: bool = False) -> None:
    """Give the device memory no renderer holds back to the drivers (with
    ``keep_host_memory`` the CPU devices' stays); nothing where no device
    was ever opened (gpu_core's device layer not loaded, pyopencl perhaps
    missing)."""
    devices = sys.modules.get("gpu_core.device")
    if devices is not None:
        devices.free_held_memory(keep_host_memory)


def render_started() -> None:
    """A render job or a viewport render began: a release pending from before skips itself."""
    global _RENDERS_STARTED
    with _LOCK:
        _RENDERS_STARTED += 1


def release_unused_later() -> None:
    """A render job ended or a viewport closed: a GPU's unused memory goes
    back now, a CPU device's RELEASE_AFTER_S later if no render has started
    by then."""
    with _LOCK:
        started = _RENDERS_STARTED
    free_unused_device_memory(keep_host_memory=True)
    try:
        import bpy

        bpy.app.timers.register(lambda: _release_if_idle(started), first_interval=RELEASE_AFTER_S, persistent=True)
    except Exception:  # noqa: BLE001 - no timers (Blender shutting down, a viewport's engine collected late): now
        free_unused_device_memory()


def _release_if_idle(started: int) -> None:
    """The release release_unused_later scheduled, ``started`` renders in:
    only if none has started since (a timer's function; returning None runs
    it once)."""
    with _LOCK:
        idle = _RENDERS_STARTED == started
    if idle:
        free_unused_device_memory()
