"""The image stage (image.cl): camera paths over the render window, in
launches of a bounded number of pixels so that progress is reported and a
request to stop is seen between them, then the passes read back.

With a noise threshold (adaptive sampling) the samples come in rounds:
every pixel takes the minimum first, then, round after round, only the
pixels whose noise (or a neighbour's) is still above the threshold take
more, up to the samples setting; the kernel merges each round's means
with those before.

A film (ImageFilm) is where the samples go. A render makes its own; the
viewport's passes of one view continue the one the renderer keeps, each
pass a round: the kernel merges it into the passes before, and with a
noise threshold the pixels that have settled sit the later passes out.

In GI mode the kernel reads the GI cache through the shading-point grid
(gi/pipeline.py) that the stages before it left on the device.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .device import Device
from .device.constants import OUTPUT_ADAPTIVE, OUTPUT_DENOISING, PASS_COUNT
from .device.layout import IMAGE_JOB_DTYPE
from .errors import check_stop
from .scene.model import Scene
from .scene.upload import SceneBuffers
from .settings import RenderSettings
from .shading.pixel_filter import filter_table

PROGRAM = "image.cl"
_FIRST_BATCH_PATHS = 1 << 14  # camera paths in the first launch, before any timing
# pixels per launch: a fixed ladder, so launch sizes repeat from one render to the next
BATCH_LADDER = (256, 1024, 4096, 16384, 65536)

# Light passes in the kernel's order (PASS_*, device/constants.py), named as
# Blender names them; all but Caustics add up to Combined.
LIGHT_PASSES = (
    "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect",
    "Transmission Direct", "Transmission Indirect", "Emission", "Environment", "Caustics",
)
DENOISING_PASSES = ("Denoising Albedo", "Denoising Normal", "Denoising Depth")
assert len(LIGHT_PASSES) == PASS_COUNT
# Cycles compares a pixel's noise with five times the threshold its users
# set; so does this, so that a threshold means here what it means there
NOISE_SCALE = 5.0
MAX_ROUNDS = 16  # later rounds of adaptive sampling take at least samples / this many samples each
MIN_SAMPLES = 4  # fewest samples of a continued film before its pixels' noise is judged (Min Samples 0)
_UNLIMITED = 1 << 30  # a continued film's sample limit: its passes decide how many it takes


def programs(defines: dict) -> list[tuple[str, dict]]:
    """The program the image stage builds with the plan's defines."""
    return [(PROGRAM, defines)]


def film_bytes(window: tuple[int, int, int, int], settings: RenderSettings) -> int:
    """Device bytes of the passes of a render window."""
    x0, y0, x1, y1 = window
    per_pixel = 36  # combined, depth, normal
    if settings.light_passes:
        per_pixel += 16 * len(LIGHT_PASSES)
    if settings.denoising_passes:
        per_pixel += 32
    if adaptive_rounds(settings) is not None:
        per_pixel += 20  # each pixel's even-sample mean and count, and its flag
    return (x1 - x0) * (y1 - y0) * per_pixel


