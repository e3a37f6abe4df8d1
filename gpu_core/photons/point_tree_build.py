"""Device build of the point kd-tree (kernels/point_tree_build.cl), level by level.

The host loops over tree levels and reads back only list sizes; every
kernel works on all nodes (or point chunks) of a level at once.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..device import Device
from ..layout import KDNODE_DTYPE
from . import scan
from .kernels import Kernels
from .layout import BUILD_NODE_DTYPE, BUILD_SUMS_DTYPE, CHUNK_DTYPE, POINT_NODE_DTYPE

SMALL_MAX = 32  # points of a small node (width of the bit masks); [ZHWG08] uses 32 for points
MAX_DEPTH = 60  # matches POINT_TREE_MAX_DEPTH in point_tree.h
EMPTY_RATIO = 0.1  # empty fraction of a cell that is cut off, retuned for points
COST_TRAVERSE = 3.0  # VVH cost of visiting a node, in point tests (kNN fastest at 3 on photon maps)


@dataclass
class BuildParams:
    """Knobs of the build; the defaults suit kNN with k about k_hint."""

    k_hint: float = 50.0  # the k the VVH radius is estimated for
    radius: float | None = None  # search radius R of the VVH; None: estimated from the points
    cost_traverse: float = COST_TRAVERSE
    empty_ratio: float = EMPTY_RATIO
    max_depth: int = MAX_DEPTH


@dataclass
class BuiltTree:
    """Device arrays of a finished tree, in preorder and leaf order."""

    nodes: cla.Array  # KdNode
    info: cla.Array  # PointNode
    points: cla.Array  # float4, w = original index (int bits)
    power: cla.Array | None
    direction: cla.Array | None
    normal: cla.Array | None
    node_count: int
    radius: float
    stats: dict = field(default_factory=dict)


class _NodeTable:
    """The growing array of build nodes; children always land after their parent."""

    def __init__(self, queue: cl.CommandQueue, capacity: int):
        self.queue = queue
        self.array = cla.empty(queue, max(capacity, 16), BUILD_NODE_DTYPE)
        self.count = 0

    def reserve(self, extra: int) -> int:
        """Room for ``extra`` more nodes; returns the id of the first one."""
        need = self.count + extra
        if need > len(self.array):
            bigger = cla.empty(self.queue, max(need, 2 * len(self.array)), BUILD_NODE_DTYPE)
            cl.enqueue_copy(self.queue, bigger.data, self.array.data, byte_count=self.count * BUILD_NODE_DTYPE.itemsize)
            self.array = bigger
        base = self.count
        self.count = need
        return base


GROUP = 64  # work-group size of every launch: PoCL compiles once per group size


def _launch(kernel, queue, n: int, *args) -> None:
    """``n`` work items (kernels bound-check), in groups of GROUP."""
    if n > 0:
        kernel(queue, (-(-n // GROUP) * GROUP,), (GROUP,), *args)


def _cat(queue, parts: list[cla.Array], dtype) -> cla.Array:
    """One device array holding ``parts`` in order."""
    total = sum(len(p) for p in parts)
    out = cla.empty(queue, max(total, 1), dtype)
    offset = 0
    for p in parts:
        if len(p):
            cl.enqueue_copy(queue, out.data, p.data, byte_count=p.nbytes, dst_offset=offset * out.dtype.itemsize)
            offset += len(p)
    return out


def points_on_device(queue: cl.CommandQueue, points: np.ndarray) -> cla.Array:
    """(N, 4) float32 device array: xyz, and the point's index in w (int bits)."""
    work4 = np.zeros((len(points), 4), np.float32)
    work4[:, :3] = points
    work4[:, 3] = np.arange(len(points), dtype=np.int32).view(np.float32)
    return cla.to_device(queue, work4)


