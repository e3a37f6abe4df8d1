"""Indirect diffuse light and caustics of the image [WZPB09], stage after
stage on the device.

Per render (the photon maps come from the renderer, traced or kept):
shading points (each pixel's first diffuse hits); irradiance sample points
chosen among them (adaptive seeding + k-means); the illumination cut of the
global photon tree, its nodes also carrying the caustic map's light; final
gathering at the sample points through the cut;
lone outliers and the samples' distances clamped by their neighbours';
Ward interpolation to every shading point; caustics
by density estimation of the caustic map on the shading points' grid
(``caustics``). Each stage
reads the buffers the stage before wrote; the image kernel then reads the
irradiance back at its camera paths' first diffuse hits through the
shading-point grid (``GiField``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl

from ..device import Device, primitives
from ..accel.point_tree import query_programs
from ..device.timer import StageTimer
from ..errors import check_stop
from ..photons.trace import PhotonMaps
from ..scene.upload import SceneBuffers
from ..settings import RenderSettings
from . import caustics, cut, gather, shading_points
from .cache import interpolation, neighbours, samples


# what the stats tell of the choice of cache points (samples.select)
_SELECTION_STATS = ("warm_start", "iterations", "changed_fraction", "converged", "restarts", "empty_clusters")
# gather streams set aside per record: new records of a later view draw the streams after the kept ones'
_STREAMS = 7919


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
    glossy_cut: cut.Cut | None = None  # with glossy surfaces: the cut their paths read (IMAGE_GLOSSY_CUT)

    def kernel_args(self) -> list:
        grid = [self.positions, self.normals, self.indirect, self.caustics]
        return grid + (self.glossy_cut.kernel_args() if self.glossy_cut is not None else [])


def strata(rays: int) -> int:
    """Strata per side for about ``rays`` gather rays (strata² rays)."""
    return max(1, int(round(np.sqrt(max(int(rays), 1)))))


@dataclass
class CacheRecords:
    """Gathered irradiance records in world space (the scene's device
    frame): what a later view of the same lit scene can interpolate from."""

    pos: cl.Buffer  # float4 per record
    nrm: cl.Buffer  # float4 per record, unit
    e: cl.Buffer  # float4 per record: irradiance (outliers clamped)
    r: cl.Buffer  # float per record: harmonic mean distance R_j (neighbour-clamped)
    grad: cl.Buffer  # three float4 per record: translational irradiance gradient (gather.GatherResult)
    count: int


def render_gi(device: Device, buffers: SceneBuffers, window: tuple[int, int, int, int], settings: RenderSettings,
              maps: PhotonMaps, stages: list[str], scene_defines: dict, timer: StageTimer,
              should_stop: Callable[[], bool] | None = None, records: CacheRecords | None = None,
              say: Callable[[str], None] | None = None,
              held_samples: samples.HeldSamples | None = None) -> tuple[GiField, CacheRecords | None]:
    """The GI field of the pixels in ``window`` for a scene on the device,
    and the cache records it was interpolated from; ``stages`` (the plan)
    says which cache stages run. ``records`` (of an earlier view of the
    same lit scene) are kept: only the shading points they do not cover
    get new cache points and gathering. ``held_samples`` keeps the cache
    points of earlier renders, taken again where the shading points are
    the same. ``should_stop`` is polled between
    the stages and between gather batches (RenderCancelled); ``say`` is
    told the name of each stage as it starts (the status line)."""
    say = say or (lambda text: None)
    stats: dict = {"photons": maps.stats}
    say("shading points")
    with timer.stage("shading_points"):
        points = shading_points.trace(device, buffers, window, settings.max_bounces, settings.gi_subpixels,
                                        scene_defines)
    n = stats["shading_points"] = points.count
    check_stop(should_stop)
    indirect = caustic = None
    if "final_gather" in stages and n:
        irradiance, records = _cached_irradiance(device, buffers, points, settings, maps, scene_defines, timer,
                                                 should_stop, records, stats, say,
                                                 held_samples or samples.HeldSamples())
        indirect = points.scatter(irradiance)
        check_stop(should_stop)
    if "caustics" in stages and n:
        say("caustics")
        with timer.stage("caustics"):
            caustic = caustics.irradiance(maps.caustic_map, points, settings.caustic_k)
    zeros = device.zeros(16 * points.grid_size) if indirect is None or caustic is None else None
    # glossy paths read the diffuse light where they land from the cut
    glossy_cut = _cut(device, maps, settings)[1] if "glossy_cut" in stages else None
    field_ = GiField(points.grid_pos, points.grid_nrm, indirect if indirect is not None else zeros,
                     caustic if caustic is not None else zeros, points.subpixels, stats, glossy_cut)
    return field_, records


def _cached_irradiance(device: Device, buffers: SceneBuffers, points, settings: RenderSettings, maps: PhotonMaps,
                       scene_defines: dict, timer: StageTimer, should_stop, records: CacheRecords | None,
                       stats: dict, say, held_samples: samples.HeldSamples) -> tuple[cl.Buffer, CacheRecords]:
    """Indirect irradiance (float4 per shading point) and the records it
    comes from: cache points chosen among the points ``records`` leave
    uncovered (all of them without records), gathered, clamped, and
    interpolated together with the records kept."""
    n = points.count
    prior = index = None
    todo, kept = points, 0
    if records is not None and records.count:
        say("cache coverage")
        with timer.stage("coverage"):
            flag = device.empty(4 * n)
            prior, _ = interpolation.interpolate_on_device(device, records.pos, records.nrm, records.e, records.r,
                                                           records.count, points.pos, points.nrm, n, flag=flag,
                                                           sgrad=records.grad)
            index, left = interpolation.uncovered(device, flag, n)
            todo, kept = shading_points.subset(points, index, left), records.count
        check_stop(should_stop)
    new = None
    if todo.count:
        seeds = settings.cache_seeds if index is None else max(1, round(settings.cache_seeds * todo.count / n))
        say("cache points")
        with timer.stage("sample_points"):
            args = (device, todo.pos, todo.nrm, todo.pixel, todo.count, todo.width, todo.height, min(seeds, todo.count))
            if index is None:
                chosen, samples_reused = held_samples.select(*args, settings.cache_alpha, settings.seed,
                                                             warm=settings.cache_reuse,
                                                             max_iterations=settings.cache_iterations)
            else:  # the points the records leave uncovered: a new subset each view, not held
                chosen = samples.select(*args, settings.cache_alpha, max_iterations=settings.cache_iterations,
                                        seed=settings.seed)
                samples_reused = False
        check_stop(should_stop)
        with timer.stage("cut"):
            the_cut, gather_cut, cut_reused = _cut(device, maps, settings)
        check_stop(should_stop)
        say("gathering")
        with timer.stage("gather"):
            # the streams of new records go on from the kept ones' (no repeated noise)
            gathered = gather.gather(device, buffers, chosen.pos, chosen.nrm, chosen.count,
                                     strata(settings.gather_rays), gather_cut, settings.seed + _STREAMS * kept,
                                     settings.max_bounces, scene_defines, should_stop)
        check_stop(should_stop)
        with timer.stage("interpolate"):
            checked = neighbours.check(device, chosen.pos, chosen.nrm, gathered.e, gathered.distance, chosen.count)
        new = CacheRecords(chosen.pos, chosen.nrm, checked.irradiance, checked.radii, gathered.gradient, chosen.count)
        stats.update(sample_points=chosen.count, sample_points_reused=samples_reused,
                     selection={key: chosen.stats.get(key) for key in _SELECTION_STATS},
                     cut={**the_cut.stats, "reused": cut_reused}, gather=gathered.stats,
                     outliers_clamped=checked.outliers_clamped, radii_clamped=checked.radii_clamped,
                     radii_bounded=checked.radii_bounded)
    merged = _merged(device, records if kept else None, new)
    stats["records"] = {"kept": kept, "new": new.count if new else 0, "uncovered": todo.count / n}
    say("interpolation")
    with timer.stage("interpolate"):
        if index is None:
            irradiance, interp = interpolation.interpolate_on_device(
                device, merged.pos, merged.nrm, merged.e, merged.r, merged.count, points.pos, points.nrm, n,
                sgrad=merged.grad)
        else:  # covered points keep the records' value; the others are interpolated from all records
            irradiance, interp = prior, {}
            if todo.count:
                filled, interp = interpolation.interpolate_on_device(
                    device, merged.pos, merged.nrm, merged.e, merged.r, merged.count, todo.pos, todo.nrm, todo.count,
                    sgrad=merged.grad)
                primitives.scatter_rows(device, filled, index, todo.count, irradiance)
    stats["interpolation"] = {k: v for k, v in interp.items() if k != "ms"}
    return irradiance, merged


def _merged(device: Device, kept: CacheRecords | None, new: CacheRecords | None) -> CacheRecords:
    """The records kept followed by the new ones."""
    if kept is None or new is None:
        return kept or new
    parts = [(kept, kept.count), (new, new.count)]
    return CacheRecords(*(primitives.concatenated(device, [(getattr(r, name), c) for r, c in parts], size)
                          for name, size in (("pos", 16), ("nrm", 16), ("e", 16), ("r", 4), ("grad", 48))),
                        kept.count + new.count)


def _cut(device: Device, maps: PhotonMaps, settings: RenderSettings) -> tuple:
    """The illumination cut of the global map, the cut gathering reads
    (caustic light added), and whether they were kept: a function of the
    maps and three settings, computed once per photon maps for every view."""
    key = ("cut", settings.photon_k, settings.caustic_k, settings.cut_delta)
    reused = key in maps.derived
    if not reused:
        the_cut = cut.select(device, maps.global_map, settings.photon_k, delta=settings.cut_delta)
        maps.derived[key] = (the_cut, cut.with_caustics(the_cut, maps.caustic_map, settings.caustic_k))
    return (*maps.derived[key], reused)


def programs(device: Device, settings: RenderSettings, stages: list[str], scene_defines: dict) -> list:
    """The programs the GI stages of ``stages`` build."""
    wanted = shading_points.programs(scene_defines)
    if "final_gather" in stages:
        wanted += samples.programs() + cut.programs(settings.photon_k)
        wanted += gather.programs(scene_defines) + neighbours.programs()
        wanted += interpolation.programs()
    if "caustics" in stages:
        wanted += caustics.programs(settings.caustic_k)  # the caustic map's estimates seen directly
        wanted += query_programs(settings.caustic_k)  # and in the cut's nodes
    return wanted