def adaptive_rounds(settings: RenderSettings) -> tuple[int, int] | None:
    """Adaptive sampling's samples in the first round (every pixel) and in
    each later one (the pixels still noisy), or None where every pixel
    takes every sample: no threshold, or a minimum of all the samples.
    Min Samples 0 takes a quarter of the samples, at least 4."""
    if not settings.noise_threshold > 0.0:
        return None
    first = settings.min_samples or max(4, settings.samples // 4)
    if first >= settings.samples:
        return None
    return first, max(first, -(-settings.samples // MAX_ROUNDS))


@dataclass
class ImageFilm:
    """The device buffers of a render window's passes, and per pixel its
    even samples' mean with its sample count (``counts``), whether it
    takes the next round (``active``) and its noise when it last took
    samples (``noise``), kept where the samples come in rounds: adaptive
    sampling, or passes that continue the film."""

    size: tuple[int, int]  # width, height
    combined: cl.Buffer
    depth: cl.Buffer
    normal: cl.Buffer
    light: cl.Buffer  # a stand-in the kernel never writes unless the settings ask for light passes
    albedo: cl.Buffer
    feature_normal: cl.Buffer
    counts: cl.Buffer  # float4 per pixel (even samples' mean, count) where counted, else a stand-in
    active: cl.Buffer  # int per pixel where counted, else a stand-in
    noise: cl.Buffer  # float per pixel where counted: its noise when it last took samples, else a stand-in
    counted: bool
    sample_start: int  # the number of every pixel's first camera path
    samples: int = 0  # the rounds' samples so far: what a pixel that never sat one out has
    taken: int = 0  # samples taken, summed over the pixels
    converged: bool = False  # a round found every pixel's noise below the threshold
    key: object = None  # what the renderer compares before a pass continues the film

    @classmethod
    def new(cls, device: Device, size: tuple[int, int], settings: RenderSettings, sample_start: int,
            counted: bool) -> "ImageFilm":
        """An empty film of ``size`` for the passes ``settings`` ask for;
        ``counted``: keep each pixel's count and flag."""
        total = size[0] * size[1]
        light = device.empty(total * 16 * len(LIGHT_PASSES) if settings.light_passes else 16)
        albedo, feature_normal = (device.empty(total * 16 if settings.denoising_passes else 16) for _ in range(2))
        counts, active, noise = ((device.zeros(total * 16), device.empty(total * 4), device.empty(total * 4))
                                 if counted else (device.empty(16),) * 3)
        if counted:
            device.fill(active, 1, total * 4)
        return cls(size, device.empty(total * 16), device.empty(total * 4), device.empty(total * 16), light, albedo,
                   feature_normal, counts, active, noise, counted, sample_start)

    def buffers(self) -> list:
        """The kernel's output arguments, in Image_pixels' order."""
        return [self.combined, self.depth, self.normal, self.light, self.albedo, self.feature_normal, self.counts,
                self.active]

    def accumulated(self) -> dict:
        """What the film holds, for the stats: samples of the rounds, mean
        samples a pixel took, and whether it has settled."""
        pixels = max(self.size[0] * self.size[1], 1)
        return {"samples": self.samples, "mean_samples": self.taken / pixels, "converged": self.converged,
                "sample_start": self.sample_start}


def _ladder(pixels: int, limit: int) -> int:
    """The largest step of the batch ladder at most ``pixels`` (and ``limit``)."""
    fitting = [b for b in BATCH_LADDER if b <= min(pixels, limit)]
    return fitting[-1] if fitting else min(BATCH_LADDER[0], max(1, limit))


def render_image(device: Device, buffers: SceneBuffers, scene: Scene, settings: RenderSettings, defines: dict,
                 gi_field=None, progress=None, should_stop=None, sample_start: int = 0,
                 film: ImageFilm | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """The passes of the render window (rows from the bottom), and what the
    stage did: its launches (``batches``) and, with adaptive sampling, its
    rounds and mean samples per pixel (``adaptive``). ``gi_field``: the GI
    cache grid (GI mode), else None; ``sample_start``: the number of each
    pixel's first camera path. ``film``: a counted film of the window to
    continue (continue_film) instead of a new one; what it holds then is
    under ``accumulated``."""
    x0, y0, x1, y1 = scene.camera.pixel_window
    w, h = x1 - x0, y1 - y0
    total = w * h
    continuing = film is not None
    rounds = None if continuing else adaptive_rounds(settings)
    if film is None:
        film = ImageFilm.new(device, (w, h), settings, sample_start, counted=rounds is not None)
    outputs = (OUTPUT_DENOISING if settings.denoising_passes else 0) | (OUTPUT_ADAPTIVE if film.counted else 0)
    gi = gi_field.kernel_args() if gi_field is not None else [device.empty(16)] * 4
    job = np.zeros(1, IMAGE_JOB_DTYPE)
    job["origin"], job["window"] = (x0, y0), (w, h, 0, 0)
    # GI mode: indirect diffuse light comes from the cache, so no diffuse bounce is traced
    diffuse = settings.diffuse_bounces if gi_field is None else 0
    job["max_bounces"], job["max_diffuse"] = settings.max_bounces, diffuse
    job["light_samples"], job["seed"], job["clamp"] = settings.light_samples, settings.seed, settings.clamp
    job["outputs"], job["gi_subpixels"] = outputs, gi_field.subpixels if gi_field is not None else 1
    job["sample_start"] = film.sample_start
    job["sample_limit"] = _UNLIMITED if continuing else settings.samples
    kernel = device.kernel(PROGRAM, "Image_pixels", defines)
    scene_args = buffers.kernel_args(settings.transparent_background)
    pixel_filter = device.to_device(filter_table(scene.camera.filter_kind, scene.camera.filter_width))
    args = [*scene_args, job, pixel_filter, *gi, *film.buffers()]
    # the first launch is sized by its path count; later ones by the measured speed
    batch = _ladder(max(_FIRST_BATCH_PATHS // (settings.samples * settings.light_samples), 1), settings.batch_pixels)
    if continuing:
        launches = continue_film(device, kernel, args, job, film, settings, defines, batch, progress, should_stop)
        info = {"batches": launches, "accumulated": film.accumulated()}
        return _read_passes(device, settings, w, h, film), info
    taken, count, launches = 0, (rounds or (settings.samples,))[0], 0
    for number in range(_round_limit(settings, rounds)):
        job["samples"] = count

        def report(start: int) -> None:
            if progress is not None:
                share = min(taken + count * start / total, settings.samples) / settings.samples
                progress(share, f"rendered {start}/{total} pixels" + (f", round {number + 1}" if rounds else ""))

        batch, launched = _launch_round(device, kernel, args, job, (w, h), batch, settings, report, should_stop)
        launches += launched
        taken += count
        if not rounds or not _next_round(device, defines, job, film, settings.noise_threshold, total):
            break
        check_stop(should_stop)
        count = rounds[1]
    info = {"batches": launches}
    if rounds:
        samples = device.read(film.counts, (total, 4), np.float32)[:, 3]
        info["adaptive"] = {"noise_threshold": settings.noise_threshold, "min_samples": rounds[0],
                            "round_samples": rounds[1], "rounds": number + 1, "mean_samples": float(samples.mean()),
                            "stopped_early": float((samples < settings.samples).mean())}
    return _read_passes(device, settings, w, h, film), info


def continue_film(device: Device, kernel, args: list, job, film: ImageFilm, settings: RenderSettings,
                  defines: dict, batch: int, progress, should_stop) -> int:
    """One round of ``settings.samples`` into ``film``: every pixel until
    the film has the minimum samples of adaptive sampling (Min Samples, at
    least 4), then, with a noise threshold, only the pixels still noisy
    (none: the film has converged, nothing is launched). The launches."""
    w, h = film.size
    total, count = w * h, settings.samples
    minimum = settings.min_samples or MIN_SAMPLES
    taking = total
    if settings.noise_threshold > 0.0 and film.samples >= minimum:
        taking = _next_round(device, defines, job, film, settings.noise_threshold, total)
    else:
        device.fill(film.active, 1, total * 4)
    film.converged = taking == 0
    if film.converged:
        return 0
    job["samples"] = count

    def report(start: int) -> None:
        if progress is not None:
            progress(start / total, f"rendered {start}/{total} pixels"
                     + (f" ({100 * taking / total:.0f}% sampling)" if taking < total else ""))

    key, film.key = film.key, None  # a round stopped part-way leaves a film no later pass continues
    _, launches = _launch_round(device, kernel, args, job, (w, h), batch, settings, report, should_stop)
    film.key = key
    film.samples += count
    film.taken += taking * count
    return launches


def _launch_round(device: Device, kernel, args: list, job, size: tuple[int, int], batch: int,
                  settings: RenderSettings, report, should_stop) -> tuple[int, int]:
    """The image kernel over every pixel of the window of ``size`` (``args``:
    its arguments, ``job`` among them), in launches of sizes from the ladder,
    each sized by the speed of the last one finished; ``report(pixels
    done)`` after each, a stop request seen between them. Each launch is
    queued while the one before runs, so the device does not wait for the
    host between them (a stop waits for the running launch and the one
    queued behind it). The next launch's size and the number of launches."""
    (w, h), start, launches = size, 0, 0
    running = None  # (event, pixels, pixels done once it ends) of the launch queued before
    began = time.perf_counter()
    while True:
        queued = None
        if start < w * h:
            pixels = min(batch, w * h - start)
            job["window"] = (w, h, pixels, start)
            start += pixels
            launches += 1
            queued = (kernel(pixels, *args), pixels, start)
        if running is not None:
            event, pixels, done = running
            event.wait()
            now = time.perf_counter()
            elapsed, began = now - began, now  # it ran from the end of the one before
            report(done)
            if queued is not None:
                check_stop(should_stop)
            batch = _ladder(int(pixels * min(settings.batch_seconds / max(elapsed, 1e-4), 4.0)), settings.batch_pixels)
        if queued is None:
            return batch, launches
        running = queued


def _round_limit(settings: RenderSettings, rounds: tuple[int, int] | None) -> int:
    """Most rounds of one render: enough for a pixel that sat some rounds
    out (its neighbours quiet) to reach all the samples when they are not."""
    if rounds is None:
        return 1
    first, later = rounds
    return 1 + 2 * -(-(settings.samples - first) // later)


def _next_round(device: Device, defines: dict, job, film: ImageFilm, threshold: float, total: int) -> int:
    """Flag the pixels of the next round (Image_adaptive_active), once the
    pixels of the round just done have their noise (Image_noise_of); how
    many there are."""
    counter = device.zeros(4)
    device.kernel(PROGRAM, "Image_noise_of", defines)(total, job, film.combined, film.counts, film.active, film.noise)
    device.kernel(PROGRAM, "Image_adaptive_active", defines)(
        total, job, film.noise, film.counts, np.float32(NOISE_SCALE * threshold), film.active, counter)
    return int(device.read(counter, 1, np.int32)[0])


def _read_passes(device: Device, settings: RenderSettings, w: int, h: int, film: ImageFilm) -> dict[str, np.ndarray]:
    """The passes the settings ask for, read back."""
    def rgb(buf) -> np.ndarray:
        return np.ascontiguousarray(device.read(buf, (h, w, 4), np.float32)[..., :3])

    passes = {"Combined": device.read(film.combined, (h, w, 4), np.float32)}
    if settings.geometry_passes or settings.denoising_passes:
        passes["Depth"] = device.read(film.depth, (h, w, 1), np.float32)
    if settings.geometry_passes:
        passes["Normal"] = rgb(film.normal)
    if settings.light_passes:
        layers = device.read(film.light, (len(LIGHT_PASSES), h, w, 4), np.float32)
        passes.update((name, np.ascontiguousarray(layers[i, ..., :3])) for i, name in enumerate(LIGHT_PASSES))
    if settings.denoising_passes:
        passes["Denoising Albedo"] = rgb(film.albedo)
        passes["Denoising Normal"] = rgb(film.feature_normal)
        passes["Denoising Depth"] = passes["Depth"].copy() if settings.geometry_passes else passes.pop("Depth")
    return passes
