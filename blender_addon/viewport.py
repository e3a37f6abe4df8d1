"""Rendered viewport: the scene is synced on the main thread, a worker
thread renders it, view_draw shows the latest image.

After an edit or a view change the worker renders a coarse image first (a
quarter of the resolution, one sample, an eighth of the photons where the
edit makes them traced again), then the full resolution with one
sample, then keeps adding samples (1, 2, 4, ... per pass, up to
``MAX_PASS_SAMPLES``) until Viewport Samples (0: until stopped), denoising
the last when Denoise Viewport is on. The passes of one view share
everything the renderer holds: the photon maps, the kd-tree and the GI
cache of the view are computed once, and later passes only run the image
kernel into the renderer's film, which each continues (numbered by
``sample_start``, they are one render of all their samples). With a
Viewport Noise Threshold the pixels whose noise has settled below it sit
the later passes out (adaptive sampling, as Cycles' viewport does), and
the view is done once every pixel has. An edit names the parts it
changed, which the renderer alone uploads and invalidates. Once a view
has settled, the engine's session compiles on the idle worker the kernels
that edits launch and the open did not (``warm_edit_kernels``); a view that
never settles (Viewport Samples 0) pauses for it once it has as many
samples as the default view settles with. Nothing here
touches Blender data: the engine passes exported scenes, cameras and
settings in.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Callable

import numpy as np

from gpu_core.denoise import denoise
from gpu_core.errors import GpuGiError, RenderCancelled

from .export.camera import pixel_filter, view_camera
from .device_memory import release_unused_later, render_started
from .status import mode_line

COARSE_FACTOR = 4
# fewest cache points of a coarse pass
COARSE_MIN_CACHE_POINTS = 32
# share of the photons a coarse pass traces when the maps held cannot serve it
COARSE_PHOTON_SHARE = 0.125
# the denoiser's guides, the film's means beside the image
DENOISE_GUIDES = ("Denoising Albedo", "Denoising Normal")
# shortest time between two status-line redraws during a pass
STATUS_SECONDS = 0.1
# most samples one accumulation pass adds (a redraw at least every such pass)
MAX_PASS_SAMPLES = 16
# aimed duration of one image launch in the viewport: an edit waits for the
# launch running when it comes (F12 keeps the renderer's 0.1 s)
BATCH_SECONDS = 0.03
# samples every pixel takes before its noise is judged, with Min Samples 0
# and Viewport Samples 0 (until stopped); else a quarter of Viewport Samples
OPEN_MIN_SAMPLES = 16
# samples after which a view that never settles (Viewport Samples 0, no
# noise threshold reached) pauses to warm the edits' kernels, then goes on:
# the samples of the default view (Viewport Samples 32) when it settles
UNSETTLED_WARM_SAMPLES = 32


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


def view_update_session(session: "ViewportSession", sync, context, depsgraph, pixel_size, updates) -> bool:
    """What the engine's view_update does: sync the edits (``updates``, None
    when not known) on this thread and hand the scene to the session;
    True when rendering restarted."""
    from .preferences import device_spec

    scene = depsgraph.scene
    view = view_state(context)
    exported, edits = sync.export(depsgraph, view.camera, updates)
    settings = scene.gpugi.render_settings(preview=True, transparent=scene.render.film_transparent)
    settings = dataclasses.replace(settings, samples=scene.gpugi.preview_samples)  # 0: until stopped
    job = Job(scene=exported, settings=settings, device_spec=device_spec(scene), pixel_size=pixel_size(scene),
              edits=edits)
    session.sync_stats = sync.stats.as_dict()
    return session.update_scene(job, view.signature)


def default_renderer(device_spec: str | None):
    """A gpu_core Renderer on the device named by the spec."""
    from gpu_core.device import get_device
    from gpu_core.renderer import Renderer

    return Renderer(get_device(device_spec))


@dataclasses.dataclass
class Job:
    """One render request: the scene, how to render it, and what changed."""

    scene: object  # gpu_core Scene
    settings: object  # gpu_core RenderSettings (its samples: Viewport Samples, 0 = until stopped)
    device_spec: str | None
    pixel_size: int = 1
    edits: set | None = None  # scene parts changed since the previous job (None: not known)


@dataclasses.dataclass(frozen=True)
class Pass:
    """One render of the worker's sequence after an edit."""

    factor: int  # resolution divisor
    samples: int
    start: int  # number of the pass's first sample (sample_start)
    coarse: bool = False  # the quick low-resolution image, shown until the first full one


