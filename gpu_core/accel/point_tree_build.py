"""Device build of the point kd-tree (point_tree_build.cl), level by level.

The host loops over tree levels and reads back only list sizes (one read
per level; a large level's read is queued without waiting, and waited on
once the next level is queued); every kernel works on all nodes (or point
chunks) of a level at once:

* large-node stage: an empty-space cut and a median split of what it keeps
  per node and level (or a median split alone), the points partitioned
  between two arrays in turn, the next level's nodes and chunks listed on
  the device;
* small-node stage: VVH splits over bit masks of each small root's points;
* output stage: sums bottom-up (sizes, photon power, positions), preorder
  addresses top-down, then the traversal nodes, the node payloads
  (``PointNode``) and the points in leaf order.

A small point set (up to SERIAL_MAX points) is built in one launch instead
(``PointBuild_serial``): its levels one after another, each level's steps
shared among one work-group (of one work-item on a CPU device), the same
steps in the same order, so the same tree bit for bit, in one launch and one
read where the levels take about a hundred launches and a dozen reads,
which cost far more than their work (on a CPU device, and on a GPU, whose
frames wait on the host's launches).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pyopencl.cltypes as cltypes

from ..device import Device, primitives
from ..device.constants import POINT_BUILD_SMALL as SMALL_MAX
from ..device.constants import POINT_BUILD_CHUNK as CHUNK_POINTS
from ..device.constants import POINT_TREE_MAX_DEPTH as MAX_DEPTH
from ..device.layout import BUILD_NODE_DTYPE, BUILD_SUMS_DTYPE, CHUNK_DTYPE, KDNODE_DTYPE, POINT_NODE_DTYPE, float4_rows
from ..device.timer import StageTimer

EMPTY_RATIO = 0.1  # empty fraction of a cell that is cut off, retuned for points
COST_TRAVERSE = 3.0  # VVH cost of visiting a node, in point tests (kNN fastest at 3 on photon maps)
SERIAL_MAX = 16384  # largest point set built in one launch
SERIAL_BATCHES = 2 * MAX_DEPTH + 2  # BUILD_SERIAL_BATCHES
# node table of the one-launch build: SERIAL_ROOM slots a point and SERIAL_SLACK more (measured: at
# most half a slot a point on clouds, walls, lines, planes and tight clusters); it falls back when full
SERIAL_ROOM = 1.0
SERIAL_SLACK = 256
PROGRAM = "accel/point_tree_build.cl"


@dataclass
class BuildParams:
    """Knobs of the build; the defaults suit kNN with k about k_hint."""

    k_hint: float = 50.0  # the k the VVH radius is estimated for
    radius: float | None = None  # search radius R of the VVH; None: estimated from the points
    cost_traverse: float = COST_TRAVERSE
    empty_ratio: float = EMPTY_RATIO
    max_depth: int = MAX_DEPTH
    serial_max: int | None = None  # largest set built in one launch; None: SERIAL_MAX
    serial_group: int | None = None  # its work-group; None: one work-item on a CPU device, else the kernel's local size


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

    def __init__(self, device: Device, capacity: int):
        self.device = device
        self.array = device.array(max(capacity, 16), BUILD_NODE_DTYPE)
        self.count = 0

    def reserve(self, extra: int) -> int:
        """Room for ``extra`` more nodes; returns the id of the first one."""
        need = self.count + extra
        if need > len(self.array):
            bigger = self.device.array(max(need, 2 * len(self.array)), BUILD_NODE_DTYPE)
            self.device.copy(bigger.data, self.array.data, self.count * BUILD_NODE_DTYPE.itemsize)
            self.array = bigger
        base = self.count
        self.count = need
        return base


def points_on_device(device: Device, points: np.ndarray) -> cla.Array:
    """(N, 4) float32 device array: xyz, and the point's index in w (int bits)."""
    work4 = float4_rows(points)
    work4[:, 3] = np.arange(len(points), dtype=np.int32).view(np.float32)
    return device.array_from(work4)