def build(device: Device, points: cla.Array, photons: tuple | None, params: BuildParams) -> BuiltTree:
    """Build the tree over ``points``, an (N, 4) float32 device array with
    each point's index in w (see points_on_device); ``photons`` is
    ``(power, direction, normal)`` as (N, 4) float32 device arrays indexed
    by that index, or None. The arrays are not modified."""
    queue = device.queue
    prog = Kernels(device.program("point_tree_build.cl"))
    ms: dict[str, float] = {}
    start = time.perf_counter()

    n = len(points)
    work = cla.empty(queue, (max(n, 1), 4), np.float32)
    if n:
        cl.enqueue_copy(queue, work.data, points.data, byte_count=n * 16, src_offset=points.offset)
    scratch = cla.empty_like(work)
    has_photons = np.int32(photons is not None and n > 0)
    ph = list(photons) if has_photons else [cla.empty(queue, (1, 4), np.float32) for _ in range(3)]

    table = _NodeTable(queue, 2 * max(n, 1) // 8 + 64)
    table.reserve(1)
    root = np.zeros(1, BUILD_NODE_DTYPE)
    root["lo"], root["hi"] = np.inf, -np.inf
    root["count"], root["root"], root["left"] = n, -1, -1
    cl.enqueue_copy(queue, table.array.data, root)
    batches = [(0, 1)]
    max_depth = np.int32(min(params.max_depth, MAX_DEPTH))

    # -- large-node stage: median splits and empty-space cuts, level by level
    active = cla.to_device(queue, np.zeros(1, np.int32))
    n_active = 1 if n > SMALL_MAX else 0
    small_parts = [cla.to_device(queue, np.zeros(1, np.int32))] if 2 <= n <= SMALL_MAX else []
    large_levels = 0
    while n_active:
        large_levels += 1
        counts = cla.empty(queue, n_active, np.int32)
        _launch(prog.Build_chunk_counts, queue, n_active, active.data, table.array.data, counts.data, np.int32(n_active))
        chunk_end = scan.inclusive_sum(queue, counts)
        n_chunks = int(chunk_end[n_active - 1 : n_active].get()[0])
        chunks = cla.empty(queue, n_chunks, CHUNK_DTYPE)
        chunk_lo = cla.empty(queue, (n_chunks, 4), np.float32)
        chunk_hi = cla.empty(queue, (n_chunks, 4), np.float32)
        chunk_left = cla.empty(queue, n_chunks, np.int32)
        left_end = cla.empty(queue, n_chunks, np.int32)
        _launch(prog.Build_chunks, queue, n_active, active.data, table.array.data, chunk_end.data, chunks.data, np.int32(n_active))
        _launch(prog.Build_chunk_bounds, queue, n_chunks, chunks.data, work.data, chunk_lo.data, chunk_hi.data, np.int32(n_chunks))
        _launch(
            prog.Build_large_decide, queue, n_active, active.data, table.array.data, chunk_end.data,
            chunk_lo.data, chunk_hi.data, np.float32(params.empty_ratio), np.int32(n_active),
        )
        _launch(
            prog.Build_chunk_count_left, queue, n_chunks, chunks.data, active.data, table.array.data,
            work.data, chunk_left.data, np.int32(n_chunks),
        )
        scan.inclusive_sum(queue, chunk_left, left_end)
        base = table.reserve(2 * n_active)
        _launch(
            prog.Build_large_split, queue, n_active, active.data, table.array.data, chunk_end.data,
            left_end.data, np.int32(base), np.int32(n_active),
        )
        _launch(
            prog.Build_chunk_scatter, queue, n_chunks, chunks.data, active.data, table.array.data,
            work.data, scratch.data, chunk_left.data, left_end.data, np.int32(n_chunks),
        )
        _launch(prog.Build_chunk_copy, queue, n_chunks, chunks.data, scratch.data, work.data, np.int32(n_chunks))
        batches.append((base, 2 * n_active))
        cls = cla.empty(queue, 2 * n_active, np.int32)
        _launch(prog.Build_classify, queue, 2 * n_active, table.array.data, np.int32(base), np.int32(2 * n_active), max_depth, cls.data)
        smalls, n_small = scan.compact(queue, cls, 2, base)
        if n_small:
            small_parts.append(smalls[:n_small])
        active, n_active = scan.compact(queue, cls, 1, base)
    queue.finish()
    ms["large"] = (time.perf_counter() - start) * 1e3

    # -- small-node stage: VVH splits over bit masks of each small root's points
    start = time.perf_counter()
    roots = _cat(queue, small_parts, np.int32)
    n_roots = sum(len(p) for p in small_parts)
    masks = cla.empty(queue, max(n_roots, 1) * 96, np.uint32)
    root_radius = cla.empty(queue, max(n_roots, 1), np.float32)
    _launch(
        prog.Build_small_roots, queue, n_roots, roots.data, table.array.data, work.data, masks.data,
        root_radius.data, np.float32(params.k_hint), np.int32(n_roots),
    )
    if params.radius is not None:
        radius = max(float(params.radius), 0.0)
    else:
        estimates = root_radius.get()[:n_roots]
        estimates = estimates[np.isfinite(estimates) & (estimates > 0)]
        radius = float(np.median(estimates)) if estimates.size else 0.0
    active, n_active = roots, n_roots
    small_levels = 0
    while n_active:
        small_levels += 1
        flag = cla.empty(queue, n_active, np.int32)
        cand = cla.empty(queue, n_active, np.int32)
        _launch(
            prog.Build_small_decide, queue, n_active, active.data, table.array.data, work.data, masks.data,
            np.float32(radius), np.float32(params.cost_traverse), max_depth, flag.data, cand.data, np.int32(n_active),
        )
        splitting, n_split = scan.compact(queue, flag, 1, 0)
        if not n_split:
            break
        base = table.reserve(2 * n_split)
        _launch(
            prog.Build_small_split, queue, n_split, splitting.data, active.data, table.array.data, cand.data,
            masks.data, np.int32(base), np.int32(n_split),
        )
        batches.append((base, 2 * n_split))
        cls = cla.empty(queue, 2 * n_split, np.int32)
        _launch(prog.Build_small_classify, queue, 2 * n_split, table.array.data, np.int32(base), np.int32(2 * n_split), max_depth, cls.data)
        active, n_active = scan.compact(queue, cls, 1, base)
    queue.finish()
    ms["small"] = (time.perf_counter() - start) * 1e3

    # -- output stage: sums bottom-up, preorder addresses top-down, emit
    start = time.perf_counter()
    n_nodes = table.count
    size = cla.empty(queue, n_nodes, np.int32)
    sums = cla.empty(queue, n_nodes, BUILD_SUMS_DTYPE)
    for base, count in reversed(batches):
        _launch(
            prog.Build_sums, queue, count, table.array.data, work.data, ph[0].data, ph[1].data, ph[2].data,
            has_photons, size.data, sums.data, np.int32(base), np.int32(count),
        )
    addr = cla.zeros(queue, n_nodes, np.int32)
    first = cla.zeros(queue, n_nodes, np.int32)
    for base, count in batches:
        _launch(prog.Build_preorder, queue, count, table.array.data, size.data, addr.data, first.data, np.int32(base), np.int32(count))
    out_nodes = cla.empty(queue, n_nodes, KDNODE_DTYPE)
    out_info = cla.empty(queue, n_nodes, POINT_NODE_DTYPE)
    out_pts = cla.empty(queue, (max(n, 1), 4), np.float32)
    out_ph = [cla.empty(queue, (max(n, 1), 4), np.float32) for _ in range(3)]
    _launch(
        prog.Build_emit, queue, n_nodes, table.array.data, sums.data, addr.data, first.data, work.data,
        ph[0].data, ph[1].data, ph[2].data, has_photons, np.float32(radius), out_nodes.data, out_info.data,
        out_pts.data, out_ph[0].data, out_ph[1].data, out_ph[2].data, np.int32(n_nodes),
    )
    queue.finish()
    ms["output"] = (time.perf_counter() - start) * 1e3

    stats = {
        "points": n,
        "nodes": n_nodes,
        "large_levels": large_levels,
        "small_levels": small_levels,
        "small_roots": n_roots,
        "radius": radius,
        "ms": ms,
    }
    return BuiltTree(
        nodes=out_nodes,
        info=out_info,
        points=out_pts,
        power=out_ph[0] if photons is not None else None,
        direction=out_ph[1] if photons is not None else None,
        normal=out_ph[2] if photons is not None else None,
        node_count=n_nodes,
        radius=radius,
        stats=stats,
    )