def passes(job: Job):
    """The worker's passes for ``job``: coarse, then full resolution with
    doubling sample counts until the job's samples (forever when 0)."""
    full = max(1, int(job.pixel_size))
    yield Pass(COARSE_FACTOR * full, 1, 0, coarse=True)
    target, done, step = int(job.settings.samples), 0, 1
    while target <= 0 or done < target:
        count = step if target <= 0 else min(step, target - done)
        yield Pass(full, count, done)
        done, step = done + count, min(2 * step, MAX_PASS_SAMPLES)


def pass_settings(settings, step: Pass):
    """The settings of one pass: its samples, never denoised by the renderer
    (the session denoises the finished image), the denoiser's guides on
    full passes when asked; a coarse pass has as many cache points per
    pixel as the full one (a 16th of them) and, where the photon maps must
    be traced (an edit of the lit scene), an eighth of the photons (the
    full pass traces them all), so it stays quick. Every pass launches the
    image kernel in shorter batches than F12, so an edit waits less for
    the launch it comes during. A full pass judges noise against the
    Viewport Noise Threshold once every pixel has the minimum samples (Min
    Samples, else a quarter of Viewport Samples, at least 4); a coarse
    pass takes every sample. No pass reads back Depth and Normal: the
    viewport shows Combined."""
    target = int(settings.samples)
    minimum = settings.min_samples or (max(4, target // 4) if target > 0 else OPEN_MIN_SAMPLES)
    settings = dataclasses.replace(settings, samples=step.samples, denoise=False, batch_seconds=BATCH_SECONDS,
                                   geometry_passes=False, denoising_passes=bool(settings.denoise) and not step.coarse,
                                   noise_threshold=0.0 if step.coarse else settings.preview_noise_threshold,
                                   min_samples=minimum)
    if step.coarse:
        seeds = max(COARSE_MIN_CACHE_POINTS, settings.cache_seeds // COARSE_FACTOR**2)
        settings = dataclasses.replace(settings, cache_seeds=min(settings.cache_seeds, seeds),
                                       photon_share=COARSE_PHOTON_SHARE)
    return settings


def render_pass(renderer, job: Job, step: Pass, edits, should_stop, progress=None):
    """Render one pass of ``job`` (its scene at the pass's resolution, its
    settings for the pass) with ``renderer``."""
    scene = dataclasses.replace(job.scene, camera=scaled_camera(job.scene.camera, step.factor))
    return renderer.render(scene, pass_settings(job.settings, step), progress=progress, should_stop=should_stop,
                           edits=edits, sample_start=step.start, accumulate=not step.coarse)


# device specs whose edit kernels this process has compiled (warm_edit_kernels)
_EDITS_WARMED: set = set()


def warm_edit_kernels(job: Job, should_stop: Callable[[], bool]) -> list[list[str]]:
    """Compile the kernels the viewport's edits launch and an open does
    not (a turned view's cache records reused, a light's photon maps
    reweighted, a moved object's overlay kd-tree): the viewport's passes
    over a small copy of ``job``'s scene and its edits
    (gpu_core/warmup.py), with a renderer of their own on the job's device,
    once per process and device. PoCL compiles each kernel at its first
    launch, so without this the first move after an install waited for
    compiles (README, the first edits after an install). Stops when
    ``should_stop()`` says so (an edit came), to go on at the next settled
    view; any failure is left to the edit that would meet it. The stages
    each edit's first pass ran."""
    from gpu_core import warmup

    if job.device_spec in _EDITS_WARMED:
        return []
    plans = []
    try:
        renderer = default_renderer(job.device_spec)
        scene, settings = warmup.small_copy(job.scene, job.settings)
        for edited, edits in [(scene, None)] + warmup.edited_copies(scene):
            small = Job(edited, settings, job.device_spec, edits=edits)
            for index, step in enumerate(passes(small)):
                if should_stop():
                    return plans
                result = render_pass(renderer, small, step, edits if index == 0 else set(), should_stop)
                if index == 0:
                    plans.append(list(result.stats.get("plan", [])))
    except Exception:  # stopped (RenderCancelled), or failed: never the viewport's error; the edit reports its own
        return plans
    _EDITS_WARMED.add(job.device_spec)
    return plans


class Accumulation:
    """The full-resolution image of one view: the renderer's film after
    each full pass (the mean of every sample so far), denoised once the
    view is done (Viewport Samples taken, or every pixel settled below the
    Viewport Noise Threshold) when asked, guided by the film's denoising
    albedo and normal."""

    def __init__(self, target: int, denoise: bool, quality: str):
        self.target, self.denoise, self.quality = int(target), bool(denoise), quality
        self.samples = 0
        self.done = False

    def add(self, step: Pass, result) -> tuple[np.ndarray, str]:
        """The image to show after ``step`` and its status label."""
        if step.coarse:
            return result.passes["Combined"], "preview"
        held = result.stats["accumulated"]
        self.samples = int(held["samples"])
        self.done = bool(held["converged"]) or self.samples >= self.target > 0
        image = result.passes["Combined"]
        label = self.label(self.samples, float(held["mean_samples"]), bool(held["converged"]))
        if self.denoise and self.done:
            try:
                image = denoise(image, *(result.passes[name] for name in DENOISE_GUIDES), self.quality)
                label += ", denoised"
            except GpuGiError as err:
                label += f", not denoised: {err}"
        return image, label

    def label(self, samples: int, mean: float | None = None, settled: bool = False) -> str:
        """'sample 12/32' (or 'sample 12' without a target), with the mean a
        pixel took where pixels sat passes out, and 'settled' once all do."""
        text = f"sample {samples}" + (f"/{self.target}" if self.target > 0 else "")
        if mean is not None and mean < samples:
            text += f" ({mean:.1f} per pixel)"
        return text + (", settled" if settled else "")


class ViewportSession:
    """One viewport's worker thread and latest image.

    ``redraw`` is called (from the worker) whenever a new image or error is
    ready; ``make_renderer(device_spec)`` builds the renderer the worker uses;
    ``warm_up(job, should_stop)`` (the engine's: ``warm_edit_kernels``), when
    given, runs on the worker after a view has settled, until an edit comes;
    in a view that takes samples until stopped, once between its passes
    after UNSETTLED_WARM_SAMPLES.
    """

    def __init__(self, redraw: Callable[[], None], make_renderer=default_renderer, warm_up=None):
        self._redraw = redraw
        self._make_renderer = make_renderer
        self._warm_up = warm_up  # run on the idle worker once a view has settled: warm_up(job, should_stop)
        self.warming = False  # the warm-up is running
        self._renderers: dict = {}
        self._pending: dict = {}  # device spec -> parts edited since its renderer last rendered (None: unknown)
        self._lock = threading.Lock()  # the latest image
        self._wake = threading.Condition()  # the queued job, the pending edits, the running flag
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._queued: tuple | None = None  # (job, its stop event) waiting for the worker
        self._running = False
        self._closed = False
        self.job: Job | None = None
        self.signature: tuple | None = None
        self._image: np.ndarray | None = None
        self._version = 0
        self.error: str | None = None
        self.status = ""
        self.stats: dict = {}  # the last pass's render stats
        self.sync_stats: dict = {}  # what the last sync exported (main thread)
        self.samples = 0  # samples in the image shown (full resolution; 0 until the first full pass)
        self.first_plan: list = []  # the stages of the first pass after the last restart: what the edit redid

    # -- main thread ----------------------------------------------------------

    def update_scene(self, job: Job, signature: tuple) -> bool:
        """A new sync (after an edit): render it from the start, unless
        nothing it renders changed; True when rendering restarted."""
        unchanged = (self.job is not None and job.edits == set() and signature == self.signature
                     and (job.settings, job.device_spec, job.pixel_size)
                     == (self.job.settings, self.job.device_spec, self.job.pixel_size) and self.error is None)
        if unchanged:
            return False
        self.signature = signature
        self.restart(job)
        return True

    def update_view(self, view: ViewState) -> bool:
        """Follow a view change seen in view_draw; True when rendering restarted."""
        if self.job is None or view.signature == self.signature:
            return False
        self.signature = view.signature
        scene = dataclasses.replace(self.job.scene, camera=view.camera)
        self.restart(dataclasses.replace(self.job, scene=scene, edits=set()))
        return True

    def restart(self, job: Job) -> None:
        """Ask the running job to stop and queue ``job``; the worker starts
        it after the stopped job's batch (Blender's thread never waits for
        a kernel)."""
        with self._wake:
            self._stop.set()
            for spec in set(self._pending) | {job.device_spec}:
                pending = self._pending.get(spec, set())
                self._pending[spec] = None if pending is None or job.edits is None else pending | job.edits
            self.job = job
            self.error = None
            self.status = "GPU GI | rendering"
            self.samples, self.first_plan = 0, []
            self._stop = threading.Event()
            self._queued = (job, self._stop)
            self._closed = False
            self._wake.notify()
        render_started()
        if self._thread is None or not self._thread.is_alive():
            # one worker for the session's life: OpenCL drivers keep per-thread
            # state, so a thread per edit would grow the process edit by edit
            self._thread = threading.Thread(target=self._worker, name="gpugi-viewport", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the running job after its current batch and end the worker;
        a warm-up ends at its next stage without Blender's thread waiting
        for it (the stage may be a program's compile; it holds nothing of
        the session's)."""
        with self._wake:
            self._stop.set()
            self._queued, self._closed = None, True
            self._wake.notify()
        if self._thread is not None and not self.warming:
            self._thread.join(timeout=10.0)
        self._thread = None
        # the view's renderers go, and their device memory back to the drivers
        # (a CPU device's once no render comes for a while: device_memory.py)
        self._renderers = {}
        release_unused_later()

    def latest(self) -> tuple[np.ndarray | None, int]:
        """The newest finished image (float RGBA, rows from the bottom) and its version."""
        with self._lock:
            return self._image, self._version

    @property
    def busy(self) -> bool:
        """A job is queued or rendering."""
        with self._wake:
            return self._queued is not None or self._running

    # -- worker thread --------------------------------------------------------

    def _worker(self) -> None:
        """Run queued jobs one after the other until the session stops."""
        while True:
            with self._wake:
                while self._queued is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                (job, stop), self._queued = self._queued, None
                self._running = True
            settled = False
            try:
                settled = self._work(job, stop)
            finally:
                with self._wake:
                    self._running = False
                    self.warming = settled and self._warm_up is not None
            if self.warming:
                self._warm(job, self._waited_for)

    def _warm(self, job: Job, should_stop: Callable[[], bool]) -> None:
        """Run the warm-up for ``job`` until ``should_stop()`` (``warming`` meanwhile)."""
        self.warming = True
        try:
            self._warm_up(job, should_stop)
        finally:
            self.warming = False

    def _waited_for(self) -> bool:
        """A job is queued or the session is closing (what stops a warm-up)."""
        with self._wake:
            return self._queued is not None or self._closed

    def _work(self, job: Job, stop: threading.Event) -> bool:
        """Render ``job``'s passes; True when its view settled (not stopped, no error)."""
        try:
            renderer = self._renderer(job.device_spec)
            film = Accumulation(job.settings.samples, job.settings.denoise, job.settings.denoise_quality)
            for step in passes(job):
                if stop.is_set():
                    return False
                with self._wake:
                    if stop.is_set():
                        return False  # the edits pending stay for the next job
                    edits, self._pending[job.device_spec] = self._pending.get(job.device_spec), set()
                result = render_pass(renderer, job, step, edits, stop.is_set, self._progress(step, film, stop))
                if stop.is_set():
                    return False
                image, label = film.add(step, result)
                with self._lock:
                    self._image = image
                    self._version += 1
                self.stats, self.samples = result.stats, film.samples
                self.first_plan = self.first_plan or list(result.stats.get("plan", []))
                self.status = status_line(result, label)
                self._notify()
                if film.done:
                    return True
                if (self._warm_up is not None and film.target <= 0
                        and film.samples >= UNSETTLED_WARM_SAMPLES > film.samples - step.samples):
                    # a view that may never settle warms up once, between two passes
                    self._warm(job, lambda: stop.is_set() or self._waited_for())
        except RenderCancelled:
            return False
        except GpuGiError as err:
            self._fail(str(err))
        except Exception as err:  # a worker must never take Blender down
            self._fail(f"internal error ({type(err).__name__}): {err}")
        return False

    def _progress(self, step: Pass, film: "Accumulation", stop: threading.Event):
        """The renderer's progress as the status line ("gathering", "sample 3/32:
        rendered 4096/230400 pixels"), redrawn at most every STATUS_SECONDS."""
        label = "preview" if step.coarse else film.label(film.samples + step.samples)
        shown = [0.0]

        def progress(_fraction: float, message: str) -> None:
            now = time.perf_counter()
            if stop.is_set() or now - shown[0] < STATUS_SECONDS:
                return
            shown[0] = now
            self.status = f"GPU GI | {label}: {message}"
            self._notify()
        return progress

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
        except ReferenceError:  # the engine is gone; nothing will draw this
            with self._wake:
                self._stop.set()
                self._closed = True


def status_line(result, label: str) -> str:
    """The viewport's status after a pass: mode, progress, triangles, and
    the first warning of the scene (with how many more there are)."""
    line = f"GPU GI | {mode_line(result.stats)} | {label}, {result.stats.get('triangles', 0)} triangles"
    if result.warnings:
        more = len(result.warnings) - 1
        line += f" | warning: {result.warnings[0]}" + (f" (+{more} more)" if more else "")
    return line


def scaled_camera(camera, factor: int):
    """``camera`` with its resolution divided by ``factor`` (same view, no border)."""
    if factor <= 1 and camera.border is None:
        return camera
    return dataclasses.replace(
        camera, width=max(1, camera.width // factor), height=max(1, camera.height // factor), border=None
    )
