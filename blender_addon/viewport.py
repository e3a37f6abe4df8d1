"""Rendered viewport: export on the main thread, render in a worker, draw the latest.

The worker renders coarse first (a quarter of the resolution, one sample),
then the full region; an edit or a view change restarts it.
"""

from __future__ import annotations

import dataclasses
import threading

import numpy as np

from gpu_core.device import get_device
from gpu_core.errors import GpuGiError, RenderCancelled
from gpu_core.renderer import Renderer

from .export import ExportError, export_scene
from .export.camera import view_camera

COARSE_FACTOR = 4


def view_signature(context) -> tuple:
    """What identifies the current view: region size and view/projection matrices."""
    region, rv3d = context.region, context.region_data
    return (
        region.width,
        region.height,
        tuple(tuple(row) for row in rv3d.view_matrix),
        tuple(tuple(row) for row in rv3d.window_matrix),
    )


def camera_for_view(context):
    """A gpu_core camera for the 3D view (camera view included)."""
    region, rv3d, space = context.region, context.region_data, context.space_data
    return view_camera(
        rv3d.view_matrix,
        rv3d.window_matrix,
        region.width,
        region.height,
        ortho=not rv3d.is_perspective,
        clip_start=space.clip_start,
        clip_end=space.clip_end,
    )


class ViewportSession:
    """One viewport's scene, worker thread and latest image."""

    def __init__(self, redraw):
        self._redraw = redraw
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.scene = None
        self.settings = None
        self.device_spec = None
        self.signature = None
        self.image: np.ndarray | None = None
        self.error: str | None = None

    def update_scene(self, depsgraph, context) -> None:
        """Re-export after an edit (main thread) and restart rendering."""
        try:
            scene = export_scene(depsgraph, camera=camera_for_view(context))
        except ExportError as err:
            self.error = str(err)
            return
        gpugi = depsgraph.scene.gpugi
        self.settings = gpugi.render_settings(preview=True)
        self.device_spec = gpugi.device or None
        self.signature = view_signature(context)
        self.restart(scene)

    def update_view(self, context) -> bool:
        """Follow a view change (main thread); True when a restart happened."""
        signature = view_signature(context)
        if self.scene is None or signature == self.signature:
            return False
        self.signature = signature
        self.restart(dataclasses.replace(self.scene, camera=camera_for_view(context)))
        return True

    def restart(self, scene) -> None:
        self.stop()
        self.scene = scene
        self.error = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, args=(scene, self.settings, self._stop), daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._thread = None

    def _work(self, scene, settings, stop: threading.Event) -> None:
        try:
            renderer = Renderer(get_device(self.device_spec))
            for coarse in (True, False):
                job_scene, job_settings = scene, settings
                if coarse:
                    job_scene = dataclasses.replace(scene, camera=_scaled_camera(scene.camera, COARSE_FACTOR))
                    job_settings = dataclasses.replace(settings, samples=1)
                result = renderer.render(job_scene, job_settings, should_stop=stop.is_set)
                with self._lock:
                    self.image = result.passes["Combined"]
                self._redraw()
        except RenderCancelled:
            return
        except GpuGiError as err:
            self.error = str(err)
            self._redraw()
        except Exception as err:  # a worker must never take Blender down
            self.error = f"internal error ({type(err).__name__}): {err}"
            self._redraw()

    def latest(self) -> np.ndarray | None:
        with self._lock:
            return self.image


def _scaled_camera(camera, factor: int):
    return dataclasses.replace(
        camera, width=max(1, camera.width // factor), height=max(1, camera.height // factor), border=None
    )
