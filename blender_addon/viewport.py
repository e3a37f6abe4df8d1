"""Rendered viewport: the scene is exported on the main thread, a worker
thread renders it, view_draw shows the latest image.

The worker renders a coarse image first (a quarter of the resolution, one
sample), then the full one (denoised when Denoise Viewport is on); an edit or a view change stops it between two
kernel batches and starts it again. Nothing here touches Blender data: the
engine passes exported scenes, cameras and settings in.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Callable

import numpy as np

from gpu_core.errors import GpuGiError, RenderCancelled

from .export.camera import pixel_filter, view_camera
from .status import mode_line

COARSE_FACTOR = 4


@dataclasses.dataclass(frozen=True)
class ViewState:
    """What the viewport shows from: its camera and a signature to compare."""

    camera: object  # gpu_core Camera at the region's size
    signature: tuple


def view_state(context) -> ViewState:
    """The camera and signature (region size, view and window matrices) of a 3D view."""
    region, rv3d = context.region, context.region_data
    view = np.array(rv3d.view_matrix, np.float64)
    window = np.array(rv3d.window_matrix, np.float64)
    film_filter = pixel_filter(context.scene)
    camera = view_camera(view, window, region.width, region.height, ortho=not rv3d.is_perspective,
                         film_filter=film_filter)
    signature = (region.width, region.height, view.round(9).tobytes(), window.round(9).tobytes(), film_filter)
    return ViewState(camera=camera, signature=signature)


def default_renderer(device_spec: str | None):
    """A gpu_core Renderer on the device named by the spec."""
    from gpu_core.device import get_device
    from gpu_core.renderer import Renderer

    return Renderer(get_device(device_spec))


@dataclasses.dataclass
class Job:
    """One render request: the scene and how to render it."""

    scene: object  # gpu_core Scene
    settings: object  # gpu_core RenderSettings
    device_spec: str | None
    pixel_size: int = 1


class ViewportSession:
    """One viewport's worker thread and latest image.

    ``redraw`` is called (from the worker) whenever a new image or error is
    ready; ``make_renderer(device_spec)`` builds the renderer the worker uses.
    """

    def __init__(self, redraw: Callable[[], None], make_renderer=default_renderer):
        self._redraw = redraw
        self._make_renderer = make_renderer
        self._renderers: dict = {}
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.job: Job | None = None
        self.signature: tuple | None = None
        self._image: np.ndarray | None = None
        self._version = 0
        self.error: str | None = None
        self.status = ""

    # -- main thread ----------------------------------------------------------

    def update_scene(self, job: Job, signature: tuple) -> None:
        """A new export (after an edit): render it from the start."""
        self.signature = signature
        self.restart(job)

    def update_view(self, view: ViewState) -> bool:
        """Follow a view change seen in view_draw; True when rendering restarted."""
        if self.job is None or view.signature == self.signature:
            return False
        self.signature = view.signature
        scene = dataclasses.replace(self.job.scene, camera=view.camera)
        self.restart(dataclasses.replace(self.job, scene=scene))
        return True

    def restart(self, job: Job) -> None:
        """Stop the worker and start a new one on ``job``."""
        self.stop()
        self.job = job
        self.error = None
        self.status = "GPU GI | rendering"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, args=(job, self._stop), name="gpugi-viewport", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask the worker to stop after its current batch and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        self._thread = None

    def latest(self) -> tuple[np.ndarray | None, int]:
        """The newest finished image (float RGBA, rows from the bottom) and its version."""
        with self._lock:
            return self._image, self._version

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # -- worker thread --------------------------------------------------------

    def _work(self, job: Job, stop: threading.Event) -> None:
        try:
            renderer = self._renderer(job.device_spec)
            for factor, samples, denoise, label in self._passes(job):
                if stop.is_set():
                    return
                scene = dataclasses.replace(job.scene, camera=scaled_camera(job.scene.camera, factor))
                settings = dataclasses.replace(job.settings, samples=samples, denoise=denoise)
                result = renderer.render(scene, settings, should_stop=stop.is_set)
                if stop.is_set():
                    return
                with self._lock:
                    self._image = result.passes["Combined"]
                    self._version += 1
                triangles = result.stats.get("triangles", 0)
                self.status = f"GPU GI | {mode_line(result.stats)} | {label}, {triangles} triangles"
                self._notify()
        except RenderCancelled:
            return
        except GpuGiError as err:
            self._fail(str(err))
        except Exception as err:  # a worker must never take Blender down
            self._fail(f"internal error ({type(err).__name__}): {err}")

    def _passes(self, job: Job):
        """(resolution divisor, samples, denoised, label) of each image the
        worker renders: the coarse one never denoised, the full one when
        the settings ask (Denoise Viewport)."""
        full = max(1, int(job.pixel_size))
        yield COARSE_FACTOR * full, 1, False, "preview"
        denoise = bool(job.settings.denoise)
        yield full, job.settings.samples, denoise, f"{job.settings.samples} samples" + (", denoised" if denoise else "")

    def _renderer(self, device_spec):
        if device_spec not in self._renderers:
            self._renderers[device_spec] = self._make_renderer(device_spec)
        return self._renderers[device_spec]

    def _fail(self, message: str) -> None:
        self.error = message
        self.status = f"GPU GI | error: {message}"
        self._notify()

    def _notify(self) -> None:
        try:
            self._redraw()
        except ReferenceError:
            self._stop.set()  # the engine is gone; nothing will draw this


def scaled_camera(camera, factor: int):
    """``camera`` with its resolution divided by ``factor`` (same view, no border)."""
    if factor <= 1 and camera.border is None:
        return camera
    return dataclasses.replace(
        camera, width=max(1, camera.width // factor), height=max(1, camera.height // factor), border=None
    )
