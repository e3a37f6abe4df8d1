"""Breadth-first kd-tree build on the device [ZHWG08] (kdtree_build.cl).

The host launches the kernels of one level at a time and reads back only
the next level's counts (one scan total a level; the chunk kernel runs over
a bound and reads its own count on the device):

* large-node stage: chunk bounds (a work-item per chunk on a CPU, a
  work-group per chunk elsewhere), node bounds, empty-space cuts (up to
  ``MAX_CHAIN`` a node in one level: a cut moves no triangle) then a spatial
  median split, triangles clipped to the children (on Intel's CPU runtime
  ``RUN`` elements a work-item, straddlers' corners asked for ahead), counts
  and compaction by prefix sums (of each run's side flags: a node's count is
  the difference of two); children with at most ``SMALL`` triangles
  become small roots; a larger child becomes a leaf after more than
  ``BAD_SPLITS`` median splits in a row that made no progress for it (it
  kept all its parent's triangles, as around a fan's centre or in a stack,
  or the split did not pay by the SAH);
* small-node stage: candidate planes and their 64-bit side masks per small
  root, the SAH of every candidate of every node (a work-item per node on a
  CPU, a work-group per node elsewhere), a leaf where not splitting is
  cheaper (a node step weighed against the way leaves will be tested:
  ``cost_traverse``);
* output stage: subtree sizes bottom-up, preorder addresses top-down, then
  the ``KdNode`` array (device/layout.py) and the leaf triangle lists.

On a CPU device a small mesh (up to SERIAL_MAX triangles) is built after the
setup by one work-item (``KdBuild_serial``): the same steps in the same
order, so the same tree bit for bit, in one launch and one read where the
levels take a few hundred launches and dozens of reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes

from ..device import Device, primitives
from ..device.constants import KD_LEAF as LEAF
from ..device.constants import KD_MAX_DEPTH as MAX_DEPTH
from ..device.layout import KDNODE_DTYPE
from ..device.timer import StageTimer
from ..errors import check_stop
from . import kdtree_blocks

CHUNK = 256  # elements per chunk of the large-node stage
SMALL = 64  # largest small node (the width of its element mask)
EMPTY_RATIO = 0.25  # empty fraction of a side that is cut off
MAX_CHAIN = 6  # empty-space cuts a large node makes in one level before its split (one a face of its cell)
COST_TRAVERSE = 1.0  # SAH cost of a node step, in triangle tests, where leaves test triangles one by one
# the same where leaves test them four at a time from blocks (kdtree_blocks.py): a CPU traced fastest at 8-10
# (bench/kdtree.py: larger leaves, a quarter of the nodes; one by one, 1 was fastest)
COST_TRAVERSE_BLOCKS = 8.0
BAD_SPLITS = 2  # median splits in a row without progress allowed before a large node is a leaf (fans, stacks)
SAH_GROUP = 64  # work-group size of the per-node SAH search, and its work-items per node off the CPU
ELEMENT_BUDGET = 8  # large-stage elements per triangle before nodes become leaves
ELEMENT_SLACK = 65536  # large-stage elements allowed beyond the budget's share, for small meshes
PROGRAM = "accel/kdtree_build.cl"
RUN = 64  # large-stage elements a CPU work-item classifies and scatters in a row (32-128 alike at 636k)
PREFETCH_AHEAD = 16  # elements ahead in a run the classification asks for a straddler's corners (16-64 alike)
SERIAL_MAX = 12288  # largest mesh one work-item builds on a CPU device (as fast as two cores' launches at ~15k)
# room of the one work-item build, per triangle, plus SERIAL_SLACK (measured on blob meshes, the demo
# scenes and triangle soups: at most 1.45 elements in a level, 1.9 small-root elements, 3.9 records,
# 0.7 small nodes a level and 10.7 leaf references a triangle); it falls back when it needs more (a fan
# of triangles around one vertex: 105 leaf references a triangle)
SERIAL_ROOM = {"elements": 3, "small": 3, "records": 6, "leaves": 16, "small_nodes": 2}
SERIAL_SLACK = 1024


def element_budget(triangle_count: int) -> int:
    """Most elements a large level's children may hold before every large
    child of that level becomes a leaf."""
    return ELEMENT_BUDGET * triangle_count + ELEMENT_SLACK


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


def programs(device: Device, sah_lanes: int | None = None) -> list[tuple[str, dict]]:
    """The programs a build uses (for building them up front)."""
    return [(PROGRAM, _Config(device, sah_lanes).defines)]


def cost_traverse(blocks: bool) -> float:
    """The SAH cost of a node step for a tree whose leaves get blocks or not."""
    return COST_TRAVERSE_BLOCKS if blocks else COST_TRAVERSE


class _Config:
    """Group sizes and the program's defines on one device."""

    def __init__(self, device: Device, sah_lanes: int | None, sorted_masks: bool | None = None,
                 blocks: bool | None = None, runs: bool | None = None):
        max_group = int(device.device.max_work_group_size)
        self.chunk_group = 1 << int(math.log2(min(CHUNK, max_group)))
        self.sah_group = 1 << int(math.log2(min(SAH_GROUP, max_group)))
        # a CPU runs a node's candidates best in one work-item (no barriers);
        # other devices spread them over a work-group
        if sah_lanes is None:
            sah_lanes = 1 if device.is_cpu else self.sah_group
        self.sah_lanes = min(sah_lanes, self.sah_group)
        # a CPU bounds each chunk in one work-item, other devices in a group
        self.chunk_lanes = 1 if device.is_cpu else self.chunk_group
        # a CPU makes a small root's candidate masks from sorted bounds, one
        # work-item per root and axis; other devices one work-item per
        # candidate (the sorted form's private arrays were not measured there)
        self.sorted_masks = device.is_cpu if sorted_masks is None else bool(sorted_masks)
        # a CPU's work-item takes a run of the large stage's elements, and asks
        # for a straddler's corners ahead of its clipping (measured to pay
        # through Intel's runtime and PoCL); one element a work-item elsewhere
        if runs is None:
            runs = device.is_cpu
        self.run = RUN if runs else 1
        self.prefetch_ahead = PREFETCH_AHEAD if runs else 0
        # the SAH weighs a node step against how its leaves will be tested
        self.cost_traverse = cost_traverse(kdtree_blocks.wanted(device) if blocks is None else bool(blocks))
        self.defines = {
            "KD_CHUNK": CHUNK, "KD_SMALL": SMALL, "KD_EMPTY_RATIO": f"{EMPTY_RATIO!r}f",
            "KD_COST_TRAVERSE": f"{self.cost_traverse!r}f", "KD_BAD_SPLITS": BAD_SPLITS, "KD_SAH_GROUP": self.sah_group,
            "KD_SAH_LANES": self.sah_lanes, "KD_CHUNK_LANES": self.chunk_lanes,
            "KD_SORTED_MASKS": int(self.sorted_masks), "KD_MAX_CHAIN": MAX_CHAIN,
            "KD_RUN": self.run, "KD_PREFETCH_AHEAD": self.prefetch_ahead,
        }


