"""Triangle kd-tree: built on the device, and closest/any-hit queries.

``build(device, triangles)`` runs the breadth-first builder of
``kdtree_build.py``; the tree's arrays stay on the device and every tracing
kernel takes them through ``KdTree.kernel_args()`` (``KDTREE_PARAMS`` in
``kernels/types.h``). ``intersect`` and ``occluded`` run batches of rays
for tests and benchmarks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes

from .device import Device
from .errors import SceneError
from .kdtree_build import LEAF, MAX_DEPTH, NODE_DTYPE, build_tree

__all__ = ["KdTree", "build", "LEAF", "MAX_DEPTH", "NODE_DTYPE", "SELF_HIT_SCALE"]

# Default lower end of a query ray, relative to the size of the coordinates
# involved: hits closer than this to the origin are taken for the surface
# the ray starts on.
SELF_HIT_SCALE = 2.0**-18
_FAR = np.float32(3.0e38)


@dataclass
class KdTree:
    """Device arrays of a built tree, its root box and its statistics."""

    device: Device
    nodes: cla.Array
    leaf_tris: cla.Array
    verts: cla.Array
    bmin: np.ndarray  # (4,) float32
    bmax: np.ndarray  # (4,) float32
    triangle_count: int
    stats: dict = field(default_factory=dict)

    def kernel_args(self) -> list:
        """Arguments matching KDTREE_PARAMS in kernels/types.h, in order."""
        return [self.nodes.data, self.leaf_tris.data, self.verts.data, self.bmin, self.bmax]

    def nodes_host(self) -> tuple[np.ndarray, np.ndarray]:
        """The node array (``NODE_DTYPE``, preorder) and the leaf triangle lists, read back.

        An inner node's left child follows it and ``child`` is its right
        child; a leaf's triangles are ``leaf_tris[child : child + count]``.
        """
        nodes = self.nodes.get()
        used = int((nodes["child"] + nodes["count"])[nodes["axis"] == LEAF].max(initial=0))
        return nodes, self.leaf_tris.get()[:used]

    @property
    def magnitude(self) -> float:
        """Largest absolute coordinate of the root box."""
        return float(max(np.abs(self.bmin[:3]).max(), np.abs(self.bmax[:3]).max()))

    def intersect(self, origins, directions, t_max=None, *, t_min=None, barycentrics=False):
        """Closest hits: ``(t, triangle_index)``, ``inf`` and ``-1`` on a miss.

        Hits count for ``t_min < t < t_max``; ``t_min`` defaults to a small
        distance scaled to the coordinates, so a ray starting on a surface
        does not hit it. With ``barycentrics``, also ``(N, 2)`` weights of
        each hit triangle's second and third corners.
        """
        n, org, dirs, rng = self._rays(origins, directions, t_min, t_max)
        q = self.device.queue
        t_out = cla.empty(q, max(n, 1), np.float32)
        tri_out = cla.empty(q, max(n, 1), np.int32)
        uv_out = cla.empty(q, (max(n, 1), 2), np.float32)
        if n:
            _query_kernel(self.device, "KdQuery_closest")(
                q, (n,), None, *self.kernel_args(), org.data, dirs.data, rng.data,
                t_out.data, tri_out.data, uv_out.data, np.int32(n),
            )
        t, tri = t_out.get()[:n], tri_out.get()[:n]
        t[tri < 0] = np.inf
        if barycentrics:
            return t, tri, uv_out.get()[:n]
        return t, tri

    def occluded(self, origins, directions, t_max, *, t_min=None) -> np.ndarray:
        """Whether anything lies along each ray between ``t_min`` and ``t_max``."""
        n, org, dirs, rng = self._rays(origins, directions, t_min, t_max)
        q = self.device.queue
        out = cla.empty(q, max(n, 1), np.int32)
        if n:
            _query_kernel(self.device, "KdQuery_occluded")(
                q, (n,), None, *self.kernel_args(), org.data, dirs.data, rng.data, out.data, np.int32(n)
            )
        return out.get()[:n].astype(bool)

    def _rays(self, origins, directions, t_min, t_max):
        org = np.asarray(origins, np.float32).reshape(-1, 3)
        dirs = np.asarray(directions, np.float32).reshape(-1, 3)
        n = len(org)
        org4 = np.zeros((max(n, 1), 4), np.float32)
        dir4 = np.zeros((max(n, 1), 4), np.float32)
        org4[:n, :3], dir4[:n, :3] = org, dirs
        rng = np.zeros((max(n, 1), 2), np.float32)
        if t_min is None:
            # (column by column: much faster than reductions along short rows)
            a = np.abs(org)
            scale = np.maximum(np.maximum(a[:, 0], a[:, 1]), np.maximum(a[:, 2], self.magnitude))
            d = dirs.astype(np.float64)
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            with np.errstate(divide="ignore", invalid="ignore"):
                rng[:n, 0] = np.where(length > 0, SELF_HIT_SCALE * scale / length, 0.0)
        else:
            rng[:n, 0] = np.broadcast_to(np.asarray(t_min, np.float32), (n,))
        if t_max is None:
            rng[:n, 1] = _FAR
        else:
            tmax = np.broadcast_to(np.asarray(t_max, np.float32), (n,)).copy()
            tmax[~np.isfinite(tmax)] = _FAR
            rng[:n, 1] = tmax
        q = self.device.queue
        return n, cla.to_device(q, org4), cla.to_device(q, dir4), cla.to_device(q, rng)


_QUERY_KERNELS: dict[tuple[int, str], cl.Kernel] = {}


def _query_kernel(device: Device, name: str) -> cl.Kernel:
    """A kernel of kdtree_query.cl, made once per device."""
    key = (id(device), name)
    if key not in _QUERY_KERNELS:
        _QUERY_KERNELS[key] = cl.Kernel(device.program("kdtree_query.cl"), name)
    return _QUERY_KERNELS[key]


def build(device: Device, triangles: np.ndarray) -> KdTree:
    """A kd-tree over ``triangles`` (``(N, 3, 3)`` float32), built on ``device``."""
    tris = np.asarray(triangles, np.float32).reshape(-1, 3, 3)
    if not np.isfinite(tris).all():
        bad = int((~np.isfinite(tris).all(axis=(1, 2))).sum())
        raise SceneError(f"{bad} triangle(s) have non-finite corners; validate the scene first")
    start = time.perf_counter()
    count = len(tris)
    verts = np.zeros((max(count, 1) * 3, 4), np.float32)
    verts[: count * 3, :3] = tris.reshape(-1, 3)
    verts_dev = cla.to_device(device.queue, verts.view(cltypes.float4).reshape(-1))
    upload_ms = (time.perf_counter() - start) * 1e3
    out = build_tree(device, verts_dev, count)
    stats = dict(out.stats)
    stats["ms"] = {"upload": upload_ms, **out.stats["ms"]}
    stats["ms"]["total"] = (time.perf_counter() - start) * 1e3
    stats["triangles"] = count
    return KdTree(
        device=device,
        nodes=out.nodes,
        leaf_tris=out.leaf_tris,
        verts=verts_dev,
        bmin=out.bmin,
        bmax=out.bmax,
        triangle_count=count,
        stats=stats,
    )

