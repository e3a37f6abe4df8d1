"""Irradiance cache: choosing the sample points among the shading points, and
interpolating the irradiance gathered at them to every shading point [WZPB09].

``select_samples`` seeds adaptively over a screen-space quadtree and
refines by k-means under the illumination-change error

    eps(x_i, x_k) = alpha |x_i - x_k| + sqrt(2 - 2 n_i . n_k);

``interpolate`` blends the samples' irradiance with Ward's weights
(gpu_core/cache_interpolation.py). Both run on the device; positions are
moved and scaled on the host (in float64) so the box of the points is
centred at the origin with largest side 1, which makes the results the same
for a scene at any scale or distance from the origin.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import cache_clusters, cache_seeding
from .cache_frame import Frame, finite_rows, float4
from .cache_interpolation import interpolate
from .device import Device

__all__ = ["SampleSet", "select_samples", "interpolate", "ALPHA0"]

ALPHA0 = 0.6  # default alpha times the largest side of the shading points' box
MAX_ITERATIONS = 4  # default cap on k-means iterations (gains flatten out after 3-4)
CONVERGE_FRACTION = 0.01  # k-means stops once at most this fraction of points changed cluster


@dataclass
class SampleSet:
    """The chosen sample points, one per non-empty cluster."""

    indices: np.ndarray  # int32 (M,): indices into the shading points
    positions: np.ndarray  # float32 (M, 3)
    normals: np.ndarray  # float32 (M, 3)
    cluster_of: np.ndarray  # int32 (N,): the sample (0..M-1) whose cluster holds each point
    centre_positions: np.ndarray  # float32 (M, 3): cluster centres the points were assigned to
    centre_normals: np.ndarray  # float32 (M, 3)
    stats: dict = field(default_factory=dict)


def select_samples(device: Device, positions, normals, pixels, width: int, height: int, count: int,
                   alpha: float | None = None, max_iterations: int = MAX_ITERATIONS,
                   converge_fraction: float = CONVERGE_FRACTION, seed: int = 0) -> SampleSet:
    """Choose about ``count`` irradiance sample points among the shading points.

    positions, normals: (N, 3) float32, normals unit; pixels: (N, 2) int32
    (x, y) inside a ``width`` x ``height`` image, several points per pixel
    allowed. ``alpha`` weighs distance against normal change in eps, in 1 /
    scene units; None means ``ALPHA0`` / the largest side of the points' box.
    Returns one sample per non-empty cluster: ``count`` of them (fewer only
    when there are fewer points, or when identical points tie).
    """
    started = time.perf_counter()
    pos = finite_rows("positions", positions, 3, np.float32)
    nrm = finite_rows("normals", normals, 3, np.float32)
    pix = finite_rows("pixels", pixels, 2, np.int32)
    n = len(pos)
    if len(nrm) != n or len(pix) != n:
        raise ValueError(f"positions, normals and pixels differ in length ({n}, {len(nrm)}, {len(pix)})")
    if width < 1 or height < 1:
        raise ValueError(f"image size {width} x {height} is empty")
    if n and ((pix.min(axis=0) < 0).any() or (pix.max(axis=0) >= (width, height)).any()):
        raise ValueError(f"pixel coordinates fall outside the {width} x {height} image")
    if count < 1 or max_iterations < 1 or not 0.0 <= converge_fraction <= 1.0:
        raise ValueError(f"need count >= 1, max_iterations >= 1 and converge_fraction in [0, 1], not "
                         f"{count}, {max_iterations}, {converge_fraction}")
    frame = Frame.around(pos)
    alpha_world = ALPHA0 / frame.extent if alpha is None else float(alpha)
    if not (np.isfinite(alpha_world) and alpha_world >= 0.0):
        raise ValueError(f"alpha must be finite and >= 0, not {alpha}")
    alpha_n = alpha_world * frame.extent  # alpha in normalised units
    stats = {"points": n, "alpha": alpha_world, "alpha_normalised": alpha_n, "ms": {}}
    if n == 0:
        empty3 = np.zeros((0, 3), np.float32)
        stats.update(seeds=0, clusters=0, empty_clusters=0, iterations=0, changed_fraction=0.0, converged=True)
        return SampleSet(np.zeros(0, np.int32), empty3, empty3, np.zeros(0, np.int32), empty3, empty3, stats)
    ms = stats["ms"]

    def lap(stage: str, since: float) -> float:
        device.queue.finish()
        now = time.perf_counter()
        ms[stage] = (now - since) * 1e3
        return now

    pos4 = frame.to_device(pos)
    d_pos, d_nrm, d_pix = device.buffer(pos4), device.buffer(float4(nrm)), device.buffer(pix)
    t = lap("upload", started)
    tree = cache_seeding.build(device, d_pos, d_nrm, d_pix, n, width, height, alpha_n)
    t = lap("quadtree", t)
    seeds, k = cache_seeding.seed(device, tree, d_pos, d_nrm, count, alpha_n, seed)
    t = lap("seeding", t)
    result = cache_clusters.cluster(device, d_pos, d_nrm, n, seeds, k, alpha_n, max_iterations, converge_fraction)
    lap("kmeans", t)
    # keep the non-empty clusters, renumbered in order
    kept = np.flatnonzero(result.sample_of >= 0)
    renumber = np.full(k, -1, np.int32)
    renumber[kept] = np.arange(len(kept), dtype=np.int32)
    indices = result.sample_of[kept].astype(np.int32)
    stats.update(
        seeds=k,
        clusters=len(kept),
        empty_clusters=k - len(kept),
        iterations=result.iterations,
        changed_fraction=result.changed_fraction,
        converged=bool(result.converged),
        restarts=result.restarts,
        quadtree_levels=len(tree.levels),
        leaf_pixels=1 << tree.leaf_shift,
    )
    ms["total"] = (time.perf_counter() - started) * 1e3
    return SampleSet(
        indices=indices,
        positions=pos[indices],
        normals=nrm[indices],
        cluster_of=renumber[result.cluster_of],
        centre_positions=frame.to_world(result.centre_pos[kept]),
        centre_normals=result.centre_nrm[kept].astype(np.float32),
        stats=stats,
    )
