"""Indirect diffuse light and caustics of the image [WZPB09].

Per render: photon maps (global, and caustic where the scene can make
caustics); shading points (each pixel's first diffuse hit); irradiance
sample points chosen among them (adaptive seeding + k-means); the
illumination cut of the global photon tree; final gathering at the sample
points through the cut; Ward interpolation to every shading point; caustics
by density estimation of the caustic map at the shading points. The
image kernel reads the irradiance back at its camera paths' first diffuse
hits and adds direct light and specular paths, traced.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import cache, cut, gather, shading_points
from .device import Device
from .photons import PhotonMaps, PointTree, trace_photon_maps
from .scene import Scene, scene_digest
from .settings import RenderSettings

OUTLIER_NEIGHBOURS = 8  # samples a cache sample is compared with
OUTLIER_RATIO = 4.0  # largest irradiance of a sample over its neighbours' median


@dataclass
class GiField:
    """Irradiance at the shading-point grid of a render window (see
    shading_points.py), which the image kernel reads (render.cl, RENDER_GI)."""

    positions: np.ndarray  # (M, 4) float32 per grid slot: xyz, w = 1 where there is a point
    normals: np.ndarray  # (M, 4) float32
    indirect: np.ndarray  # (M, 4) float32: indirect irradiance (rgb)
    caustics: np.ndarray  # (M, 4) float32: caustic irradiance (rgb)
    subpixels: int
    stats: dict = field(default_factory=dict)


class PhotonReuse:
    """The last photon maps traced, kept while neither the scene (geometry,
    materials, lights, world) nor the photon settings change: a render that
    only moves the camera does not trace photons again."""

    def __init__(self):
        self._key: bytes | None = None
        self._maps: PhotonMaps | None = None

    def maps(self, device: Device, scene: Scene, settings: RenderSettings, up=None) -> tuple[PhotonMaps, bool]:
        """The photon maps for ``scene`` (traced through the renderer's
        upload ``up`` when given), and whether they were reused."""
        key = _photon_key(scene, settings)
        if key == self._key and self._maps is not None:
            return self._maps, True
        self._maps = trace_photon_maps(device, scene, settings.global_photons, settings.caustic_photons,
                                       seed=settings.seed, k_hint=settings.photon_k, uploaded=up)
        self._key = key
        return self._maps, False


def _photon_key(scene: Scene, settings: RenderSettings) -> bytes:
    """A digest of everything photon tracing reads (not the camera)."""
    knobs = (settings.global_photons, settings.caustic_photons, settings.seed, settings.photon_k)
    return scene_digest(scene) + repr(knobs).encode()


def render_gi(device: Device, scene: Scene, up, window: tuple[int, int, int, int], settings: RenderSettings,
              reuse: PhotonReuse | None = None) -> GiField:
    """Indirect and caustic irradiance at the shading points of the pixels
    in ``window`` for a validated ``scene`` uploaded by the renderer (``up``,
    same centre); ``reuse`` keeps photon maps from one render to the next."""
    x0, y0, x1, y1 = window
    w, h = x1 - x0, y1 - y0
    ms: dict[str, float] = {}
    stats: dict = {"ms": ms}

    began = time.perf_counter()
    maps, reused = (reuse or PhotonReuse()).maps(device, scene, settings, up)
    ms["photons"] = (time.perf_counter() - began) * 1e3
    stats.update(photons=maps.stats, photons_reused=reused)

    began = time.perf_counter()
    points = shading_points.trace(device, up, window, settings.max_bounces)
    ms["shading_points"] = (time.perf_counter() - began) * 1e3
    stats["shading_points"] = len(points.positions)
    irradiance = np.zeros((len(points.positions), 3), np.float32)
    caustic = np.zeros_like(irradiance)

    if maps.global_map is not None and len(points.positions):
        began = time.perf_counter()
        extent = float(np.ptp(points.positions, axis=0).max())
        alpha = settings.cache_alpha / extent if extent > 0 else None
        samples = cache.select_samples(device, points.positions, points.normals, points.pixels, w, h,
                                       min(settings.cache_seeds, len(points.positions)), alpha=alpha,
                                       seed=settings.seed)
        ms["sample_points"] = (time.perf_counter() - began) * 1e3
        began = time.perf_counter()
        the_cut = cut.select(device, maps.global_map, settings.photon_k, delta=settings.cut_delta)
        ms["cut"] = (time.perf_counter() - began) * 1e3
        gathered = gather.gather(device, up, samples.positions, samples.normals, _strata(settings.gather_rays),
                                 _irradiance_at(the_cut, maps.caustic_map, settings.photon_k), seed=settings.seed)
        ms["gather"] = gathered.stats["ms"]["total"]
        began = time.perf_counter()
        sample_irradiance, clamped = _clamp_outliers(device, samples.positions, gathered.irradiance)
        irradiance, interp = cache.interpolate(device, samples.positions, samples.normals, sample_irradiance,
                                               gathered.harmonic_distance, points.positions, points.normals)
        ms["interpolate"] = (time.perf_counter() - began) * 1e3
        stats.update(sample_points=len(samples.indices), cut=the_cut.stats, gather=gathered.stats,
                     outliers_clamped=clamped,
                     interpolation={k: v for k, v in interp.items() if k != "ms"})
    if maps.caustic_map is not None and len(points.positions):
        began = time.perf_counter()
        caustic = maps.caustic_map.irradiance(points.positions, points.normals, settings.photon_k)
        ms["caustics"] = (time.perf_counter() - began) * 1e3

    return GiField(*(_grid(points, values) for values in (points.positions, points.normals, irradiance, caustic)),
                   subpixels=points.subpixels, stats=stats)


def _clamp_outliers(device: Device, positions: np.ndarray, irradiance: np.ndarray) -> tuple[np.ndarray, int]:
    """Sample irradiance with lone outliers brought down to OUTLIER_RATIO
    times the median of their nearest samples. A few gather rays that hit a
    small, very bright spot (a focused caustic) make one sample far
    brighter than its neighbours, and interpolation would spread it into a
    blotch; where the neighbours see the light too, nothing changes."""
    m = len(positions)
    if m <= OUTLIER_NEIGHBOURS:
        return irradiance, 0
    tree = PointTree.build(device, positions)
    idx, _ = tree.knn(positions, OUTLIER_NEIGHBOURS + 1)
    luminance = irradiance.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    neighbours = np.where(idx[:, 1:] >= 0, luminance[np.maximum(idx[:, 1:], 0)], np.nan)
    limit = OUTLIER_RATIO * np.nanmedian(neighbours, axis=1)
    over = luminance > np.maximum(limit, 0.0)
    scale = np.where(over, limit / np.maximum(luminance, 1e-30), 1.0)
    return (irradiance * scale[:, None]).astype(np.float32), int(over.sum())


def _irradiance_at(the_cut: cut.Cut, caustic_map, k: int):
    """Irradiance at gather hits: the global map's smooth light through its
    cut, plus caustic light by density estimation of the caustic map (which
    the global map leaves out where there is one: a cut would smear it)."""
    if caustic_map is None:
        return the_cut.irradiance_at

    def both(points, normals):
        return the_cut.irradiance_at(points, normals) + caustic_map.irradiance(points, normals, k)

    return both


def plan(stats: dict) -> list[str]:
    """The GI stages a render ran, for the renderer's plan: which photon maps
    were traced (or reused), and the cache stages where there was light."""
    maps = stats["photons"].get("maps", {})
    stages = []
    for name in ("global", "caustic"):
        if str(maps.get(name, "")).startswith("built"):
            stages.append(f"{name}_photons" + ("_reused" if stats["photons_reused"] else ""))
    if "cut" in stats:
        stages += ["sample_points", "illumination_cut", "final_gather", "interpolation"]
    if "caustics" in stats["ms"]:
        stages.append("caustics")
    return stages


def _strata(rays: int) -> int:
    """Strata per side for about ``rays`` gather rays (strata² rays)."""
    return max(1, int(round(np.sqrt(max(int(rays), 1)))))


def _grid(points: shading_points.ShadingPoints, values: np.ndarray) -> np.ndarray:
    """Per-point values (N, 3) in the shading-point grid as (M, 4) float32,
    w = 1 where a slot holds a point (0 elsewhere)."""
    out = np.zeros((points.grid_size, 4), np.float32)
    out[points.slots, :3] = np.nan_to_num(values, nan=0.0, posinf=0.0)
    out[points.slots, 3] = 1.0
    return out