class _Build:
    """The state of one build: the node table, the working point array (and
    the other one a level partitions into) and the batches of nodes made per
    level (children after parents)."""

    def __init__(self, device: Device, points: cla.Array, photons: tuple | None, params: BuildParams,
                 capacity: int | None = None):
        self.device = device
        self.params = params
        n = self.n = len(points)
        self.work = device.array(max(n, 1) * 4, np.float32).reshape(max(n, 1), 4)
        device.copy(self.work.data, points.data, n * 16, src_offset=points.offset)
        self.scratch = cla.empty_like(self.work)
        self.has_photons = np.int32(photons is not None and n > 0)
        self.photons = list(photons) if self.has_photons else [device.array(4, np.float32) for _ in range(3)]
        self.table = _NodeTable(device, capacity or 2 * max(n, 1) // 8 + 64)
        self.table.reserve(1)
        root = np.zeros(1, BUILD_NODE_DTYPE)
        root["lo"], root["hi"] = np.inf, -np.inf
        root["count"], root["root"], root["left"] = n, -1, -1
        device.write(self.table.array.data, root)
        self.batches = [(0, 1, 0, 0)]  # first id, count, and the id range of the X children made with them
        self.max_depth = np.int32(min(params.max_depth, MAX_DEPTH))
        self.small_parts = [device.array_from(np.zeros(1, np.int32))] if 2 <= n <= SMALL_MAX else []
        self.large_levels = self.small_levels = 0

    def launch(self, name: str, n: int, *args) -> None:
        self.device.kernel(PROGRAM, name)(n, *args)

    def large_stage(self) -> None:
        """Median splits and empty-space cuts, level by level. The host
        queues each level before it has read how many large nodes the level
        before made: the level's kernels read that count on the device and
        run over room for twice the count of the level before (a node makes
        at most two large nodes), which the host reads while the device
        works on the level queued after it. So the device does not wait on
        the host between levels; the last level queued finds no active node
        and does nothing."""
        if self.n <= SMALL_MAX:
            return
        dev = self.device
        active = dev.array_from(np.zeros(1, np.int32))
        chunk_end = dev.array_from(np.array([-(-self.n // CHUNK_POINTS)], np.int32))
        chunks = dev.array(1 + self.n // CHUNK_POINTS, CHUNK_DTYPE)
        self.launch("PointBuild_root_chunks", 1, self.table.array.data, chunk_end.data, chunks.data)
        count = dev.to_device(np.array([1, 0], np.int32))  # the level's active nodes: the root alone
        slots, before = 1, None
        while True:
            active, chunk_end, chunks, count, small = self._large_level(active, chunk_end, chunks, count, slots)
            made = (dev.read_later(count, 2, np.int32), small)  # the large nodes and small roots it makes
            n_active = 1 if before is None else self._made(before)  # the level just queued had these
            if not n_active:
                self._made(made)
                return
            self.large_levels += 1
            slots, before = 2 * n_active, made

    def _made(self, made: tuple) -> int:
        """Wait for a level's counts (read_later, with its list of small
        roots): keep its small roots; return its count of large nodes."""
        read, small = made
        n_large, n_small = (int(v) for v in read.wait())
        if n_small:
            self.small_parts.append(small[:n_small])
        return n_large

    def _large_level(self, active: cla.Array, chunk_end: cla.Array, chunks: cla.Array, count: cl.Buffer,
                     slots: int) -> tuple:
        """One level over the active nodes (``count``: their number on the
        device, at most ``slots``), whose chunks (and their inclusive scan
        per node, chunk_end) the last level listed; returns the next level's
        lists, their counts (large nodes, small roots: a device buffer) and
        the small roots' list."""
        dev, nodes, i32 = self.device, self.table.array, np.int32
        # chunk bounds (the chunk count stays on the device: the chunk
        # kernels run over a bound)
        bound = slots + self.n // CHUNK_POINTS
        chunk_lo, chunk_hi = dev.array(4 * bound, np.float32), dev.array(4 * bound, np.float32)
        chunk_left, left_end = dev.array(bound, np.int32), dev.array(bound, np.int32)
        level = (chunk_end.data, count)
        self.launch("PointBuild_chunk_bounds", bound, chunks.data, self.work.data, chunk_lo.data, chunk_hi.data, *level)
        # each node's cut and the split of what it keeps, or its split; then
        # its points partitioned stably
        x_plane = dev.array(4 * slots, np.float32)
        self.launch("PointBuild_large_decide", slots, active.data, nodes.data, chunk_end.data, chunk_lo.data,
                    chunk_hi.data, np.float32(self.params.empty_ratio), self.max_depth, x_plane.data, count)
        self.launch("PointBuild_chunk_count_left", bound, chunks.data, active.data, nodes.data, x_plane.data,
                    self.work.data, chunk_left.data, *level, i32(bound))
        primitives.scan(dev, chunk_left.data, bound, out=left_end.data, inclusive=True)
        # children two per slot, then the children of the cut-off parts two per slot (holes where none)
        new = 4 * slots
        base = self.table.reserve(new)
        nodes = self.table.array
        classes = dev.array(new, cltypes.int8)
        self.launch("PointBuild_large_split", slots, active.data, nodes.data, chunk_end.data, left_end.data,
                    x_plane.data, i32(base), self.max_depth, classes.data, count, i32(slots))
        self.launch("PointBuild_chunk_scatter", bound, chunks.data, active.data, nodes.data, x_plane.data,
                    self.work.data, self.scratch.data, chunk_left.data, left_end.data, *level)
        self.work, self.scratch = self.scratch, self.work  # the partitioned points are the working array now
        # one batch: the children of the cut-off parts (after them) are done with their parents
        self.batches.append((base, 2 * slots, base + 2 * slots, base + new))
        # new nodes: the next level's large nodes with their chunks, and the
        # small roots, counted together (lanes of one int8)
        scanned = dev.array(new, cltypes.int8)
        total = primitives.scan(dev, classes.data, new, kind="int8", out=scanned.data)
        large, small, next_end = (dev.array(new, np.int32) for _ in range(3))
        next_chunks = dev.array(new + self.n // CHUNK_POINTS, CHUNK_DTYPE)
        self.launch("PointBuild_lists", new, classes.data, scanned.data, i32(base), i32(new), nodes.data,
                    self.work.data, self.scratch.data, large.data, small.data, next_end.data, next_chunks.data)
        return large, next_end, next_chunks, total, small

    def small_stage(self) -> None:
        """VVH splits over bit masks of each small root's points."""
        dev, i32 = self.device, np.int32
        roots = _cat(dev, self.small_parts, np.int32)
        n_roots = self.n_roots = sum(len(p) for p in self.small_parts)
        self.masks = dev.array(max(n_roots, 1) * 3 * SMALL_MAX, np.uint32)
        root_radius = dev.array(n_roots, np.float32)
        self.launch("PointBuild_small_roots", n_roots, roots.data, self.table.array.data, self.work.data,
                    self.masks.data, root_radius.data, np.float32(self.params.k_hint), i32(n_roots))
        self.radius = self._vvh_radius(root_radius, n_roots)
        active, n_active = roots, n_roots
        while n_active:
            self.small_levels += 1
            active, n_active = self._small_level(active, n_active)

    def _vvh_radius(self, root_radius: cla.Array, n_roots: int) -> float:
        """The search radius of the VVH: given, else the median of the small
        roots' estimates."""
        if self.params.radius is not None:
            return max(float(self.params.radius), 0.0)
        estimates = self.device.get(root_radius)[:n_roots]
        estimates = estimates[np.isfinite(estimates) & (estimates > 0)]
        return float(np.median(estimates)) if estimates.size else 0.0

    def _small_level(self, active: cla.Array, n_active: int) -> tuple[cla.Array, int]:
        """Split the active small nodes that gain by it; all their children are
        the next level's active nodes (small_decide leaves the leaves)."""
        dev, i32 = self.device, np.int32
        flag, cand = dev.array(n_active, np.int32), dev.array(n_active, np.int32)
        self.launch("PointBuild_small_decide", n_active, active.data, self.table.array.data, self.work.data,
                    self.masks.data, np.float32(self.radius), np.float32(self.params.cost_traverse), self.max_depth,
                    flag.data, cand.data, i32(n_active))
        splitting, n_split = primitives.compact(dev, flag.data, n_active)
        if not n_split:
            return active, 0
        base = self.table.reserve(2 * n_split)
        children = dev.array(2 * n_split, np.int32)
        self.launch("PointBuild_small_split", n_split, splitting, active.data, self.table.array.data, cand.data,
                    self.masks.data, i32(base), children.data, i32(n_split))
        self.batches.append((base, 2 * n_split, 0, 0))
        return children, 2 * n_split

    def output_stage(self) -> tuple:
        """Sums bottom-up, preorder addresses top-down, then every node and
        point to its place."""
        dev, i32 = self.device, np.int32
        n, n_nodes, ph, nodes = self.n, self.table.count, self.photons, self.table.array
        size, sums = dev.array(n_nodes, np.int32), dev.array(n_nodes, BUILD_SUMS_DTYPE)
        for base, count, x_first, x_end in reversed(self.batches):
            self.launch("PointBuild_sums", count, nodes.data, self.work.data, ph[0].data, ph[1].data, ph[2].data,
                        self.has_photons, size.data, sums.data, i32(base), i32(count), i32(x_first), i32(x_end))
        # the tree's nodes: the root's subtree (the table also holds unused slots)
        self.node_count = int(dev.scalar(size.data, np.int32))
        addr, first = dev.array(n_nodes, np.int32), dev.array(n_nodes, np.int32)
        dev.fill(addr.data, 0, addr.nbytes)
        dev.fill(first.data, 0, first.nbytes)
        for base, count, x_first, x_end in self.batches:
            self.launch("PointBuild_preorder", count, nodes.data, size.data, addr.data, first.data, i32(base), i32(count),
                        i32(x_first), i32(x_end))
        out_nodes, out_info = dev.array(self.node_count, KDNODE_DTYPE), dev.array(self.node_count, POINT_NODE_DTYPE)
        out_pts = dev.array(max(n, 1) * 4, np.float32).reshape(max(n, 1), 4)
        out_ph = [dev.array(max(n, 1) * 4, np.float32).reshape(max(n, 1), 4) for _ in range(3)]
        self.launch("PointBuild_emit", n_nodes, nodes.data, sums.data, addr.data, first.data, self.work.data,
                    ph[0].data, ph[1].data, ph[2].data, self.has_photons, np.float32(self.radius), out_nodes.data,
                    out_info.data, out_pts.data, out_ph[0].data, out_ph[1].data, out_ph[2].data, i32(n_nodes))
        return out_nodes, out_info, out_pts, out_ph


def _cat(device: Device, parts: list[cla.Array], dtype) -> cla.Array:
    """One device array holding ``parts`` in order."""
    out = device.array(sum(len(p) for p in parts), dtype)
    offset = 0
    for p in parts:
        if len(p):
            device.copy(out.data, p.data, p.nbytes, dst_offset=offset * out.dtype.itemsize, src_offset=p.offset)
            offset += len(p)
    return out


def build(device: Device, points: cla.Array, photons: tuple | None, params: BuildParams) -> BuiltTree:
    """Build the tree over ``points``, an (N, 4) float32 device array with
    each point's index in w (see points_on_device); ``photons`` is
    ``(power, direction, normal)`` as (N, 4) float32 device arrays indexed
    by that index, or None. The arrays are not modified."""
    serial_max = params.serial_max if params.serial_max is not None else SERIAL_MAX
    if 2 <= len(points) <= serial_max:
        built = _serial_build(device, points, photons, params)
        if built is not None:
            return built
    timer = StageTimer(device.queue)
    state = _Build(device, points, photons, params)
    with timer.stage("large"):
        state.large_stage()
    with timer.stage("small"):
        state.small_stage()
    with timer.stage("output"):
        out_nodes, out_info, out_pts, out_ph = state.output_stage()
    stats = {
        "points": state.n, "nodes": state.node_count, "large_levels": state.large_levels,
        "small_levels": state.small_levels, "small_roots": state.n_roots, "radius": state.radius, "ms": timer.ms,
    }
    return _built(out_nodes, out_info, out_pts, out_ph if photons is not None else None, stats)


def _serial_build(device: Device, points: cla.Array, photons: tuple | None, params: BuildParams) -> BuiltTree | None:
    """The build in one launch by one work-group (PointBuild_serial), with
    room for the nodes of a usual tree; None when it needs more (the
    level-by-level build then runs)."""
    timer = StageTimer(device.queue)
    with timer.stage("serial"):
        n, i32, f32 = len(points), np.int32, np.float32
        state = _Build(device, points, photons, params, capacity=int(SERIAL_ROOM * n) + SERIAL_SLACK)
        nodes = state.table.array
        capacity = len(nodes)
        large = n // (SMALL_MAX + 1) + 1  # active large nodes at most: more than SMALL_MAX points each
        bound = large + n // CHUNK_POINTS + 1  # their chunks
        ints = device.array(2 * large + 2 * bound + 5 * n + 3 * capacity, np.int32)
        out_nodes, out_info = device.array(capacity, KDNODE_DTYPE), device.array(capacity, POINT_NODE_DTYPE)
        out_pts = device.array(n * 4, np.float32).reshape(n, 4)
        out_ph = [device.array(n * 4, np.float32).reshape(n, 4) for _ in range(3)]
        result = device.array(8, np.int32)
        radius = -1.0 if params.radius is None else max(float(params.radius), 0.0)
        kernel = device.kernel(PROGRAM, "PointBuild_serial")
        group = params.serial_group or kernel.lone_group(device.is_cpu)
        kernel.groups(1, group, i32(n), i32(large), i32(bound), i32(capacity), f32(params.empty_ratio),
                      state.max_depth, f32(params.k_hint), f32(radius), f32(params.cost_traverse), nodes.data,
                      state.work.data, state.scratch.data, device.array(bound, CHUNK_DTYPE).data,
                      device.array(4 * large, cltypes.int8).data, device.array(4 * large, cltypes.int8).data, ints.data,
                      device.array(large + 2 * bound, cltypes.float4).data,
                      device.array((n // 2 + 1) * 3 * SMALL_MAX, np.uint32).data,
                      device.array(n // 2 + 1, np.float32).data,
                      device.array(SERIAL_BATCHES, cltypes.int4).data, device.array(capacity, BUILD_SUMS_DTYPE).data,
                      state.has_photons, *(p.data for p in state.photons), out_nodes.data, out_info.data,
                      out_pts.data, *(p.data for p in out_ph), result.data)
        status, node_count, large_levels, small_levels, n_roots, radius_bits = device.get(result)[:6]
    if status:
        return None
    if params.radius is None:  # estimated on the device (a given one is kept as given, as _vvh_radius does)
        radius = float(np.int32(radius_bits).view(np.float32))
    stats = {"points": n, "nodes": int(node_count), "large_levels": int(large_levels),
             "small_levels": int(small_levels), "small_roots": int(n_roots), "radius": radius, "ms": timer.ms}
    return _built(out_nodes[:node_count], out_info[:node_count], out_pts, out_ph if photons is not None else None,
                  stats)


def _built(nodes: cla.Array, info: cla.Array, points: cla.Array, photons: list | None, stats: dict) -> BuiltTree:
    """The finished tree of a build's output arrays (photons: power, direction, normal, or None)."""
    power, direction, normal = photons if photons is not None else (None, None, None)
    return BuiltTree(nodes=nodes, info=info, points=points, power=power, direction=direction, normal=normal,
                     node_count=stats["nodes"], radius=stats["radius"], stats=stats)