class _Growing:
    """A device array appended to level by level, doubling its capacity."""

    def __init__(self, device: Device, dtype, capacity: int):
        self.device = device
        self.array = device.array(capacity, dtype)

    def reserve(self, size: int) -> cla.Array:
        if size > self.array.size:
            bigger = self.device.array(max(int(size), 2 * self.array.size), self.array.dtype)
            self.device.copy(bigger.data, self.array.data, self.array.nbytes)
            self.array = bigger
        return self.array

    @property
    def data(self) -> cl.Buffer:
        return self.array.data


def _values(device: Device, array: cla.Array, dtype) -> np.ndarray:
    """The lanes of a device vector (or vectors) as a flat host array."""
    return np.frombuffer(device.get(array).tobytes(), dtype).copy()


class _Build:
    """The state of one build: records (nodes in creation order), leaf lists,
    small roots and their elements, as growing device arrays."""

    def __init__(self, device: Device, verts: cla.Array, count: int, config: _Config,
                 should_stop: Callable[[], bool] | None = None):
        self.device = device
        self.should_stop = should_stop
        self.config = config
        self.verts = verts
        self.count = count
        self.max_depth = depth_limit(count)
        self.timer = StageTimer(device.queue)
        n = 2 * count + 1
        self.rec_lo, self.rec_hi = _Growing(device, cltypes.float4, n), _Growing(device, cltypes.float4, n)
        self.rec_info, self.rec_split = _Growing(device, cltypes.int4, n), _Growing(device, np.float32, n)
        self.rec_count = 1
        # record ranges in creation order; children come after parents, in a
        # later range but down a node's chain of cuts (inside one)
        self.batches = [(0, 1)]
        self.leaf_tris, self.leaf_count = _Growing(device, np.int32, n), 0
        self.small_roots = _Growing(device, cltypes.int4, count // 16 + 1)
        self.sel_tri, self.sel_lo, self.sel_hi = (_Growing(device, t, n) for t in (np.int32, cltypes.float4, cltypes.float4))
        self.root_count = self.small_count = 0
        self.large_levels = self.small_levels = 0

    def kernel(self, name: str):
        return self.device.kernel(PROGRAM, name, self.config.defines)

    def setup(self) -> None:
        """Root box, clipping tolerance, the root record and the elements."""
        dev, count = self.device, self.count
        lo, hi = primitives.bounds(dev, self.verts.data, 3 * count) if count else (np.zeros(4, np.float32),) * 2
        lo, hi = lo.copy(), hi.copy()
        lo[3] = hi[3] = 0.0
        self.lo, self.hi = lo, hi
        magnitude = float(max(np.abs(lo[:3]).max(), np.abs(hi[:3]).max()))
        self.eps = np.float32(max(magnitude * 2.0**-20, 1e-30))
        dev.write(self.rec_lo.data, lo)
        dev.write(self.rec_hi.data, hi)
        dev.write(self.rec_info.data, np.array([LEAF, 0, 0, 0], np.int32))
        self.el_tri, self.el_lo, self.el_hi = (dev.array(count, t) for t in (np.int32, cltypes.float4, cltypes.float4))
        self.kernel("KdBuild_init")(count, self.verts.data, np.int32(count), self.el_tri.data, self.el_lo.data,
                                    self.el_hi.data)

    def serial(self) -> cla.Array | None:
        """Everything after the setup by one work-item (KdBuild_serial):
        the node array, with the records, leaves and counts as the launched
        build leaves them; None when the build needs more room than
        SERIAL_ROOM gives (its records are then spoilt: build again from a
        fresh setup)."""
        dev, count, i32 = self.device, self.count, np.int32
        room = {name: per * count + SERIAL_SLACK for name, per in SERIAL_ROOM.items()}
        room["elements"] = max(room["elements"], count)  # the first level's
        el_cap, sel_cap, rec_cap, leaf_cap, sn_cap = (room[k] for k in ("elements", "small", "records", "leaves",
                                                                         "small_nodes"))
        act_cap = el_cap // (SMALL + 1) + 2  # large nodes hold more than SMALL elements each
        chunk_cap = act_cap + el_cap // CHUNK + 1
        batch_cap = 2 * self.max_depth + 4  # each level deepens what it keeps
        caps = np.array([(el_cap, act_cap, chunk_cap, sel_cap, rec_cap, leaf_cap, sn_cap, batch_cap)],
                        cltypes.int8)[0]
        for grow in (self.rec_lo, self.rec_hi, self.rec_info, self.rec_split):
            grow.reserve(rec_cap)
        for grow in (self.sel_tri, self.sel_lo, self.sel_hi):
            grow.reserve(sel_cap)
        self.small_roots.reserve(sel_cap)
        self.leaf_tris.reserve(leaf_cap)
        f4, i4, i8 = cltypes.float4, cltypes.int4, cltypes.int8
        elements = [dev.array(el_cap, t) for t in (np.int32, f4, f4)]
        for have, wide in zip((self.el_tri, self.el_lo, self.el_hi), elements):
            dev.copy(wide.data, have.data, have.nbytes)
        active = [dev.array(act_cap, t) for t in (f4, f4, i4)]
        dev.write(active[0].data, self.lo)
        dev.write(active[1].data, self.hi)
        dev.write(active[2].data, np.array([0, count, 0, 0], np.int32))
        nodes, result = dev.array(rec_cap, KDNODE_DTYPE), dev.array(8, np.int32)
        # in KdBuild_serial's order: records, elements (two sets), element work arrays, active nodes (two
        # sets), node work arrays, chunks, small roots and elements, candidates, small nodes (two sets),
        # leaves, batches, subtree sizes, addresses, the nodes and the result
        arrays = [
            self.rec_lo, self.rec_hi, self.rec_info, self.rec_split, *elements,
            *(dev.array(el_cap, t) for t in (np.int32, f4, f4, np.int32, np.int64, np.int64)), dev.array(1, np.int64),
            *(dev.array(el_cap, f4) for _ in range(4)), *active, *(dev.array(act_cap, t) for t in (f4, f4, i4)),
            *(dev.array(act_cap, t) for t in (np.int32, np.float32, np.int32, np.int32)),
            dev.array(MAX_CHAIN * act_cap, cltypes.int2), *(dev.array(act_cap, t) for t in (cltypes.int2, i8, i8, i4)),
            *(dev.array(chunk_cap, t) for t in (np.int32, f4, f4)), self.small_roots, self.sel_tri, self.sel_lo,
            self.sel_hi, dev.array(sel_cap, np.int32), dev.array(6 * sel_cap, cltypes.ulong2),
            *(dev.array(sn_cap, t) for t in (cltypes.int2, np.uint64, cltypes.int2, np.uint64, np.int32, np.int64)),
            self.leaf_tris, dev.array(batch_cap, cltypes.int2), dev.array(rec_cap, np.int32),
            dev.array(rec_cap, np.int32), nodes, result,
        ]
        budget = element_budget(count)
        self.kernel("KdBuild_serial")(1, self.verts.data, i32(count), i32(self.max_depth), self.eps, i32(budget), caps,
                                      *(a.data for a in arrays))
        status, *counts = (int(v) for v in dev.get(result)[:7])
        if status:
            return None
        (self.rec_count, self.leaf_count, self.root_count, self.small_count, self.large_levels,
         self.small_levels) = counts
        return nodes[: self.rec_count]

    def large_stage(self) -> None:
        """Median splits and empty-space cuts, level by level, until every
        node is small or a leaf."""
        dev, count = self.device, self.count
        if 0 < count <= SMALL:
            # the root is already small: its elements are the one small root's
            self.sel_tri.array, self.sel_lo.array, self.sel_hi.array = self.el_tri, self.el_lo, self.el_hi
            dev.write(self.small_roots.data, np.array([0, count, 0, 0], np.int32))
            self.root_count, self.small_count = 1, count
            return
        if count == 0:
            return
        self.act_lo, self.act_hi, self.act_info = (dev.array(1, t) for t in (cltypes.float4, cltypes.float4, cltypes.int4))
        dev.write(self.act_lo.data, self.lo)
        dev.write(self.act_hi.data, self.hi)
        dev.write(self.act_info.data, np.array([0, count, 0, 0], np.int32))
        self.active, self.elements = 1, count
        self.totals = (dev.empty(4), dev.array(1, np.int64), dev.array(1, cltypes.int8))
        while self.active:
            self.large_levels += 1
            self._large_level()
            check_stop(self.should_stop)

    def _large_level(self) -> None:
        dev, i32 = self.device, np.int32
        active, elements = self.active, self.elements
        total_i, total_l, total_8 = self.totals
        # chunks of every active node, and each chunk's bounds; their count
        # stays on the device (total_i): the chunk kernel runs over a bound
        chunk_base = dev.array(active, np.int32)
        self.kernel("KdBuild_chunk_counts")(active, self.act_info.data, i32(active), chunk_base.data)
        primitives.scan(dev, chunk_base.data, active, total=total_i)
        bound = active + elements // CHUNK
        chunk_node = dev.array(bound, np.int32)
        chunk_lo, chunk_hi = dev.array(bound, cltypes.float4), dev.array(bound, cltypes.float4)
        el_node = dev.array(elements, np.int32)
        self.kernel("KdBuild_chunk_nodes")(active, self.act_info.data, chunk_base.data, i32(active), chunk_node.data)
        bounds = self.kernel("KdBuild_chunk_bounds")
        bounds_args = (self.act_info.data, chunk_base.data, chunk_node.data, self.el_lo.data, self.el_hi.data,
                       el_node.data, chunk_lo.data, chunk_hi.data, total_i)
        if self.config.chunk_lanes == 1:
            bounds(bound, *bounds_args)
        else:
            bounds.groups(bound, self.config.chunk_group, *bounds_args)
        # each node's plane (after the cuts it chains where no child can spend
        # the element budget), each element's sides and clipped boxes
        budget = element_budget(self.count)
        node_split, node_mode, node_chain = (dev.array(active, t) for t in (np.float32, np.int32, np.int32))
        chain_cut = dev.array(MAX_CHAIN * active, cltypes.int2)
        self.kernel("KdBuild_large_split")(
            active, self.act_lo.data, self.act_hi.data, self.act_info.data, chunk_base.data, chunk_lo.data,
            chunk_hi.data, i32(active), i32(self.max_depth), i32(2 * elements <= budget), node_split.data,
            node_mode.data, node_chain.data, chain_cut.data)
        flags = dev.array(elements, np.int64)
        boxes = [dev.array(elements, cltypes.float4) for _ in range(4)]
        element_items = -(-elements // self.config.run)  # work-items of the element kernels: a run each
        run_scan = dev.array(element_items, np.int64)  # each run's flag sum, then their exclusive scan
        self.kernel("KdBuild_large_classify")(
            element_items, self.verts.data, self.el_tri.data, self.el_lo.data, self.el_hi.data, el_node.data,
            node_split.data, node_mode.data, i32(elements), self.eps, flags.data, run_scan.data,
            *[b.data for b in boxes])
        primitives.scan(dev, run_scan.data, element_items, "long", total=total_l.data)
        # children counts, with every node a leaf once the element budget is spent
        node_counts, counters, counter_scan = (dev.array(active, t) for t in (cltypes.int2, cltypes.int8, cltypes.int8))
        for force_leaf in (0, 1):
            self.kernel("KdBuild_large_children")(
                active, self.act_lo.data, self.act_hi.data, self.act_info.data, node_split.data, node_mode.data,
                node_chain.data, chain_cut.data, flags.data, run_scan.data, total_l.data, i32(elements), i32(active),
                i32(self.max_depth), i32(force_leaf), node_counts.data, counters.data)
            primitives.scan(dev, counters.data, active, "int8", out=counter_scan.data, total=total_8.data)
            totals = _values(dev, total_8, np.int32)
            if totals[0] <= budget:
                break
        next_elements, small_new, leaf_new, next_active, roots_new, rec_new = (int(t) for t in totals[:6])
        self._reserve_records(rec_new)
        self.small_roots.reserve(self.root_count + roots_new)
        for grow in (self.sel_tri, self.sel_lo, self.sel_hi):
            grow.reserve(self.small_count + small_new)
        self.leaf_tris.reserve(self.leaf_count + leaf_new)
        # the children: records, next level's nodes, small roots, leaves
        next_lo, next_hi, next_info = (dev.array(next_active, t) for t in (cltypes.float4, cltypes.float4, cltypes.int4))
        node_dest = dev.array(active, cltypes.int4)
        self.kernel("KdBuild_large_emit")(
            active, self.act_lo.data, self.act_hi.data, self.act_info.data, node_split.data, node_mode.data,
            node_chain.data, chain_cut.data, node_counts.data, counter_scan.data, i32(active), i32(self.max_depth),
            i32(force_leaf), i32(self.rec_count), i32(self.root_count), i32(self.small_count), i32(self.leaf_count),
            self.rec_lo.data, self.rec_hi.data, self.rec_info.data, self.rec_split.data, next_lo.data, next_hi.data,
            next_info.data, self.small_roots.data, node_dest.data)
        next_tri, next_el_lo, next_el_hi = (dev.array(next_elements, t) for t in (np.int32, cltypes.float4, cltypes.float4))
        self.kernel("KdBuild_large_scatter")(
            element_items, self.el_tri.data, el_node.data, self.act_info.data, flags.data, run_scan.data, total_l.data,
            *[b.data for b in boxes], node_dest.data, i32(elements), next_tri.data, next_el_lo.data, next_el_hi.data,
            self.sel_tri.data, self.sel_lo.data, self.sel_hi.data, self.leaf_tris.data)
        self.batches.append((self.rec_count, self.rec_count + rec_new))
        self.rec_count += rec_new
        self.root_count += roots_new
        self.small_count += small_new
        self.leaf_count += leaf_new
        self.act_lo, self.act_hi, self.act_info, self.active = next_lo, next_hi, next_info, next_active
        self.el_tri, self.el_lo, self.el_hi, self.elements = next_tri, next_el_lo, next_el_hi, next_elements

    def _reserve_records(self, extra: int) -> None:
        for grow in (self.rec_lo, self.rec_hi, self.rec_info, self.rec_split):
            grow.reserve(self.rec_count + extra)

    def small_stage(self) -> None:
        """Split every small root down to its leaves by the SAH, level by level."""
        if not self.root_count:
            return
        dev, i32 = self.device, np.int32
        roots, small = self.root_count, self.small_count
        sel_root = dev.array(small, np.int32)
        self.sn_node, self.sn_mask = dev.array(roots, cltypes.int2), dev.array(roots, np.uint64)
        self.kernel("KdBuild_small_init")(roots, self.small_roots.data, i32(roots), sel_root.data, self.sn_node.data,
                                          self.sn_mask.data)
        self.cand = dev.array(6 * small, cltypes.ulong2)
        if self.config.sorted_masks:
            self.kernel("KdBuild_small_masks_sorted")(3 * roots, self.small_roots.data, self.sel_lo.data,
                                                      self.sel_hi.data, i32(3 * roots), self.cand.data)
        else:
            self.kernel("KdBuild_small_masks")(6 * small, self.small_roots.data, sel_root.data, self.sel_lo.data,
                                               self.sel_hi.data, i32(6 * small), self.cand.data)
        self.small_total = dev.array(1, np.int64)
        self.small_active = roots
        while self.small_active:
            self.small_levels += 1
            self._small_level()
            check_stop(self.should_stop)

    def _small_level(self) -> None:
        dev, i32, config = self.device, np.int32, self.config
        active = self.small_active
        best = dev.array(active, np.int32)
        groups = -(-active * config.sah_lanes // config.sah_group)
        self.kernel("KdBuild_small_best").groups(
            groups, config.sah_group, self.sn_node.data, self.sn_mask.data, self.small_roots.data, self.rec_lo.data,
            self.rec_hi.data, self.rec_info.data, self.sel_lo.data, self.sel_hi.data, self.cand.data, i32(active),
            i32(self.max_depth), best.data)
        rank = dev.array(active, np.int64)
        self.kernel("KdBuild_small_ranks")(active, best.data, self.sn_mask.data, i32(active), rank.data)
        primitives.scan(dev, rank.data, active, "long", total=self.small_total.data)
        packed = int(dev.get(self.small_total)[0])
        splits, leaf_new = packed & 0xFFFFFFFF, packed >> 32
        self._reserve_records(2 * splits)
        self.leaf_tris.reserve(self.leaf_count + leaf_new)
        next_node, next_mask = dev.array(2 * splits, cltypes.int2), dev.array(2 * splits, np.uint64)
        self.kernel("KdBuild_small_emit")(
            active, self.sn_node.data, self.sn_mask.data, best.data, rank.data, self.small_roots.data,
            self.sel_tri.data, self.sel_lo.data, self.sel_hi.data, self.cand.data, i32(active), i32(self.rec_count),
            i32(self.leaf_count), self.rec_lo.data, self.rec_hi.data, self.rec_info.data, self.rec_split.data,
            next_node.data, next_mask.data, self.leaf_tris.data)
        self.batches.append((self.rec_count, self.rec_count + 2 * splits))
        self.rec_count += 2 * splits
        self.leaf_count += leaf_new
        self.sn_node, self.sn_mask, self.small_active = next_node, next_mask, 2 * splits

    def output_stage(self) -> cla.Array:
        """Preorder addresses (subtree sizes bottom-up, addresses top-down),
        then the node array."""
        dev, i32, n = self.device, np.int32, self.rec_count
        size, addr = dev.array(n, np.int32), dev.array(n, np.int32)
        for begin, end in reversed(self.batches):
            self.kernel("KdBuild_subtree_size")(end - begin, self.rec_info.data, i32(begin), i32(end), size.data)
        dev.fill(addr.data, 0, 4)
        for (begin, end), (next_begin, next_end) in zip(self.batches, self.batches[1:] + [(n, n)]):
            self.kernel("KdBuild_preorder")(end - begin, self.rec_info.data, size.data, i32(begin), i32(end),
                                            i32(next_begin), i32(next_end), addr.data)
        nodes = dev.array(n, KDNODE_DTYPE)
        self.kernel("KdBuild_output")(n, self.rec_info.data, self.rec_split.data, addr.data, i32(n), nodes.data)
        return nodes

    def statistics(self) -> dict:
        """Node, leaf and depth counts and the SAH cost, reduced on the device."""
        dev, n = self.device, self.rec_count
        terms, sizes = dev.empty(16 * n), dev.empty(16 * n)
        self.kernel("KdBuild_statistics")(n, self.rec_info.data, self.rec_lo.data, self.rec_hi.data, np.int32(n),
                                          terms, sizes)
        leaves, leaf_sum = (int(x) for x in primitives.sum_int4(dev, sizes, n)[:2])
        leaf_max, depth = (int(x) for x in primitives.max_int4(dev, sizes, n)[2:])
        sah = float(primitives.sum_float4(dev, terms, n)[0])
        d = (self.hi - self.lo)[:3].astype(np.float64)
        root_area = 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
        return {
            "nodes": n, "leaves": leaves, "depth": depth, "cost_traverse": self.config.cost_traverse,
            "mean_leaf_size": leaf_sum / leaves if leaves else 0.0, "max_leaf_size": leaf_max,
            "leaf_references": leaf_sum, "sah_cost": sah / root_area if root_area > 0 else float(leaf_sum),
            "large_levels": self.large_levels, "small_roots": self.root_count, "small_levels": self.small_levels,
        }


def build_tree(device: Device, verts: cla.Array, count: int, *, sah_lanes: int | None = None,
               should_stop: Callable[[], bool] | None = None, serial_max: int | None = None,
               sorted_masks: bool | None = None, blocks: bool | None = None, runs: bool | None = None) -> BuildOutput:
    """The kd-tree of ``count`` triangles whose corners are ``verts`` (3 float4 each).

    ``sah_lanes`` (a power of two, at most ``SAH_GROUP``) sets the work-items
    per node of the SAH search; by default 1 on a CPU, else ``SAH_GROUP``.
    The tree is the same whatever it is. ``should_stop`` is polled after
    every level (RenderCancelled). ``serial_max``: the largest mesh built by
    one work-item (where a node's SAH search has one lane); None: SERIAL_MAX
    on a CPU device, else 0. ``sorted_masks``: the small roots' candidate
    masks from sorted bounds (None: on a CPU device); the tree is the same.
    ``blocks``: whether its leaves will get blocks (None: where the device
    wants them, kdtree_blocks.wanted), which sets the SAH's cost of a node
    step (cost_traverse). ``runs``: the large stage's element kernels take
    RUN elements a work-item, asking for straddlers' corners ahead (None: on
    a CPU device other than PoCL); the tree is the same.
    """
    config = _Config(device, sah_lanes, sorted_masks, blocks, runs)
    build = _Build(device, verts, count, config, should_stop)
    timer = build.timer
    with timer.stage("setup"):
        build.setup()
    limit = serial_max if serial_max is not None else (SERIAL_MAX if device.is_cpu else 0)
    nodes = None
    if 0 < count <= limit and build.config.sah_lanes == 1:
        with timer.stage("serial"):
            nodes = build.serial()
        if nodes is None:  # out of room: the launched build, from a fresh setup
            build = _Build(device, verts, count, config, should_stop)
            timer = build.timer
            with timer.stage("setup"):
                build.setup()
    if nodes is None:
        with timer.stage("large"):
            build.large_stage()
        with timer.stage("small"):
            build.small_stage()
        with timer.stage("output"):
            nodes = build.output_stage()
    stats = build.statistics()
    stats["ms"] = timer.ms
    bmin = (build.lo - build.eps).astype(np.float32)
    bmax = (build.hi + build.eps).astype(np.float32)
    bmin[3] = bmax[3] = 0.0
    return BuildOutput(nodes=nodes, leaf_tris=build.leaf_tris.array, bmin=bmin, bmax=bmax, stats=stats)
