"""The renderer: the driver that reads like the method.

One Renderer serves F12, ``blender -b`` and the viewport, and keeps on the
device what a later render can reuse (the scene's buffers part by part,
the kd-tree, the photon maps). A render: validate the scene; plan it
(plan.py: what changed, what runs, what is reused, the memory it takes);
build every program it needs (in parallel, progress reported); upload what
changed (the kd-tree is built when the triangles changed); in GI mode,
trace or keep the photon maps and run the GI stages (gi/pipeline.py); then
the image kernel (image.py), in launches between which progress is
reported and Esc is seen; then, when asked, the denoiser (denoise.py).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, replace
from typing import Callable

import pyopencl as cl

from . import warmup
from .denoise import denoise
from .device import Device
from .device.timer import StageTimer
from .errors import DeviceError, GpuGiError, check_stop
from .gi.cache.samples import HeldSamples
from .gi.pipeline import GiField, render_gi
from .image import DENOISING_PASSES, LIGHT_PASSES, ImageFilm, render_image  # noqa: F401  (LIGHT_PASSES: pass names)
from .photons.reweight import reweight_maps
from .photons.aim import caustic_boxes
from .photons.trace import PhotonMaps, PhotonSettings, trace_maps, traced_maps
from .plan import Held, Plan, plan
from .scene.model import Scene
from .scene.upload import SceneBuffers, upload
from .scene.validate import GeometryMemo, validate
from .settings import RenderSettings

# most cache records held for later views, in units of the Cache Points setting
RECORDS_CAP = 4


@dataclass
class RenderResult:
    """Passes of the render window (rows from the bottom), stats and warnings."""

    passes: dict
    stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


class Renderer:
    """Renders gpu_core scenes on one OpenCL device."""

    def __init__(self, device: Device, builds_up_front: bool = True):
        """``builds_up_front``: every program a render needs is built before
        its first stage (while a helper process warms its kernels where
        that helps: warmup.py); else each when a stage first needs it."""
        self.device = device
        self._builds_up_front = builds_up_front
        self._warmup = None  # the helper process of the render running, if any
        self._held = Held()
        self._buffers: SceneBuffers | None = None
        self._maps: PhotonMaps | None = None
        self._cache: GiField | None = None
        self._records: dict = {}  # records key -> CacheRecords, the most recent last
        self._samples = HeldSamples()  # cache points of the latest renders, kept for the same shading points
        self._unsynced: set[str] = set()  # parts named in edits and not uploaded yet (a render was stopped)
        self._geometry = GeometryMemo()  # the last scene's checked geometry
        self._film: ImageFilm | None = None  # the image that accumulating passes continue

    def render(self, scene: Scene, settings: RenderSettings | None = None,
               progress: Callable[[float, str], None] | None = None,
               should_stop: Callable[[], bool] | None = None, edits: set[str] | None = None,
               sample_start: int = 0, accumulate: bool = False) -> RenderResult:
        """Render ``scene``; ``edits``, when the caller knows them, names the
        parts changed since this renderer's last call (scene/model.py PARTS;
        the camera is compared anyway). ``sample_start`` numbers the first
        camera path of every pixel: renders of ``samples`` paths from 0,
        ``samples``, 2 ``samples``... average to one render of all of them
        (progressive refinement). With ``accumulate`` the renderer does that
        averaging itself: a render whose ``sample_start`` is where the last
        accumulating render of the same image (scene, view, settings but
        the samples, noise threshold and min samples) ended continues its
        film, and its passes are the mean of every sample since the film
        began (stats ``accumulated``: its samples, the mean a pixel took,
        whether every pixel has settled below the noise threshold, the
        first sample's number); with a noise threshold, pixels that have
        settled take no more samples. An OpenCL failure on the way (out of
        memory or resources, a lost device) is a DeviceError saying so, and
        the renderer forgets what it held: the next render starts afresh."""
        try:
            return self._render(scene, settings, progress, should_stop, edits, sample_start, accumulate)
        except cl.Error as err:
            self._forget()
            raise DeviceError(device_failure(self.device.name, err)) from err
        finally:
            warmup.stop(self._warmup)
            self._warmup = None

    def _forget(self) -> None:
        """Drop everything held on the device (after a device failure)."""
        self._held, self._buffers, self._maps, self._cache, self._records = Held(), None, None, None, {}
        self._samples = HeldSamples()
        self._unsynced = set()
        self._film = None

    def _render(self, scene: Scene, settings: RenderSettings | None, progress, should_stop, edits,
                sample_start: int, accumulate: bool) -> RenderResult:
        settings = (settings or RenderSettings()).validated()
        if edits is not None:
            edits = self._unsynced = set(edits) | self._unsynced
        keep_guides = settings.denoising_passes
        if settings.denoise:  # the denoiser's guides are the denoising albedo and normal
            settings = replace(settings, denoising_passes=True)
        timer = StageTimer(getattr(self.device, "queue", None))
        with timer.stage("validate"):
            scene = validate(scene, self._geometry)
            the_plan = plan(scene, settings, self._held, edits, self.device)
        the_plan.check_budget(self.device)
        moved = self.device.transfers()
        with timer.stage("compile"):
            if self._builds_up_front:
                self._warmup = warmup.start(self.device, scene, settings, the_plan.programs)
                _Builds(self.device, the_plan.programs, busy=int(self._warmup is not None)).join(progress, should_stop)
        check_stop(should_stop)
        self._upload(scene, the_plan, timer, should_stop)
        check_stop(should_stop)
        field_ = None
        if settings.mode == "gi":
            say = (lambda text: progress(0.0, text)) if progress is not None else None
            if say is not None and the_plan.traces_photons:
                say("photons")
            with timer.stage("photons"):
                maps = self._photon_maps(scene, the_plan, settings)
            check_stop(should_stop)
            field_ = self._gi_cache(scene, settings, the_plan, maps, timer, should_stop, say)
            check_stop(should_stop)
        film = self._continued_film(scene, settings, the_plan, sample_start) if accumulate else None
        with timer.stage("render"):
            passes, image = render_image(self.device, self._buffers, scene, settings, the_plan.image_defines,
                                         field_, progress, should_stop, sample_start, film)
        warnings, denoised = self._warnings(scene), False
        if settings.denoise:
            if progress is not None:
                progress(1.0, "denoising")
            with timer.stage("denoise"):
                problem = _denoise(passes, settings.denoise_quality, keep_guides)
            denoised = not problem
            warnings += [problem] if problem else []
        stats = self._stats(scene, settings, the_plan, timer, image, field_, moved)
        stats["denoised"] = denoised
        return RenderResult(passes=passes, stats=stats, warnings=warnings)

    # -- stages ------------------------------------------------------------------

    def _upload(self, scene: Scene, the_plan: Plan, timer: StageTimer, should_stop) -> None:
        """Upload the parts the plan names; the renderer holds them from now on."""
        self._held.tables = None  # until the upload completes, nothing is held
        self._held.tree_base = None if the_plan.builds_tree else self._held.tree_base
        self._buffers = upload(self.device, scene, the_plan.tables, self._buffers, the_plan.changed, timer,
                               should_stop, the_plan.tree_rows)
        if the_plan.builds_tree:  # later moves are overlaid on this tree
            self._held.tree_base = scene.triangles.copy()
        self._held.digests, self._held.generations = the_plan.digests, the_plan.generations
        self._held.tables = the_plan.tables
        self._unsynced = set()

    def _photon_maps(self, scene: Scene, the_plan: Plan, settings: RenderSettings) -> PhotonMaps:
        """The plan's photon maps: traced (caustic photons aimed at the
        surfaces that can bounce them specularly), or the ones held when it
        says they are reused, or those reweighted for the lights' new power."""
        if the_plan.photons_reused and self._maps is not None:
            return self._maps
        held, maps = self._held, self._maps
        held.photon_key, self._maps = None, None
        if the_plan.reweights_photons and maps is not None:
            reweight_maps(self.device, maps, the_plan.photon_scales, held.photon_emitters, the_plan.emitters)
        else:
            photon_settings = PhotonSettings(*the_plan.photon_counts, settings.seed, settings.photon_k,
                                             settings.max_bounces)
            aim = (caustic_boxes(scene, the_plan.tables.materials) if "caustic" in traced_maps(the_plan.photon_maps)
                   else None)
            maps = trace_maps(self.device, self._buffers, the_plan.emitters, the_plan.photon_maps, photon_settings,
                              the_plan.scene_defines, aim)
        self._maps = maps
        held.photon_key, held.photon_emitters = the_plan.photon_key, the_plan.emitters
        held.photon_lights = the_plan.tables.lights.copy()
        return maps

    def _gi_cache(self, scene: Scene, settings: RenderSettings, the_plan: Plan, maps: PhotonMaps,
                  timer: StageTimer, should_stop, say) -> GiField:
        """The GI cache of this view: computed by the GI stages, or the one
        held when the plan says it is reused (only the image runs again)."""
        if the_plan.cache_reused and self._cache is not None:
            return self._cache
        self._held.cache_key, self._cache = None, None
        records = self._records.get(the_plan.records_source) if the_plan.records_reused else None
        field_, records = render_gi(self.device, self._buffers, scene.camera.pixel_window, settings, maps,
                                    the_plan.stages, the_plan.scene_defines, timer, should_stop, records, say,
                                    self._samples)
        self._held.cache_key, self._cache = the_plan.cache_key, field_
        self._keep_records(the_plan.records_key, records, settings)
        return field_

    def _keep_records(self, key: tuple, records, settings: RenderSettings) -> None:
        """Hold the view's cache records for later views of the lit scene:
        those of the two latest keys (a coarse and a full pass), while they
        number at most RECORDS_CAP cache points' worth (then the next view
        starts afresh)."""
        self._records.pop(key, None)
        if records is not None and settings.cache_reuse and records.count <= RECORDS_CAP * settings.cache_seeds:
            self._records[key] = records
        while len(self._records) > 2:
            self._records.pop(next(iter(self._records)))
        self._held.records_keys = tuple(self._records)

    def _continued_film(self, scene: Scene, settings: RenderSettings, the_plan: Plan, sample_start: int) -> ImageFilm:
        """The film an accumulating render goes on with: the one held when
        it holds the same image up to ``sample_start``, else a new one (held
        from now on)."""
        x0, y0, x1, y1 = scene.camera.pixel_window
        same_image = replace(settings, samples=1, noise_threshold=0.0, min_samples=0, batch_seconds=0.1,
                             batch_pixels=1)
        key = (tuple(the_plan.generations[p] for p in sorted(the_plan.generations)), the_plan.cache_key,
               sorted(the_plan.image_defines.items()), scene.camera.pixel_window, same_image)
        film = self._film
        if (film is None or sample_start == 0 or film.key != key
                or film.sample_start + film.samples != sample_start):
            self._film = None  # its buffers go before the new film's are made
            film = ImageFilm.new(self.device, (x1 - x0, y1 - y0), settings, sample_start, counted=True)
            film.key = key
        self._film = film
        return film

    # -- report --------------------------------------------------------------------

    def _stats(self, scene: Scene, settings: RenderSettings, the_plan: Plan, timer: StageTimer, image: dict,
               field_, moved) -> dict:
        transfers = self.device.transfers().since(moved)
        stats = {
            "device": self.device.name,
            "mode": settings.mode,
            "plan": _stages_run(the_plan, field_),
            "ms": timer.ms,
            "triangles": scene.triangle_count,
            "lights": len(scene.lights),
            "emissive_triangles": self._buffers.emit_count,
            "textures": len(scene.textures),
            "batches": image["batches"],
            "samples": settings.samples,
            "light_samples": settings.light_samples,
            "device_bytes": the_plan.device_bytes,
            "transfers": {"to_device": transfers.to_device, "to_host": transfers.to_host},
            "kdtree": self._buffers.tree.stats,
            **scene.report.as_stats(),
        }
        for key in ("adaptive", "accumulated"):
            if key in image:
                stats[key] = image[key]
        if field_ is not None:
            stats["gi"] = {**field_.stats, "photons_reused": not the_plan.traces_photons,
                           "photons_reweighted": the_plan.reweights_photons,
                           "photon_counts": list(the_plan.photon_counts),
                           "cache_reused": the_plan.cache_reused}
        return stats

    def _warnings(self, scene: Scene) -> list[str]:
        warnings = list(scene.warnings)
        if self.device.fallback_message:
            warnings.append(self.device.fallback_message)
        return warnings


