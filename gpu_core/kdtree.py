"""Triangle kd-tree: build, and closest/any-hit queries for tests and benchmarks.

INTERIM: a host-side median-split build in the node layout of types.h, so the
traversal kernels and the renderer can be written against the final API. The
GPU builder of [ZHWG08] replaces ``_build_host`` behind the same ``build``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .device import Device

NODE_DTYPE = np.dtype([("split", np.float32), ("axis", np.int32), ("child", np.int32), ("count", np.int32)])
LEAF = 3
_LEAF_SIZE = 8
_MAX_DEPTH = 30


@dataclass
class KdTree:
    """Device buffers of a built tree and its statistics."""

    device: Device
    nodes: cl.Buffer
    leaf_tris: cl.Buffer
    verts: cl.Buffer
    bmin: np.ndarray  # (4,) float32
    bmax: np.ndarray  # (4,) float32
    triangle_count: int
    stats: dict = field(default_factory=dict)

    def kernel_args(self) -> list:
        """Arguments matching KDTREE_PARAMS in kernels/types.h, in order."""
        return [self.nodes, self.leaf_tris, self.verts, self.bmin, self.bmax]

    def intersect(self, origins: np.ndarray, directions: np.ndarray, t_max=None):
        """Closest hits: ``(t, triangle_index)``, ``inf`` and ``-1`` on a miss."""
        org, dirs, tmax = _rays(origins, directions, t_max)
        n = len(org)
        t_out = np.empty(n, np.float32)
        tri_out = np.empty(n, np.int32)
        if n == 0:
            return t_out, tri_out
        dev = self.device
        prog = dev.program("kdtree_query.cl")
        bt, bi = dev.empty(t_out.nbytes), dev.empty(tri_out.nbytes)
        prog.KdQuery_closest(
            dev.queue, (n,), None, *self.kernel_args(),
            dev.buffer(org), dev.buffer(dirs), dev.buffer(tmax), bt, bi, np.int32(n),
        )
        cl.enqueue_copy(dev.queue, t_out, bt)
        cl.enqueue_copy(dev.queue, tri_out, bi)
        t_out[tri_out < 0] = np.inf
        return t_out, tri_out

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max) -> np.ndarray:
        """Whether anything lies along each ray before ``t_max``."""
        org, dirs, tmax = _rays(origins, directions, t_max)
        n = len(org)
        out = np.empty(n, np.int32)
        if n == 0:
            return out.astype(bool)
        dev = self.device
        prog = dev.program("kdtree_query.cl")
        bo = dev.empty(out.nbytes)
        prog.KdQuery_occluded(
            dev.queue, (n,), None, *self.kernel_args(),
            dev.buffer(org), dev.buffer(dirs), dev.buffer(tmax), bo, np.int32(n),
        )
        cl.enqueue_copy(dev.queue, out, bo)
        return out.astype(bool)


def _rays(origins, directions, t_max):
    org = np.ascontiguousarray(np.asarray(origins, np.float32).reshape(-1, 3))
    dirs = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
    n = len(org)
    org4 = np.zeros((n, 4), np.float32)
    dir4 = np.zeros((n, 4), np.float32)
    org4[:, :3], dir4[:, :3] = org, dirs
    if t_max is None:
        tmax = np.full(n, np.float32(3.0e38), np.float32)
    else:
        tmax = np.broadcast_to(np.asarray(t_max, np.float32), (n,)).copy()
        tmax[~np.isfinite(tmax)] = np.float32(3.0e38)
    return org4, dir4, tmax


def build(device: Device, triangles: np.ndarray) -> KdTree:
    """A kd-tree over ``triangles`` (``(N, 3, 3)`` float32) on ``device``."""
    tris = np.ascontiguousarray(np.asarray(triangles, np.float32).reshape(-1, 3, 3))
    start = time.perf_counter()
    nodes, leaf_tris = _build_host(tris)
    build_ms = (time.perf_counter() - start) * 1e3
    verts = np.zeros((len(tris) * 3, 4), np.float32)
    verts[:, :3] = tris.reshape(-1, 3)
    if len(tris):
        lo, hi = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
    else:
        lo = hi = np.zeros(3, np.float32)
    pad = 1e-6 * (np.abs(lo) + np.abs(hi)) + 1e-30
    bmin = np.append(lo - pad, 0).astype(np.float32)
    bmax = np.append(hi + pad, 0).astype(np.float32)
    leaves = nodes["axis"] == LEAF
    stats = {
        "nodes": len(nodes),
        "leaves": int(leaves.sum()),
        "mean_leaf_size": float(nodes["count"][leaves].mean()) if leaves.any() else 0.0,
        "max_leaf_size": int(nodes["count"][leaves].max()) if leaves.any() else 0,
        "ms": {"build": build_ms},
    }
    return KdTree(
        device=device,
        nodes=device.buffer(nodes),
        leaf_tris=device.buffer(leaf_tris),
        verts=device.buffer(verts),
        bmin=bmin,
        bmax=bmax,
        triangle_count=len(tris),
        stats=stats,
    )


def _build_host(tris: np.ndarray):
    """Preorder nodes and leaf lists by spatial-median splits of the longest axis."""
    nodes: list[tuple] = []
    leaf_lists: list[np.ndarray] = []
    offset = [0]
    lo_all, hi_all = tris.min(axis=1), tris.max(axis=1)

    def emit_leaf(ids):
        nodes.append((0.0, LEAF, offset[0], len(ids)))
        leaf_lists.append(ids)
        offset[0] += len(ids)

    def recurse(ids, lo, hi, depth):
        if len(ids) <= _LEAF_SIZE or depth >= _MAX_DEPTH:
            emit_leaf(ids)
            return
        axis = int(np.argmax(hi - lo))
        split = np.float32(0.5 * (lo[axis] + hi[axis]))
        left = ids[lo_all[ids, axis] <= split]
        right = ids[hi_all[ids, axis] >= split]
        if len(left) == len(ids) and len(right) == len(ids):
            emit_leaf(ids)
            return
        index = len(nodes)
        nodes.append(None)
        lhi, rlo = hi.copy(), lo.copy()
        lhi[axis] = rlo[axis] = split
        recurse(left, lo, lhi, depth + 1)
        nodes[index] = (float(split), axis, len(nodes), 0)
        recurse(right, rlo, hi, depth + 1)

    if len(tris):
        recurse(np.arange(len(tris), dtype=np.int32), lo_all.min(axis=0), hi_all.max(axis=0), 0)
    else:
        emit_leaf(np.zeros(0, np.int32))
    node_arr = np.array(nodes, dtype=NODE_DTYPE)
    leaf_arr = np.concatenate(leaf_lists).astype(np.int32) if leaf_lists else np.zeros(0, np.int32)
    return node_arr, leaf_arr
