"""Indirect diffuse light and caustics of the image [WZPB09], stage after
stage on the device.

Per render (the photon maps come from the renderer, traced or kept):
shading points (each pixel's first diffuse hits); irradiance sample points
chosen among them (adaptive seeding + k-means); the illumination cut of the
global photon tree, its nodes also carrying the caustic map's light; final
gathering at the sample points through the cut;
lone outliers clamped; Ward interpolation to every shading point; caustics
by density estimation of the caustic map at the shading points. Each stage
reads the buffers the stage before wrote; the image kernel then reads the
irradiance back at its camera paths' first diffuse hits through the
shading-point grid (``GiField``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl

from ..device import Device
from ..accel.point_tree import query_programs
from ..device.timer import StageTimer
from ..errors import check_stop
from ..photons.trace import PhotonMaps
from ..scene.upload import SceneBuffers
from ..settings import RenderSettings
from . import cut, gather, shading_points
from .cache import interpolation, outliers, samples


@dataclass
class GiField:
    """Irradiance on the shading-point grid of a render window, on the
    device, as the image kernel reads it (IMAGE_GI_PARAMS in image.cl)."""

    positions: cl.Buffer  # float4 per grid slot: xyz, w = 1 where there is a point
    normals: cl.Buffer  # float4 per grid slot
    indirect: cl.Buffer  # float4 per grid slot: indirect irradiance (rgb)
    caustics: cl.Buffer  # float4 per grid slot: caustic irradiance (rgb)
    subpixels: int
    stats: dict = field(default_factory=dict)

    def kernel_args(self) -> list:
        return [self.positions, self.normals, self.indirect, self.caustics]


def strata(rays: int) -> int:
    """Strata per side for about ``rays`` gather rays (strata² rays)."""
    return max(1, int(round(np.sqrt(max(int(rays), 1)))))


def render_gi(device: Device, buffers: SceneBuffers, window: tuple[int, int, int, int], settings: RenderSettings,
              maps: PhotonMaps, stages: list[str], scene_defines: dict, timer: StageTimer,
              should_stop: Callable[[], bool] | None = None) -> GiField:
    """The GI field of the pixels in ``window`` for a scene on the device;
    ``stages`` (the plan) says which cache stages run. ``should_stop`` is
    polled between the stages and between gather batches (RenderCancelled)."""
    stats: dict = {"photons": maps.stats}
    with timer.stage("shading_points"):
        points = shading_points.trace(device, buffers, window, settings.max_bounces, settings.gi_subpixels,
                                        scene_defines)
    n = stats["shading_points"] = points.count
    check_stop(should_stop)
    indirect = caustic = None
    if "final_gather" in stages and n:
        with timer.stage("sample_points"):
            chosen = samples.select(device, points.pos, points.nrm, points.pixel, n, points.width, points.height,
                                    min(settings.cache_seeds, n), alpha=settings.cache_alpha, seed=settings.seed)
        check_stop(should_stop)
        with timer.stage("cut"):
            the_cut, gather_cut, cut_reused = _cut(device, maps, settings)
        check_stop(should_stop)
        with timer.stage("gather"):
            gathered = gather.gather(device, buffers, chosen.pos, chosen.nrm, chosen.count,
                                     strata(settings.gather_rays), gather_cut, settings.seed, settings.max_bounces,
                                     scene_defines, should_stop)
        check_stop(should_stop)
        with timer.stage("interpolate"):
            clamped, outliers_clamped = outliers.clamp_outliers(device, chosen.pos, gathered.e, chosen.count)
            irradiance, interp = interpolation.interpolate_on_device(
                device, chosen.pos, chosen.nrm, clamped, gathered.distance, chosen.count, points.pos, points.nrm, n)
            indirect = points.scatter(irradiance)
        stats.update(sample_points=chosen.count, cut={**the_cut.stats, "reused": cut_reused}, gather=gathered.stats,
                     outliers_clamped=outliers_clamped, interpolation={k: v for k, v in interp.items() if k != "ms"})
        check_stop(should_stop)
    if "caustics" in stages and n:
        with timer.stage("caustics"):
            estimate = device.empty(16 * n)
            maps.caustic_map.irradiance_on_device(points.pos, points.nrm, n, settings.photon_k, estimate)
            caustic = points.scatter(estimate)
    zeros = device.zeros(16 * points.grid_size) if indirect is None or caustic is None else None
    return GiField(points.grid_pos, points.grid_nrm, indirect if indirect is not None else zeros,
                   caustic if caustic is not None else zeros, points.subpixels, stats)


def _cut(device: Device, maps: PhotonMaps, settings: RenderSettings) -> tuple:
    """The illumination cut of the global map, the cut gathering reads
    (caustic light added), and whether they were kept: a function of the
    maps and two settings, computed once per photon maps for every view."""
    key = ("cut", settings.photon_k, settings.cut_delta)
    reused = key in maps.derived
    if not reused:
        the_cut = cut.select(device, maps.global_map, settings.photon_k, delta=settings.cut_delta)
        maps.derived[key] = (the_cut, cut.with_caustics(the_cut, maps.caustic_map, settings.photon_k))
    return (*maps.derived[key], reused)


def programs(device: Device, settings: RenderSettings, stages: list[str], scene_defines: dict) -> list:
    """The programs the GI stages of ``stages`` build."""
    wanted = shading_points.programs(scene_defines)
    if "final_gather" in stages:
        wanted += samples.programs() + cut.programs(settings.photon_k)
        wanted += gather.programs(device, scene_defines) + outliers.programs()
        wanted += interpolation.programs()
    if "caustics" in stages:
        wanted += query_programs(settings.photon_k)
    return wanted
