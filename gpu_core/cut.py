"""Illumination cut of the global photon tree [WZPB09], and the irradiance
it gives at any surface point (what final gathering reads at its hits).

A cut holds exactly one node on every root-to-leaf path of the photon
kd-tree (empty leaves, which carry no light, are left out of the result). Every node carries an approximate irradiance E~_p (summed power
of front-facing photons over the squared node size, computed by the tree
build). ``select``:

1. E_min is the mean E~_p (luminance, zeros left out) over tree levels
   12-13, or the two deepest levels of a shallower tree;
2. the coarse cut is, on each path, the first node with E~_p >= E_min, and
   the leaf where there is none;
3. refinement: each cut node's exact irradiance E_p at its centre comes
   from k-nearest-photon density estimation; where |E~_p - E_p| > delta E_p
   the node is replaced by its children, for a few rounds.

A node's centre is the mean position of its photons (on the surface they
lie on, where the box centre may float in the air), and a node whose
photons lie on surfaces facing different ways (a box corner) never joins
the cut while it has children: one normal and one irradiance cannot stand
for both walls, and the estimate at such a node misses most of the light.

``Cut.irradiance_at`` interpolates the nodes' E_p around a point with
w_j = K(|p_j - y| / L_j) max(0, n_j . n_y), K(x) = 1 - x^2 (0 past x = 1),
L_j the node's size; a point no node covers takes the nearest node facing
its way, so gathering never meets holes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .device import Device
from .photons import PointTree

LEAF = 3  # KdNode.axis of a leaf (kernels/types.h)
DELTA = 0.2  # default refinement threshold, relative to E_p
MAX_ROUNDS = 6  # default refinement rounds
LEVELS = (12, 13)  # tree levels whose mean E~_p is E_min
NEIGHBOURS = 16  # cut nodes considered around a lookup point
COHERENT = 0.9  # |mean photon normal| below this: the node spans several surfaces
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class Cut:
    """The chosen nodes, their exact irradiance and a tree over their centres."""

    device: Device
    nodes: np.ndarray  # (K,) int: preorder indices in the photon tree
    centres: np.ndarray  # (K, 3) float32
    normals: np.ndarray  # (K, 3) float32, unit (zero when unknown)
    sizes: np.ndarray  # (K,) float32 L_j
    irradiance: np.ndarray  # (K, 3) float32 E_p
    stats: dict = field(default_factory=dict)
    _lookup: PointTree | None = None

    def irradiance_at(self, points, normals) -> np.ndarray:
        """Irradiance (N, 3) at surface points with unit ``normals``."""
        pts = np.asarray(points, np.float32).reshape(-1, 3)
        nrm = np.asarray(normals, np.float32).reshape(-1, 3)
        out = np.zeros((len(pts), 3), np.float32)
        if len(pts) == 0 or len(self.nodes) == 0:
            return out
        if self._lookup is None:
            self._lookup = PointTree.build(self.device, self.centres)
        k = min(NEIGHBOURS, len(self.nodes))
        idx, d2 = self._lookup.knn(pts, k)
        found = idx >= 0
        j = np.where(found, idx, 0)
        facing = np.einsum("nkc,nc->nk", self.normals[j], nrm)
        x2 = np.where(found, d2, np.inf) / np.maximum(self.sizes[j], 1e-30) ** 2
        w = np.clip(1.0 - x2, 0.0, None) * np.clip(facing, 0.0, None)
        total = w.sum(axis=1)
        covered = total > 0
        out[covered] = (np.einsum("nk,nkc->nc", w, self.irradiance[j])[covered] / total[covered, None])
        # uncovered points: the nearest node facing their way (candidates are sorted by distance)
        ok = found & (facing > 0)
        first = np.argmax(ok, axis=1)
        fallback = ~covered & ok.any(axis=1)
        out[fallback] = self.irradiance[j[fallback, first[fallback]]]
        return out


def select(device: Device, tree: PointTree, k: int, delta: float = DELTA, max_rounds: int = MAX_ROUNDS) -> Cut:
    """The illumination cut of photon tree ``tree`` (built with photon
    attributes), exact irradiance by ``k``-nearest-photon estimates."""
    started = time.perf_counter()
    nodes, info = tree.nodes(), tree.node_info()
    n = len(nodes)
    stats = {"tree_nodes": n}
    if n == 0 or tree.point_count == 0:
        stats.update(cut_nodes=0, e_min=0.0, refined=0, rounds=0, ms={"total": 0.0})
        return Cut(device, np.zeros(0, np.int64), *(np.zeros((0, 3), np.float32) for _ in range(2)),
                   np.zeros(0, np.float32), np.zeros((0, 3), np.float32), stats)
    leaf = nodes["axis"] == LEAF
    depth = info["depth"]
    approx = info["irradiance"][:, :3].astype(np.float64) @ _LUMINANCE
    e_min, levels = _e_min(approx, depth)
    centres, coherence = _photon_means(device, tree, info)
    mixed = ~leaf & (coherence < COHERENT)
    cut = _coarse_cut(nodes, leaf, depth, (approx >= e_min) & ~mixed)
    coarse = len(cut)
    # refinement by exact estimates at the node centres
    normals = info["normal"][:, :3]
    exact = np.full((n, 3), np.nan, np.float32)
    refined, rounds = 0, 0
    empty = info["count"] == 0
    exact[empty] = 0.0  # empty leaves hold no light: nothing to estimate
    for rounds in range(1, max_rounds + 1):
        todo = cut[np.isnan(exact[cut, 0])]
        if len(todo):
            exact[todo] = tree.irradiance(centres[todo], _unit(normals[todo], centres[todo]), k)
        e = exact[cut].astype(np.float64) @ _LUMINANCE
        split = ~leaf[cut] & ((np.abs(approx[cut] - e) > delta * e) | mixed[cut])
        if not split.any():
            break
        parents = cut[split]
        refined += len(parents)
        cut = np.sort(np.concatenate([cut[~split], parents + 1, nodes["child"][parents]]))
    todo = cut[np.isnan(exact[cut, 0])]
    if len(todo):
        exact[todo] = tree.irradiance(centres[todo], _unit(normals[todo], centres[todo]), k)
    cut = cut[~empty[cut]]  # empty leaves end their paths but give no light
    # node size L_j: its box, but at least the tree's photon search radius (r_p of the build)
    size = np.maximum((info["hi"][cut, :3] - info["lo"][cut, :3]).max(axis=1), info["lo"][cut, 3])
    stats.update(
        cut_nodes=len(cut), coarse_nodes=coarse, e_min=float(e_min), e_min_levels=list(levels),
        refined=refined, rounds=rounds, leaves_in_cut=int(leaf[cut].sum()), mixed_nodes=int(mixed.sum()),
        ms={"total": (time.perf_counter() - started) * 1e3},
    )
    return Cut(
        device, cut, np.ascontiguousarray(centres[cut], np.float32), np.ascontiguousarray(normals[cut], np.float32),
        size.astype(np.float32), np.nan_to_num(exact[cut]).clip(0.0, None), stats,
    )


def _photon_means(device: Device, tree: PointTree, info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per node: mean photon position, and |mean photon normal| (1 when all
    its photons lie on surfaces facing one way). A subtree's photons are
    contiguous in leaf order, so both come from prefix sums."""
    n = tree.point_count
    points, normals = np.empty((n, 4), np.float32), np.empty((n, 4), np.float32)
    cl.enqueue_copy(device.queue, points, tree.kernel_args()[1])
    cl.enqueue_copy(device.queue, normals, tree.photon_args()[2])
    first, count = info["first"].astype(np.int64), info["count"].astype(np.int64)
    sums = []
    for values in (points[:, :3], normals[:, :3]):
        prefix = np.zeros((n + 1, 3), np.float64)
        np.cumsum(values, axis=0, out=prefix[1:])
        sums.append(prefix[first + count] - prefix[first])
    per = np.maximum(count, 1)[:, None]
    means = np.where(count[:, None] > 0, sums[0] / per, 0.5 * (info["lo"][:, :3] + info["hi"][:, :3]))
    return means.astype(np.float32), np.linalg.norm(sums[1] / per, axis=1)