def _stages_run(the_plan: Plan, field_: GiField | None) -> list[str]:
    """The plan's stages, with the cache points named kept where the GI
    stages found the shading points of an earlier render (HeldSamples)."""
    if field_ is None or not field_.stats.get("sample_points_reused"):
        return the_plan.stages
    return [stage + "_reused" if stage == "sample_points" else stage for stage in the_plan.stages]


def device_failure(device_name: str, err: Exception) -> str:
    """What to tell the user of an OpenCL error during a render."""
    text = str(err).strip() or type(err).__name__
    if isinstance(err, cl.MemoryError) or "OUT_OF" in text.upper() or "ALLOCATION" in text.upper():
        return (f"{device_name.strip()} ran out of memory or resources during the render ({text}). Lower the "
                "resolution, photon counts or cache points, or choose another device in the add-on's preferences.")
    return (f"{device_name.strip()} failed during the render ({text}); the next render starts afresh. If it "
            "happens again, choose another device in the add-on's preferences.")


def _denoise(passes: dict, quality: str, keep_guides: bool) -> str:
    """Denoise Combined in place from the denoising passes (dropped after,
    unless asked for); what kept it from running ('' when it ran)."""
    guides = [passes[name] for name in DENOISING_PASSES]
    if not keep_guides:
        for name in DENOISING_PASSES:
            del passes[name]
    try:
        passes["Combined"] = denoise(passes["Combined"], guides[0], guides[1], quality)
    except GpuGiError as err:
        return f"{err}; the image is not denoised"
    return ""


