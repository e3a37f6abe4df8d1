"""Choosing the irradiance sample points among the shading points [WZPB09].

Adaptive seeding over a screen-space quadtree (seeding.py), then k-means
(clusters.py) under the illumination-change error

    eps(x_i, x_k) = alpha |x_i - x_k| + sqrt(2 - 2 n_i . n_k),

one sample per cluster: its member nearest the centre. Everything runs on
the device in the cache's normalised frame (frame.py), where alpha is
relative to the largest side of the shading points' box.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from ...accel.point_tree_build import PROGRAM as POINT_TREE_BUILD
from ...device import Device, primitives
from ...device.layout import finite_rows, float4_rows
from ...device.timer import StageTimer
from . import clusters as cache_clusters
from . import seeding as cache_seeding
from ..points import DevicePoints
from .frame import Frame

def programs() -> list[tuple[str, dict]]:
    """The programs choosing samples builds (the k-means centres' tree included)."""
    return [(name, {}) for name in ("gi/cache/frame.cl", "gi/cache/seeding.cl", POINT_TREE_BUILD, "gi/cache/clusters.cl")]


ALPHA0 = 0.6  # default alpha times the largest side of the shading points' box
MAX_ITERATIONS = 4  # default cap on k-means iterations (the Cache Iterations setting's default)
CONVERGE_FRACTION = 0.01  # k-means stops once at most this fraction of points changed cluster
WARM_ITERATIONS = 2  # k-means iterations from an earlier render's samples (their centres have settled)


@dataclass
class SampleSet(DevicePoints):
    """The chosen sample points, one per non-empty cluster, on the device."""

    device: Device
    index: cl.Buffer  # int (M,): indices into the shading points
    pos: cl.Buffer  # float4 (M,): positions, in the frame of the shading points given
    nrm: cl.Buffer  # float4 (M,): unit normals
    count: int
    frame: Frame  # the cache's normalised frame
    clusters: cache_clusters.Clusters
    kept: np.ndarray  # int32 (M,): the centres that kept a sample
    point_count: int
    stats: dict = field(default_factory=dict)

    # -- host copies, for tests and statistics --------------------------------

    @property
    def indices(self) -> np.ndarray:
        return self.device.read(self.index, self.count, np.int32)

    @property
    def cluster_of(self) -> np.ndarray:
        """int32 (N,): the sample (0..M-1) whose cluster holds each point."""
        renumber = np.full(len(self.clusters.sample_of), -1, np.int32)
        renumber[self.kept] = np.arange(len(self.kept), dtype=np.int32)
        return renumber[self.device.read(self.clusters.cluster_of, self.point_count, np.int32)]

    @property
    def centre_positions(self) -> np.ndarray:
        """float32 (M, 3): cluster centres the points were assigned to, in scene units."""
        k = len(self.clusters.sample_of)
        centres = self.device.read(self.clusters.centre_pos, (k, 4), np.float32)[self.kept, :3]
        return self.frame.to_world(centres)

    @property
    def centre_normals(self) -> np.ndarray:
        k = len(self.clusters.sample_of)
        return self.device.read(self.clusters.centre_nrm, (k, 4), np.float32)[self.kept, :3].copy()


def select(device: Device, pos: cl.Buffer, nrm: cl.Buffer, pixels: cl.Buffer, n: int, width: int, height: int,
           count: int, alpha: float = ALPHA0, max_iterations: int = MAX_ITERATIONS,
           converge_fraction: float = CONVERGE_FRACTION, seed: int = 0,
           start: "SampleSet | None" = None) -> SampleSet:
    """About ``count`` sample points among ``n`` shading points on the
    device: float4 positions and unit normals, int2 pixels inside a
    ``width`` x ``height`` image (several points per pixel allowed).
    ``alpha`` weighs distance against normal change in eps, relative to the
    largest side of the points' box. Returns one sample per non-empty
    cluster: ``count`` of them (fewer only when there are fewer points, or
    when identical points tie). With ``start`` (the samples of an earlier
    render, positions in the frame of ``pos``), k-means starts from them,
    each a centre, instead of from new seeds, and runs at most
    WARM_ITERATIONS."""
    if width < 1 or height < 1:
        raise ValueError(f"image size {width} x {height} is empty")
    if count < 1 or max_iterations < 1 or not 0.0 <= converge_fraction <= 1.0:
        raise ValueError(f"need count >= 1, max_iterations >= 1 and converge_fraction in [0, 1], not "
                         f"{count}, {max_iterations}, {converge_fraction}")
    if not (np.isfinite(alpha) and alpha >= 0.0):
        raise ValueError(f"alpha must be finite and >= 0, not {alpha}")
    timer = StageTimer(device.queue)
    frame = Frame.on_device(device, (pos, n))
    stats = {"points": n, "alpha": alpha / frame.extent, "alpha_normalised": alpha, "ms": timer.ms}
    if n == 0:
        stats.update(seeds=0, clusters=0, empty_clusters=0, iterations=0, changed_fraction=0.0, converged=True)
        empty = cache_clusters.Clusters(device.empty(4), np.zeros(0, np.int32), device.empty(16), device.empty(16),
                                        0, 0.0, True, 0)
        return SampleSet(device, device.empty(4), device.empty(16), device.empty(16), 0, frame, empty,
                         np.zeros(0, np.int32), 0, stats)
    with timer.stage("normalise"):
        normalised = frame.normalise(device, pos, n)
    if start is None:
        with timer.stage("quadtree"):
            tree = cache_seeding.build(device, normalised, nrm, pixels, n, width, height, alpha)
        with timer.stage("seeding"):
            seeds, k = cache_seeding.seed(device, tree, normalised, nrm, count, alpha, seed)
            centres = cache_clusters.seed_centres(device, normalised, nrm, seeds, k)
        stats.update(quadtree_levels=len(tree.levels), leaf_pixels=1 << tree.leaf_shift, warm_start=False)
    else:
        k, max_iterations = start.count, min(max_iterations, WARM_ITERATIONS)
        centres = (frame.normalise(device, start.pos, k), device.empty(16 * k))
        device.copy(centres[1], start.nrm, 16 * k)
        stats.update(warm_start=True)
    with timer.stage("kmeans"):
        result = cache_clusters.cluster(device, normalised, nrm, n, centres, k, alpha, max_iterations,
                                        converge_fraction)
    # the samples of the non-empty clusters, in centre order
    kept = np.flatnonzero(result.sample_of >= 0).astype(np.int32)
    index = device.to_device(result.sample_of[kept].astype(np.int32))
    m = len(kept)
    stats.update(
        seeds=k, clusters=m, empty_clusters=k - m, iterations=result.iterations,
        changed_fraction=result.changed_fraction, converged=bool(result.converged), restarts=result.restarts)
    stats["ms"]["total"] = sum(timer.ms.values())
    return SampleSet(device, index, primitives.gather_rows(device, pos, index, m),
                     primitives.gather_rows(device, nrm, index, m), m, frame, result, kept, n, stats)


class HeldSamples:
    """The sample sets of the latest renders (a coarse and a full pass),
    each with the shading points it was chosen among. The choice is a
    function of those points and its own settings alone, not of the lights
    or of what the materials reflect: a render whose shading points come
    out the same, bit for bit, as an earlier one's (after a light edit, or
    a material edit that moves none of them) keeps that render's samples
    instead of seeding and clustering again. Where the points differ but
    the image and settings are the same (an object moved), k-means may
    start from the last samples instead of new seeds (``warm``): most of
    them still fit, and it settles in fewer iterations. (The cache points
    of the gaps kept records leave are a new subset each view: the
    pipeline chooses them with ``select`` and does not hold them.)"""

    KEEP = 2

    def __init__(self):
        # (key, point count, the points' buffers, samples), the latest last
        self._held: list[tuple[tuple, int, tuple, SampleSet]] = []

    def select(self, device: Device, pos: cl.Buffer, nrm: cl.Buffer, pixels: cl.Buffer, n: int, width: int,
               height: int, count: int, alpha: float, seed: int, warm: bool = False,
               max_iterations: int = MAX_ITERATIONS) -> tuple[SampleSet, bool]:
        """``select``'s samples for these points, and whether they are an
        earlier render's (the points compared on the device)."""
        key = (device, width, height, count, alpha, seed, max_iterations, CONVERGE_FRACTION)
        start = None
        for entry in self._held:
            held_key, held_n, (held_pos, held_nrm, held_pixels), chosen = entry
            if held_key != key:
                continue
            if held_n == n and primitives.same_ints(
                    device, [(pos, held_pos, 4 * n), (nrm, held_nrm, 4 * n), (pixels, held_pixels, 2 * n)]):
                self._held.remove(entry)
                self._held.append(entry)
                return chosen, True
            # a start with fewer samples than asked (clusters lost to ties) would thin out edit after edit
            start = chosen if warm and chosen.count == count <= n else start
        chosen = select(device, pos, nrm, pixels, n, width, height, count, alpha=alpha, max_iterations=max_iterations,
                        seed=seed, start=start)
        self._held = [entry for entry in self._held if entry[0] != key][-(self.KEEP - 1):]
        self._held.append((key, n, (pos, nrm, pixels), chosen))
        return chosen, False


def select_samples(device: Device, positions, normals, pixels, width: int, height: int, count: int,
                   alpha: float | None = None, max_iterations: int = MAX_ITERATIONS,
                   converge_fraction: float = CONVERGE_FRACTION, seed: int = 0) -> SampleSet:
    """``select`` on host arrays: positions, normals (N, 3) float32, normals
    unit; pixels (N, 2) int32. ``alpha`` is in 1 / scene units here; None
    means ``ALPHA0`` / the largest side of the points' box."""
    pos = finite_rows("positions", positions, 3, np.float32)
    nrm = finite_rows("normals", normals, 3, np.float32)
    pix = finite_rows("pixels", pixels, 2, np.int32)
    n = len(pos)
    if len(nrm) != n or len(pix) != n:
        raise ValueError(f"positions, normals and pixels differ in length ({n}, {len(nrm)}, {len(pix)})")
    if n and ((pix.min(axis=0) < 0).any() or (pix.max(axis=0) >= (width, height)).any()):
        raise ValueError(f"pixel coordinates fall outside the {width} x {height} image")
    extent = Frame.around(pos).extent
    alpha_n = ALPHA0 if alpha is None else float(alpha) * extent
    if not (np.isfinite(alpha_n) and alpha_n >= 0.0):
        raise ValueError(f"alpha must be finite and >= 0, not {alpha}")
    return select(device, device.to_device(float4_rows(pos)), device.to_device(float4_rows(nrm)),
                  device.to_device(pix), n, width, height, count, alpha_n, max_iterations, converge_fraction, seed)