def _e_min(approx: np.ndarray, depth: np.ndarray) -> tuple[float, tuple[int, ...]]:
    """Mean non-zero E~_p over levels 12-13, or the two deepest levels."""
    deepest = int(depth.max())
    levels = LEVELS if deepest >= LEVELS[-1] else tuple(range(max(deepest - 1, 0), deepest + 1))
    on = np.isin(depth, levels) & (approx > 0)
    return (float(approx[on].mean()) if on.any() else 0.0), levels


def _coarse_cut(nodes: np.ndarray, leaf: np.ndarray, depth: np.ndarray, marked: np.ndarray) -> np.ndarray:
    """Preorder indices of the first marked node on every root-to-leaf path
    (the leaf where no node is marked)."""
    n = len(nodes)
    parent = np.full(n, -1)
    interior = np.nonzero(~leaf)[0]
    parent[interior + 1] = interior
    parent[nodes["child"][interior]] = interior
    # level by level from the root: covered = an ancestor is in the cut
    taken = np.zeros(n, bool)  # in the cut, or below a node in it
    in_cut = np.zeros(n, bool)
    for level in range(int(depth.max()) + 1):
        at = np.nonzero(depth == level)[0]
        covered = np.zeros(len(at), bool) if level == 0 else taken[parent[at]]
        in_cut[at] = ~covered & (marked[at] | leaf[at])
        taken[at] = covered | in_cut[at]
    return np.nonzero(in_cut)[0]


def _unit(normals: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Unit normals; unknown (zero) ones become +Z so the estimate still runs."""
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.maximum(length, 1e-30), [0.0, 0.0, 1.0]).astype(np.float32)
