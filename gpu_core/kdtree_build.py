"""Breadth-first kd-tree build on the device [ZHWG08] (kernels/kdtree_build.cl).

The host launches the kernels of one level at a time and reads back only
counts (scan totals) to size the next level's arrays:

* large-node stage: chunk bounds, node bounds, empty-space cut or spatial
  median split, triangles clipped to the children, counts and compaction
  by prefix sums; children with at most ``SMALL`` triangles become small roots;
* small-node stage: candidate planes and their 64-bit side masks per small
  root, the SAH of every candidate of every node (a work-item per node on a
  CPU, a work-group per node elsewhere), a leaf where not splitting is
  cheaper;
* output stage: subtree sizes bottom-up, preorder addresses top-down, then
  the ``KdNode`` array of ``kernels/types.h`` and the leaf triangle lists.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes
from pyopencl.reduction import ReductionKernel
from pyopencl.scan import GenericScanKernel

from .device import Device

CHUNK = 256  # elements per chunk of the large-node stage
SMALL = 64  # largest small node (the width of its element mask)
EMPTY_RATIO = 0.25  # empty fraction of a side that is cut off
COST_TRAVERSE = 1.0  # SAH cost of a node step, in triangle tests
MAX_DEPTH = 64  # kernels/kdtree_traverse.h KD_MAX_DEPTH (the traversal stack)
SAH_GROUP = 64  # work-group size of the per-node SAH search, and its work-items per node off the CPU
ELEMENT_BUDGET = 8  # large-stage elements per triangle before nodes become leaves
LEAF = 3

NODE_DTYPE = np.dtype([("split", np.float32), ("axis", np.int32), ("child", np.int32), ("count", np.int32)])


def depth_limit(triangle_count: int) -> int:
    """Deepest level for ``triangle_count`` triangles (within the traversal stack)."""
    return min(MAX_DEPTH, int(12 + 1.5 * math.log2(max(triangle_count, 1))))


@dataclass
class BuildOutput:
    """Device arrays of a built tree, its root box and statistics."""

    nodes: cla.Array
    leaf_tris: cla.Array
    bmin: np.ndarray  # (4,) float32, padded root box
    bmax: np.ndarray
    stats: dict


class _Kernels:
    """The build program and the scan / reduction primitives, per device."""

    def __init__(self, device: Device, sah_lanes: int | None):
        ctx = device.context
        max_group = int(device.device.max_work_group_size)
        self.chunk_group = 1 << int(math.log2(min(CHUNK, max_group)))
        self.sah_group = 1 << int(math.log2(min(SAH_GROUP, max_group)))
        # a CPU runs a node's candidates best in one work-item (no barriers);
        # other devices spread them over a work-group
        if sah_lanes is None:
            sah_lanes = 1 if device.device.type & cl.device_type.CPU else self.sah_group
        self.sah_lanes = min(sah_lanes, self.sah_group)
        self.program = device.program(
            "kdtree_build.cl",
            {
                "KD_CHUNK": CHUNK,
                "KD_SMALL": SMALL,
                "KD_EMPTY_RATIO": f"{EMPTY_RATIO!r}f",
                "KD_COST_TRAVERSE": f"{COST_TRAVERSE!r}f",
                "KD_SAH_GROUP": self.sah_group,
                "KD_SAH_LANES": self.sah_lanes,
            },
        )
        self.kernel = {kernel.function_name: kernel for kernel in self.program.all_kernels()}
        total = "if (i + 1 == n) total[0] = item;"
        self.chunk_scan = GenericScanKernel(
            ctx, np.int32,
            arguments="__global const int4 *info, __global int *out, __global int *total, const int n",
            input_expr=f"(info[i].y + {CHUNK - 1}) / {CHUNK}",
            scan_expr="a + b", neutral="0",
            output_statement="out[i] = prev_item; " + total,
        )
        self.long_scan = GenericScanKernel(
            ctx, np.int64,
            arguments="__global const long *in, __global long *out, __global long *total, const int n",
            input_expr="in[i]", scan_expr="a + b", neutral="0",
            output_statement="out[i] = prev_item; " + total,
        )
        self.counter_scan = GenericScanKernel(
            ctx, cltypes.int8,
            arguments="__global const int8 *in, __global int8 *out, __global int8 *total, const int n",
            input_expr="in[i]", scan_expr="a + b", neutral="(int8)(0)",
            output_statement="out[i] = prev_item; " + total,
        )
        self.rank_scan = GenericScanKernel(
            ctx, np.int64,
            arguments="__global const int *best, __global const ulong *mask, "
            "__global long *out, __global long *total, const int n",
            input_expr="best[i] >= 0 ? 1L : ((long)popcount(mask[i]) << 32)",
            scan_expr="a + b", neutral="0",
            output_statement="out[i] = prev_item; " + total,
        )
        self.box_min = ReductionKernel(
            ctx, cltypes.float4, neutral="(float4)(INFINITY)", reduce_expr="fmin(a, b)",
            map_expr="v[i]", arguments="__global const float4 *v",
        )
        self.box_max = ReductionKernel(
            ctx, cltypes.float4, neutral="(float4)(-INFINITY)", reduce_expr="fmax(a, b)",
            map_expr="v[i]", arguments="__global const float4 *v",
        )
        area = "(2.0f * ((hi[i].x - lo[i].x) * (hi[i].y - lo[i].y) + (hi[i].y - lo[i].y) * " \
               "(hi[i].z - lo[i].z) + (hi[i].z - lo[i].z) * (hi[i].x - lo[i].x)))"
        self.sah = ReductionKernel(
            ctx, np.float32, neutral="0", reduce_expr="a + b",
            map_expr=f"(info[i].x == {LEAF} ? (float)info[i].z : {COST_TRAVERSE!r}f) * {area}",
            arguments="__global const int4 *info, __global const float4 *lo, __global const float4 *hi",
        )
        self.leaf_stats = ReductionKernel(
            ctx, cltypes.int4, neutral="(int4)(0)",
            reduce_expr="(int4)(a.x + b.x, a.y + b.y, max(a.z, b.z), max(a.w, b.w))",
            map_expr=f"(info[i].x == {LEAF} ? (int4)(1, info[i].z, info[i].z, info[i].w) "
            "    : (int4)(0, 0, 0, info[i].w))",
            arguments="__global const int4 *info",
        )


_KERNELS: dict[tuple[int, int | None], _Kernels] = {}


def _kernels(device: Device, sah_lanes: int | None = None) -> _Kernels:
    key = (id(device), sah_lanes)
    if key not in _KERNELS:
        _KERNELS[key] = _Kernels(device, sah_lanes)
    return _KERNELS[key]


class _Growing:
    """A device array appended to level by level, doubling its capacity."""

    def __init__(self, queue, dtype, capacity: int):
        self.queue = queue
        self.array = cla.empty(queue, max(int(capacity), 1), dtype)

    def reserve(self, size: int) -> cla.Array:
        if size > self.array.size:
            bigger = cla.empty(self.queue, max(int(size), 2 * self.array.size), self.array.dtype)
            cl.enqueue_copy(self.queue, bigger.data, self.array.data, byte_count=self.array.nbytes)
            self.array = bigger
        return self.array

    @property
    def data(self) -> cl.Buffer:
        return self.array.data


def _values(array: cla.Array, dtype) -> np.ndarray:
    """The lanes of a device vector (or vectors) as a flat host array."""
    return np.frombuffer(array.get().tobytes(), dtype).copy()


def _empty(queue, n: int, dtype) -> cla.Array:
    return cla.empty(queue, max(int(n), 1), dtype)


class _Stages:
    """Milliseconds per build stage, each ended by a queue finish."""

    def __init__(self, queue):
        self.queue = queue
        self.ms: dict[str, float] = {}
        self._start = time.perf_counter()

    def end(self, name: str) -> None:
        self.queue.finish()
        now = time.perf_counter()
        self.ms[name] = self.ms.get(name, 0.0) + (now - self._start) * 1e3
        self._start = now


def build_tree(device: Device, verts: cla.Array, count: int, *, sah_lanes: int | None = None) -> BuildOutput:
    """The kd-tree of ``count`` triangles whose corners are ``verts`` (3 float4 each).

    ``sah_lanes`` (a power of two, at most ``SAH_GROUP``) sets the work-items
    per node of the SAH search; by default 1 on a CPU, else ``SAH_GROUP``.
    The tree is the same whatever it is.
    """
    k = _kernels(device, sah_lanes)
    q = device.queue
    kern = k.kernel
    i32 = np.int32
    stages = _Stages(q)
    max_depth = depth_limit(count)

    # root box and the clipping tolerance, scaled to the scene's coordinates
    if count:
        lo = _values(k.box_min(verts, queue=q), np.float32)
        hi = _values(k.box_max(verts, queue=q), np.float32)
    else:
        lo = hi = np.zeros(4, np.float32)
    lo, hi = lo.copy(), hi.copy()
    lo[3] = hi[3] = 0.0
    magnitude = float(max(np.abs(lo[:3]).max(), np.abs(hi[:3]).max()))
    eps = np.float32(max(magnitude * 2.0**-20, 1e-30))

    # records, with the root as record 0
    rec_lo = _Growing(q, cltypes.float4, 2 * count + 1)
    rec_hi = _Growing(q, cltypes.float4, 2 * count + 1)
    rec_info = _Growing(q, cltypes.int4, 2 * count + 1)
    rec_split = _Growing(q, np.float32, 2 * count + 1)
    cl.enqueue_copy(q, rec_lo.data, lo.view(cltypes.float4))
    cl.enqueue_copy(q, rec_hi.data, hi.view(cltypes.float4))
    cl.enqueue_copy(q, rec_info.data, np.array([LEAF, 0, 0, 0], np.int32).view(cltypes.int4))
    rec_count = 1
    batches = [(0, 1)]  # record ranges in creation order; children come after parents
    leaf_tris = _Growing(q, np.int32, 2 * count + 1)
    leaf_count = 0
    small_roots = _Growing(q, cltypes.int4, count // 16 + 1)
    sel_tri = _Growing(q, np.int32, 2 * count + 1)
    sel_lo = _Growing(q, cltypes.float4, 2 * count + 1)
    sel_hi = _Growing(q, cltypes.float4, 2 * count + 1)
    root_count = small_count = 0
    large_levels = small_levels = 0

    el_tri = _empty(q, count, np.int32)
    el_lo = _empty(q, count, cltypes.float4)
    el_hi = _empty(q, count, cltypes.float4)
    if count:
        kern["KdBuild_init"](q, (count,), None, verts.data, i32(count), el_tri.data, el_lo.data, el_hi.data)
    stages.end("setup")

    if 0 < count <= SMALL:
        # the root is already small: its elements are the one small root's
        sel_tri.array, sel_lo.array, sel_hi.array = el_tri, el_lo, el_hi
        cl.enqueue_copy(q, small_roots.data, np.array([0, count, 0, 0], np.int32).view(cltypes.int4))
        root_count, small_count = 1, count
    elif count > SMALL:
        # ---- large-node stage ----
        act_lo = _empty(q, 1, cltypes.float4)
        act_hi = _empty(q, 1, cltypes.float4)
        act_info = _empty(q, 1, cltypes.int4)
        cl.enqueue_copy(q, act_lo.data, lo.view(cltypes.float4))
        cl.enqueue_copy(q, act_hi.data, hi.view(cltypes.float4))
        cl.enqueue_copy(q, act_info.data, np.array([0, count, 0, 0], np.int32).view(cltypes.int4))
        active, elements = 1, count
        budget = ELEMENT_BUDGET * count + 65536
        total_i = _empty(q, 1, np.int32)
        total_l = _empty(q, 1, np.int64)
        total_8 = _empty(q, 1, cltypes.int8)
        while active:
            large_levels += 1
            a_, e_ = (active,), (elements,)
            chunk_base = _empty(q, active, np.int32)
            k.chunk_scan(act_info, chunk_base, total_i, i32(active), size=active, queue=q)
            chunks = int(total_i.get()[0])
            chunk_node = _empty(q, chunks, np.int32)
            chunk_lo = _empty(q, chunks, cltypes.float4)
            chunk_hi = _empty(q, chunks, cltypes.float4)
            el_node = _empty(q, elements, np.int32)
            kern["KdBuild_chunk_nodes"](q, a_, None, act_info.data, chunk_base.data, i32(active), chunk_node.data)
            kern["KdBuild_chunk_bounds"](
                q, (chunks * k.chunk_group,), (k.chunk_group,), act_info.data, chunk_base.data,
                chunk_node.data, el_lo.data, el_hi.data, el_node.data, chunk_lo.data, chunk_hi.data,
            )
            node_split = _empty(q, active, np.float32)
            node_mode = _empty(q, active, np.int32)
            kern["KdBuild_large_split"](
                q, a_, None, act_lo.data, act_hi.data, act_info.data, chunk_base.data,
                chunk_lo.data, chunk_hi.data, i32(active), node_split.data, node_mode.data,
            )
            flags = _empty(q, elements, np.int64)
            boxes = [_empty(q, elements, cltypes.float4) for _ in range(4)]
            kern["KdBuild_large_classify"](
                q, e_, None, verts.data, el_tri.data, el_lo.data, el_hi.data, el_node.data,
                node_split.data, node_mode.data, i32(elements), eps, flags.data,
                *[b.data for b in boxes],
            )
            flag_scan = _empty(q, elements, np.int64)
            k.long_scan(flags, flag_scan, total_l, i32(elements), size=elements, queue=q)
            node_counts = _empty(q, active, cltypes.int2)
            counters = _empty(q, active, cltypes.int8)
            counter_scan = _empty(q, active, cltypes.int8)
            for force_leaf in (0, 1):
                kern["KdBuild_large_children"](
                    q, a_, None, act_info.data, node_mode.data, flag_scan.data, total_l.data,
                    i32(elements), i32(active), i32(max_depth), i32(force_leaf),
                    node_counts.data, counters.data,
                )
                k.counter_scan(counters, counter_scan, total_8, i32(active), size=active, queue=q)
                totals = _values(total_8, np.int32)
                if totals[0] <= budget:
                    break
            next_elements, small_new, leaf_new = int(totals[0]), int(totals[1]), int(totals[2])
            next_active, roots_new, rec_new = int(totals[3]), int(totals[4]), int(totals[5])
            for grow in (rec_lo, rec_hi, rec_info, rec_split):
                grow.reserve(rec_count + rec_new)
            small_roots.reserve(root_count + roots_new)
            for grow in (sel_tri, sel_lo, sel_hi):
                grow.reserve(small_count + small_new)
            leaf_tris.reserve(leaf_count + leaf_new)
            next_lo = _empty(q, next_active, cltypes.float4)
            next_hi = _empty(q, next_active, cltypes.float4)
            next_info = _empty(q, next_active, cltypes.int4)
            node_dest = _empty(q, active, cltypes.int4)
            kern["KdBuild_large_emit"](
                q, a_, None, act_lo.data, act_hi.data, act_info.data, node_split.data,
                node_mode.data, node_counts.data, counter_scan.data, i32(active), i32(max_depth),
                i32(force_leaf), i32(rec_count), i32(root_count), i32(small_count), i32(leaf_count),
                rec_lo.data, rec_hi.data, rec_info.data, rec_split.data,
                next_lo.data, next_hi.data, next_info.data, small_roots.data, node_dest.data,
            )
            next_tri = _empty(q, next_elements, np.int32)
            next_el_lo = _empty(q, next_elements, cltypes.float4)
            next_el_hi = _empty(q, next_elements, cltypes.float4)
            kern["KdBuild_large_scatter"](
                q, e_, None, el_tri.data, el_node.data, act_info.data, flags.data, flag_scan.data,
                *[b.data for b in boxes], node_dest.data, i32(elements),
                next_tri.data, next_el_lo.data, next_el_hi.data,
                sel_tri.data, sel_lo.data, sel_hi.data, leaf_tris.data,
            )
            batches.append((rec_count, rec_count + rec_new))
            rec_count += rec_new
            root_count += roots_new
            small_count += small_new
            leaf_count += leaf_new
            act_lo, act_hi, act_info, active = next_lo, next_hi, next_info, next_active
            el_tri, el_lo, el_hi, elements = next_tri, next_el_lo, next_el_hi, next_elements
    stages.end("large")

    if root_count:
        rec_count, leaf_count, small_levels = _small_stage(
            k, q, max_depth, root_count, small_count, small_roots, sel_tri, sel_lo, sel_hi,
            rec_lo, rec_hi, rec_info, rec_split, rec_count, leaf_tris, leaf_count, batches,
        )
    stages.end("small")

    # ---- output stage: preorder addresses, then the node array ----
    size = _empty(q, rec_count, np.int32)
    addr = _empty(q, rec_count, np.int32)
    for begin, end in reversed(batches):
        kern["KdBuild_subtree_size"](q, (end - begin,), None, rec_info.data, i32(begin), i32(end), size.data)
    cl.enqueue_copy(q, addr.data, np.zeros(1, np.int32))
    for begin, end in batches:
        kern["KdBuild_preorder"](q, (end - begin,), None, rec_info.data, size.data, i32(begin), i32(end), addr.data)
    nodes = cla.empty(q, rec_count, NODE_DTYPE)
    kern["KdBuild_output"](q, (rec_count,), None, rec_info.data, rec_split.data, addr.data, i32(rec_count), nodes.data)
    stages.end("output")

    stats = _statistics(k, q, rec_info.array, rec_lo.array, rec_hi.array, rec_count, lo, hi)
    stats.update(large_levels=large_levels, small_roots=root_count, small_levels=small_levels)
    stats["ms"] = stages.ms
    bmin = (lo - eps).astype(np.float32)
    bmax = (hi + eps).astype(np.float32)
    bmin[3] = bmax[3] = 0.0
    return BuildOutput(nodes=nodes, leaf_tris=leaf_tris.array, bmin=bmin, bmax=bmax, stats=stats)


def _small_stage(k, q, max_depth, root_count, small_count, small_roots, sel_tri, sel_lo, sel_hi,
                 rec_lo, rec_hi, rec_info, rec_split, rec_count, leaf_tris, leaf_count, batches):
    """Split every small root down to its leaves by the SAH, level by level.

    Returns the record and leaf-triangle counts and the number of levels."""
    kern = k.kernel
    i32 = np.int32
    sel_root = _empty(q, small_count, np.int32)
    sn_node = _empty(q, root_count, cltypes.int2)
    sn_mask = _empty(q, root_count, np.uint64)
    kern["KdBuild_small_init"](
        q, (root_count,), None, small_roots.data, i32(root_count), sel_root.data, sn_node.data, sn_mask.data
    )
    cand = _empty(q, 6 * small_count, cltypes.ulong2)
    kern["KdBuild_small_masks"](
        q, (6 * small_count,), None, small_roots.data, sel_root.data, sel_lo.data, sel_hi.data,
        i32(6 * small_count), cand.data,
    )
    total = _empty(q, 1, np.int64)
    active, levels = root_count, 0
    while active:
        levels += 1
        best = _empty(q, active, np.int32)
        groups = -(-active * k.sah_lanes // k.sah_group)
        kern["KdBuild_small_best"](
            q, (groups * k.sah_group,), (k.sah_group,), sn_node.data, sn_mask.data, small_roots.data,
            rec_lo.data, rec_hi.data, rec_info.data, sel_lo.data, sel_hi.data, cand.data,
            i32(active), i32(max_depth), best.data,
        )
        rank = _empty(q, active, np.int64)
        k.rank_scan(best, sn_mask, rank, total, i32(active), size=active, queue=q)
        packed = int(total.get()[0])
        splits, leaf_new = packed & 0xFFFFFFFF, packed >> 32
        for grow in (rec_lo, rec_hi, rec_info, rec_split):
            grow.reserve(rec_count + 2 * splits)
        leaf_tris.reserve(leaf_count + leaf_new)
        next_node = _empty(q, 2 * splits, cltypes.int2)
        next_mask = _empty(q, 2 * splits, np.uint64)
        kern["KdBuild_small_emit"](
            q, (active,), None, sn_node.data, sn_mask.data, best.data, rank.data, small_roots.data,
            sel_tri.data, sel_lo.data, sel_hi.data, cand.data, i32(active), i32(rec_count),
            i32(leaf_count), rec_lo.data, rec_hi.data, rec_info.data, rec_split.data,
            next_node.data, next_mask.data, leaf_tris.data,
        )
        batches.append((rec_count, rec_count + 2 * splits))
        rec_count += 2 * splits
        leaf_count += leaf_new
        sn_node, sn_mask, active = next_node, next_mask, 2 * splits
    return rec_count, leaf_count, levels


def _statistics(k, q, info, lo_arr, hi_arr, n, lo, hi) -> dict:
    """Node, leaf and depth counts and the SAH cost, reduced on the device."""
    leaves, leaf_sum, leaf_max, depth = (
        int(x) for x in _values(k.leaf_stats(info, range=slice(n), queue=q), np.int32)
    )
    sah = float(k.sah(info, lo_arr, hi_arr, range=slice(n), queue=q).get())
    d = (hi - lo)[:3].astype(np.float64)
    root_area = 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
    return {
        "nodes": n,
        "leaves": leaves,
        "depth": depth,
        "mean_leaf_size": leaf_sum / leaves if leaves else 0.0,
        "max_leaf_size": leaf_max,
        "leaf_references": leaf_sum,
        "sah_cost": sah / root_area if root_area > 0 else float(leaf_sum),
    }
