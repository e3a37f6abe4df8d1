"""Illumination cut of the global photon tree [WZPB09] (cut.cl), selected
on the device, and the irradiance it gives at any surface point (what final
gathering reads at its hits, cut_lookup.h).

A cut holds exactly one node on every root-to-leaf path of the photon
kd-tree (empty leaves, which carry no light, are left out of the result).
Every node carries an approximate irradiance E~_p (summed power of
front-facing photons over the squared node size, computed by the tree
build). ``select``:

1. E_min is the mean E~_p (luminance, zeros left out) over tree levels
   12-13, or the two deepest levels of a shallower tree;
2. the coarse cut is, on each path, the first node with E~_p >= E_min and
   at most MAX_PHOTONS photons, and the leaf where there is none;
3. refinement: each cut node's exact irradiance E_p at its centre comes
   from k-nearest-photon density estimation; where |E~_p - E_p| > delta E_p
   the node is replaced by its children, for a few rounds.

A node's centre is the mean position of its photons (on the surface they
lie on, where the box centre may float in the air), and a node whose
photons lie on surfaces facing different ways (a box corner) never joins
the cut while it has children: one normal and one irradiance cannot stand
for both walls, and the estimate at such a node misses most of the light.
The host reads back only a few counts and sums.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pyopencl as cl

from ..accel.point_tree import PointTree, knn_capacity
from ..device import Device, primitives
from ..device.constants import KD_LEAF as LEAF  # noqa: F401  (the leaf axis, for readers of the nodes)
from ..device.layout import float4_rows

DELTA = 0.2  # default refinement threshold, relative to E_p
MAX_ROUNDS = 6  # default refinement rounds
LEVELS = (12, 13)  # tree levels whose mean E~_p is E_min
NEIGHBOURS = 4  # cut nodes considered around a lookup point (cut_lookup.h CUT_NEIGHBOURS; README)
# nodes searched for the nearest one facing a lookup point's way when none of
# its NEIGHBOURS nearest does (cut_lookup.h CUT_FALLBACK: a closed box whose
# cut is one node per wall, all at one point)
FALLBACK = 16
# photons of a node that can join the coarse cut, at most (MNRT's ICUT_PHOTONLIMIT): on one flat
# surface no node is mixed, and a node near the root, standing for the whole surface, flattened
# its light (README, "Illumination cut")
MAX_PHOTONS = 5000
COHERENT = 0.9  # |mean photon normal| below this: the node spans several surfaces (cut.cl CUT_COHERENT)
# Caustic estimates gather within this many times the caustic map's typical
# k-photon radius (its VVH radius), Jensen's maximum radius: further out the
# few photons found count over that disc. Without it, a point far from every
# caustic searched the map until it had k photons (the caustics scene's
# caustics stage 123 -> 7 ms at 256² Preview, the image within 0.9% RMS, no farther from Cycles).
CAUSTIC_REACH = 16.0
_PROGRAM = "gi/cut.cl"


def lookup_defines(k: int) -> dict:
    """Defines of a program that estimates with ``k`` photons and looks the
    cut up: the kNN capacity and the lookup's constants."""
    return {"KNN_K": knn_capacity(max(int(k), FALLBACK)), "KNN_VARIABLE_K": 1, "CUT_NEIGHBOURS": NEIGHBOURS,
            "CUT_FALLBACK": FALLBACK, "CUT_COHERENT": f"{COHERENT!r}f"}


def image_lookup_defines() -> dict:
    """Defines of a program that only looks the cut up (the image kernel's
    glossy paths): a kNN of CUT_NEIGHBOURS, CUT_FALLBACK where none faces."""
    return lookup_defines(NEIGHBOURS)


def programs(k: int) -> list[tuple[str, dict]]:
    """The programs the cut builds for estimates of ``k`` photons."""
    return [(_PROGRAM, lookup_defines(k))]