class _Builds:
    """Every program a render needs, built before any stage runs, in a
    background thread (in parallel where the driver allows) while the
    render's own thread reports progress ("compiling kernels 3/9") and sees
    a request to stop; the builder's thread never calls back. No thread
    when every program is built already: nothing to wait for or poll."""

    def __init__(self, device: Device, programs: list, busy: int = 0):
        self._error: GpuGiError | None = None
        self._done, self._total = 0, 0
        self._thread = None
        if device.programs.unbuilt(programs):
            self._thread = threading.Thread(target=self._run, args=(device, programs, busy), name="gpugi-builds",
                                            daemon=True)
            self._thread.start()

    def _run(self, device: Device, programs: list, busy: int) -> None:
        def count(done: int, total: int) -> None:
            self._done, self._total = done, total
        try:
            device.programs.build_all(programs, count, busy)
        except GpuGiError as err:
            self._error = err

    def join(self, progress=None, should_stop=None) -> None:
        """Wait for every build, reporting the count as it changes and
        seeing a request to stop; a build's error is raised here."""
        if self._thread is None:
            return
        reported = None
        while self._thread.is_alive() or reported not in (None, self._done):
            self._thread.join(0.1)
            if progress is not None and self._total and reported != self._done:
                reported = self._done
                progress(0.0, f"compiling kernels {self._done}/{self._total}")
            check_stop(should_stop)
        if self._error is not None:
            raise self._error
