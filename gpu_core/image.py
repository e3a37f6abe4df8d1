"""The image stage (image.cl): camera paths over the render window, in
launches of a bounded number of pixels so that progress is reported and a
request to stop is seen between them, then the passes read back.

In GI mode the kernel reads the GI cache through the shading-point grid
(gi/pipeline.py) that the stages before it left on the device.
"""

from __future__ import annotations

import time

import numpy as np

from .device import Device
from .device.constants import OUTPUT_DENOISING, PASS_COUNT
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
    return (x1 - x0) * (y1 - y0) * per_pixel


def _ladder(pixels: int, limit: int) -> int:
    """The largest step of the batch ladder at most ``pixels`` (and ``limit``)."""
    fitting = [b for b in BATCH_LADDER if b <= min(pixels, limit)]
    return fitting[-1] if fitting else min(BATCH_LADDER[0], max(1, limit))


def render_image(device: Device, buffers: SceneBuffers, scene: Scene, settings: RenderSettings, defines: dict,
                 gi_field=None, progress=None, should_stop=None, sample_start: int = 0
                 ) -> tuple[dict[str, np.ndarray], int]:
    """The passes of the render window (rows from the bottom) and the number
    of launches. ``gi_field``: the GI cache grid (GI mode), else None;
    ``sample_start``: the number of each pixel's first camera path."""
    x0, y0, x1, y1 = scene.camera.pixel_window
    w, h = x1 - x0, y1 - y0
    total = w * h
    outputs = OUTPUT_DENOISING if settings.denoising_passes else 0
    combined, depth, normal = device.empty(total * 16), device.empty(total * 4), device.empty(total * 16)
    # passes nobody asked for get a stand-in the kernel never writes
    light = device.empty(total * 16 * len(LIGHT_PASSES) if settings.light_passes else 16)
    albedo, feature_normal = (device.empty(total * 16 if settings.denoising_passes else 16) for _ in range(2))
    gi = gi_field.kernel_args() if gi_field is not None else [device.empty(16)] * 4
    job = np.zeros(1, IMAGE_JOB_DTYPE)
    job["origin"] = (x0, y0)
    # GI mode: indirect diffuse light comes from the cache, so no diffuse bounce is traced
    diffuse = settings.diffuse_bounces if gi_field is None else 0
    job["samples"], job["max_bounces"], job["max_diffuse"] = settings.samples, settings.max_bounces, diffuse
    job["light_samples"], job["seed"], job["clamp"] = settings.light_samples, settings.seed, settings.clamp
    job["outputs"], job["gi_subpixels"] = outputs, gi_field.subpixels if gi_field is not None else 1
    job["sample_start"] = sample_start
    kernel = device.kernel(PROGRAM, "Image_pixels", defines)
    scene_args = buffers.kernel_args(settings.transparent_background)
    pixel_filter = device.to_device(filter_table(scene.camera.filter_kind, scene.camera.filter_width))
    # the first launch is sized by its path count; later ones by the measured speed
    paths_per_pixel = settings.samples * settings.light_samples
    batch = _ladder(max(_FIRST_BATCH_PATHS // paths_per_pixel, 1), settings.batch_pixels)
    start, batches = 0, 0
    while start < total:
        count = min(batch, total - start)
        job["window"] = (w, h, count, start)
        began = time.perf_counter()
        kernel(count, *scene_args, job, pixel_filter, *gi, combined, depth, normal, light, albedo, feature_normal)
        device.queue.finish()
        elapsed = time.perf_counter() - began
        start += count
        batches += 1
        if progress is not None:
            progress(start / total, f"rendered {start}/{total} pixels")
        if start < total:
            check_stop(should_stop)
        batch = _ladder(int(count * min(settings.batch_seconds / max(elapsed, 1e-4), 4.0)), settings.batch_pixels)
    return _read_passes(device, settings, w, h, combined, depth, normal, light, albedo, feature_normal), batches


def _read_passes(device: Device, settings: RenderSettings, w: int, h: int, combined, depth, normal, light, albedo,
                 feature_normal) -> dict[str, np.ndarray]:
    """The passes the settings ask for, read back."""
    def rgb(buf) -> np.ndarray:
        return np.ascontiguousarray(device.read(buf, (h, w, 4), np.float32)[..., :3])

    passes = {"Combined": device.read(combined, (h, w, 4), np.float32), "Depth": device.read(depth, (h, w, 1), np.float32),
              "Normal": rgb(normal)}
    if settings.light_passes:
        layers = device.read(light, (len(LIGHT_PASSES), h, w, 4), np.float32)
        passes.update((name, np.ascontiguousarray(layers[i, ..., :3])) for i, name in enumerate(LIGHT_PASSES))
    if settings.denoising_passes:
        passes["Denoising Albedo"] = rgb(albedo)
        passes["Denoising Normal"] = rgb(feature_normal)
        passes["Denoising Depth"] = passes["Depth"].copy()
    return passes