@dataclass
class Cut:
    """The chosen nodes on the device: per node its centre (w = size L_j),
    unit normal (zero when unknown) and exact irradiance E_p, and a point
    tree over the centres for lookups."""

    device: Device
    ids: cl.Buffer  # int (K,): preorder indices in the photon tree
    centre: cl.Buffer  # float4 (K,)
    normal: cl.Buffer  # float4 (K,)
    irradiance: cl.Buffer  # float4 (K,)
    count: int
    lookup: PointTree | None
    k: int  # photons per estimate (sets the programs' kNN capacity)
    stats: dict = field(default_factory=dict)

    def kernel_args(self) -> list:
        """Arguments matching CUT_PARAMS in cut_lookup.h, in order."""
        tree = self.lookup.kernel_args() if self.lookup is not None else [None, None]
        return [*tree, self.centre, self.normal, self.irradiance, np.int32(self.count)]

    @classmethod
    def from_nodes(cls, device: Device, centres, normals, sizes, irradiance, k: int = 50) -> "Cut":
        """A cut of given nodes (host arrays: centres (K, 3), unit normals
        (K, 3), sizes L_j (K,), irradiance (K, 3))."""
        centre = float4_rows(centres)
        centre[:, 3] = np.asarray(sizes, np.float32)
        count = len(centre)
        centre_buf = device.to_device(centre)
        lookup = PointTree.from_device(device, primitives.indexed_points(device, centre_buf, count)) if count else None
        return cls(device, device.to_device(np.arange(count, dtype=np.int32)), centre_buf,
                   device.to_device(float4_rows(normals)), device.to_device(float4_rows(irradiance)), count, lookup, k)

    @property
    def nodes(self) -> np.ndarray:
        """(K,) preorder node indices, read back (tests and statistics)."""
        return self.device.read(self.ids, self.count, np.int32).astype(np.int64)

    def irradiance_at(self, points, normals) -> np.ndarray:
        """Irradiance (N, 3) at host points with unit ``normals``, looked up on the device."""
        pts, nrm = float4_rows(points), float4_rows(normals)
        n, dev = len(pts), self.device
        out = dev.zeros(16 * n)
        if self.count:
            dev.kernel(_PROGRAM, "Cut_lookup", lookup_defines(self.k))(
                n, *self.kernel_args(), dev.to_device(pts), dev.to_device(nrm), np.int32(n), out)
        return dev.read_xyz(out, n)


def with_caustics(cut: Cut, caustic_map: PointTree | None, k: int) -> Cut:
    """The cut as final gathering reads it: each node's irradiance plus the
    caustic map's ``k``-photon estimate at its centre, so a gather hit looks
    up one structure (the method of precomputed irradiance at photons: light
    seen after a diffuse bounce is smooth at the cut's scale). Caustics seen
    directly keep their own estimate per shading point. The same cut when
    there is no caustic map."""
    if caustic_map is None or caustic_map.point_count == 0 or cut.count == 0:
        return cut
    device, n = cut.device, cut.count
    caustic, total = device.empty(16 * n), device.empty(16 * n)
    caustic_irradiance(caustic_map, cut.centre, cut.normal, n, k, caustic)
    device.kernel(_PROGRAM, "Cut_add_irradiance", lookup_defines(cut.k))(n, cut.irradiance, caustic, np.int32(n), total)
    return replace(cut, irradiance=total, stats={**cut.stats, "caustics_in_nodes": True})


def caustic_max_radius(caustic_map: PointTree) -> float | None:
    """How far caustic estimates gather: CAUSTIC_REACH times the map's
    typical radius (None, unbounded, where the map has none)."""
    radius = caustic_map.radius
    return CAUSTIC_REACH * radius if np.isfinite(radius) and radius > 0 else None


def caustic_irradiance(caustic_map: PointTree, positions: cl.Buffer, normals: cl.Buffer, n: int, k: int,
                       out: cl.Buffer) -> None:
    """The caustic map's ``k``-photon irradiance at ``n`` device points,
    gathered within caustic_max_radius."""
    caustic_map.irradiance_on_device(positions, normals, n, k, out, max_radius=caustic_max_radius(caustic_map))


