"""Triangle kd-tree: built on the device, and closest/any-hit queries.

``build(device, triangles)`` runs the breadth-first builder of
``kdtree_build.py``; the tree's arrays stay on the device and every tracing
kernel takes them through ``KdTree.kernel_args()`` (``KDTREE_PARAMS`` in
``accel/kdtree.h``). ``intersect`` and ``occluded`` run batches of rays
for tests and benchmarks (kdtree_query.cl).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl.array as cla

from ..device import Device, primitives
from ..device.constants import KD_LEAF as LEAF
from ..device.constants import KD_MAX_DEPTH as MAX_DEPTH
from ..device.layout import KDNODE_DTYPE as NODE_DTYPE
from ..device.timer import StageTimer
from ..errors import SceneError
from . import kdtree_blocks
from .kdtree_build import build_tree

__all__ = ["KdTree", "build", "LEAF", "MAX_DEPTH", "NODE_DTYPE", "SELF_HIT_SCALE"]

_PROGRAM = "accel/kdtree_query.cl"

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
    base: KdTree | None = None  # an overlay tree's base (kdtree_overlay.py); None for a tree built whole
    blocks: cla.Array | None = None  # leaf blocks (kdtree_blocks.py), or None: triangles tested one at a time

    def kernel_args(self) -> list:
        """Arguments matching KDTREE_PARAMS in accel/kdtree.h, in order."""
        blocks = self.blocks.data if self.blocks is not None else None
        return [self.nodes.data, self.leaf_tris.data, self.verts.data, blocks, self.bmin, self.bmax]

    def nodes_host(self) -> tuple[np.ndarray, np.ndarray]:
        """The node array (``NODE_DTYPE``, preorder) and the leaf triangle lists, read back.

        An inner node's left child follows it and ``child`` is its right
        child; a leaf's triangles are ``leaf_tris[child : child + count]``.
        """
        nodes = self.device.get(self.nodes)
        used = int((nodes["child"] + nodes["count"])[nodes["axis"] == LEAF].max(initial=0))
        return nodes, self.device.get(self.leaf_tris)[:used]

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
        n, rays = self._rays(origins, directions, t_min, t_max)
        dev = self.device
        t_out, tri_out, uv_out = dev.empty(4 * n), dev.empty(4 * n), dev.empty(8 * n)
        dev.kernel(_PROGRAM, "KdQuery_closest")(n, *self.kernel_args(), *rays, t_out, tri_out, uv_out, np.int32(n))
        t, tri = dev.read(t_out, n, np.float32), dev.read(tri_out, n, np.int32)
        t[tri < 0] = np.inf
        if barycentrics:
            return t, tri, dev.read(uv_out, (n, 2), np.float32)
        return t, tri

    def occluded(self, origins, directions, t_max, *, t_min=None) -> np.ndarray:
        """Whether anything lies along each ray between ``t_min`` and ``t_max``."""
        n, rays = self._rays(origins, directions, t_min, t_max)
        dev = self.device
        out = dev.empty(4 * n)
        dev.kernel(_PROGRAM, "KdQuery_occluded")(n, *self.kernel_args(), *rays, out, np.int32(n))
        return dev.read(out, n, np.int32).astype(bool)

    def _rays(self, origins, directions, t_min, t_max):
        """The ray count and the query kernels' ray arguments: origins and
        directions uploaded as packed float32 triples, the given t_min and
        t_max per ray (None: the kernel's defaults, KdQuery_range), and the
        constants of those defaults."""
        org = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        dirs = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
        n = len(org)
        dev = self.device
        lo = hi = None
        if t_min is not None:
            lo = dev.to_device(np.broadcast_to(np.asarray(t_min, np.float32), (max(n, 1),)).copy())
        if t_max is not None:
            tmax = np.broadcast_to(np.asarray(t_max, np.float32), (max(n, 1),)).copy()
            tmax[~np.isfinite(tmax)] = _FAR
            hi = dev.to_device(tmax)
        empty = np.zeros((1, 3), np.float32)  # a zero-ray batch still passes buffers
        org_dev, dirs_dev = (dev.to_device(a if n else empty) for a in (org, dirs))
        return n, (org_dev, dirs_dev, lo, hi, np.float32(SELF_HIT_SCALE), np.float32(self.magnitude), _FAR)


def build(device: Device, triangles: np.ndarray, should_stop: Callable[[], bool] | None = None,
          blocks: bool | None = None) -> KdTree:
    """A kd-tree over ``triangles`` (``(N, 3, 3)`` float32), built on
    ``device``; ``should_stop`` is polled after every level of the build.
    With leaf blocks where ``blocks`` (None: where the device wants them,
    kdtree_blocks.wanted)."""
    tris = np.asarray(triangles, np.float32).reshape(-1, 3, 3)
    if not np.isfinite(tris).all():
        bad = int((~np.isfinite(tris).all(axis=(1, 2))).sum())
        raise SceneError(f"{bad} triangle(s) have non-finite corners; validate the scene first")
    timer = StageTimer()
    count = len(tris)
    with timer.stage("upload"):
        verts_dev = primitives.float4_rows(device, tris.reshape(-1, 3) if count else np.zeros((3, 3), np.float32))
    want_blocks = kdtree_blocks.wanted(device) if blocks is None else blocks
    with timer.stage("build"):
        out = build_tree(device, verts_dev, count, should_stop=should_stop, blocks=want_blocks)
    with timer.stage("blocks"):
        block_array = None
        if want_blocks:
            block_array = kdtree_blocks.make(device, out.nodes, out.leaf_tris, verts_dev, int(out.stats["nodes"]))
    stats = dict(out.stats)
    stats["ms"] = {"upload": timer.ms["upload"], **out.stats["ms"], "blocks": timer.ms["blocks"]}
    stats["ms"]["total"] = timer.ms["upload"] + timer.ms["build"] + timer.ms["blocks"]
    stats["triangles"] = count
    stats["blocks"] = kdtree_blocks.count(block_array)
    return KdTree(
        device=device,
        nodes=out.nodes,
        leaf_tris=out.leaf_tris,
        verts=verts_dev,
        bmin=out.bmin,
        bmax=out.bmax,
        triangle_count=count,
        stats=stats,
        blocks=block_array,
    )