def select(device: Device, tree: PointTree, k: int, delta: float = DELTA, max_rounds: int = MAX_ROUNDS) -> Cut:
    """The illumination cut of photon tree ``tree`` (built with photon
    attributes), exact irradiance by ``k``-nearest-photon estimates."""
    n = tree.node_count
    if n == 0 or tree.point_count == 0:
        stats = dict(tree_nodes=n, cut_nodes=0, e_min=0.0, refined=0, rounds=0)
        return Cut(device, device.empty(4), device.empty(16), device.empty(16), device.empty(16), 0, None, k, stats)
    kern = _Kernels(device, k)
    nodes, info = tree.kernel_args()[0], tree.node_buffer
    e_min, levels = _e_min(kern, info, n)
    parent = device.empty(4 * n)
    device.fill(parent, -1, 4 * n)
    kern("Cut_parents")(n, nodes, np.int32(n), parent)
    in_cut, exact = device.empty(4 * n), device.empty(16 * n)
    kern("Cut_coarse")(n, nodes, info, parent, np.int32(n), np.float32(e_min), np.int32(MAX_PHOTONS), in_cut, exact)
    coarse = _tally(kern, nodes, info, in_cut, n)[0]
    # refinement by exact estimates at the node centres
    refined, rounds, counter, next_cut = 0, 0, device.empty(4), device.empty(4 * n)
    for rounds in range(1, max_rounds + 1):
        kern("Cut_exact")(n, *tree.kernel_args(), *tree.photon_args(), info, in_cut, np.int32(n), np.int32(k), exact)
        device.fill(counter, 0, 4)
        cl.enqueue_copy(device.queue, next_cut, in_cut, byte_count=4 * n)
        kern("Cut_split")(n, nodes, info, exact, np.int32(n), np.float32(delta), in_cut, next_cut, counter)
        in_cut, next_cut = next_cut, in_cut
        split = int(device.scalar(counter))
        refined += split
        if not split:
            break
    kern("Cut_exact")(n, *tree.kernel_args(), *tree.photon_args(), info, in_cut, np.int32(n), np.int32(k), exact)
    # the cut without its empty leaves, in preorder
    ids, count = _compact(kern, in_cut, info, n)
    centre, normal, irradiance = device.empty(16 * count), device.empty(16 * count), device.empty(16 * count)
    kern("Cut_emit")(count, info, exact, ids, np.int32(count), centre, normal, irradiance)
    lookup = PointTree.from_device(device, primitives.indexed_points(device, centre, count)) if count else None
    _, leaves, mixed = _tally(kern, nodes, info, in_cut, n)
    stats = dict(tree_nodes=n, cut_nodes=count, coarse_nodes=coarse, e_min=float(e_min), e_min_levels=list(levels),
                 refined=refined, rounds=rounds, leaves_in_cut=leaves, mixed_nodes=mixed)
    return Cut(device, ids, centre, normal, irradiance, count, lookup, k, stats)


class _Kernels:
    def __init__(self, device: Device, k: int):
        self.device, self.defines = device, lookup_defines(k)

    def __call__(self, name: str):
        return self.device.kernel(_PROGRAM, name, self.defines)


def _e_min(kern: _Kernels, info: cl.Buffer, n: int) -> tuple[float, tuple[int, ...]]:
    """Mean non-zero E~_p over levels 12-13, or the two deepest levels;
    summed on the device to float64 accuracy."""
    device = kern.device
    tally, terms = device.empty(16 * n), device.empty(16 * n)
    kern("Cut_depths")(n, info, np.int32(n), tally)
    deepest = int(primitives.max_int4(device, tally, n)[0])
    levels = LEVELS if deepest >= LEVELS[-1] else tuple(range(max(deepest - 1, 0), deepest + 1))
    kern("Cut_level_terms")(n, info, np.int32(n), np.int32(levels[0]), np.int32(levels[-1]), terms)
    total, _, count, _ = primitives.sum_float4(device, terms, n)
    return (total / count if count > 0 else 0.0), levels


def _compact(kern: _Kernels, in_cut: cl.Buffer, info: cl.Buffer, n: int) -> tuple[cl.Buffer, int]:
    """Preorder ids of the cut nodes that hold photons, in order."""
    flags = kern.device.empty(4 * n)
    kern("Cut_kept")(n, in_cut, info, np.int32(n), flags)
    return primitives.compact(kern.device, flags, n)


def _tally(kern: _Kernels, nodes: cl.Buffer, info: cl.Buffer, in_cut: cl.Buffer, n: int) -> tuple[int, int, int]:
    """Nodes in the cut (empty leaves included), leaves among the cut nodes
    that hold photons, and mixed nodes in the tree."""
    tally = kern.device.empty(16 * n)
    kern("Cut_tally")(n, nodes, info, in_cut, np.int32(n), tally)
    in_cut_count, leaves, mixed, _ = (int(x) for x in primitives.sum_int4(kern.device, tally, n))
    return in_cut_count, leaves, mixed
