"""k-means clustering of shading points from the seeds (kernels/cache_clusters.cl).

One iteration assigns every shading point to the centre of smallest
``eps``, found exactly through a kd-tree over the centres, then (but
for the last) moves each centre to its members' mean position and
normalised mean normal. Iterations stop at ``max_iterations`` or once at
most ``converge_fraction`` of the points changed cluster. Each cluster's
sample point is its member of smallest ``eps`` to the centre it was
assigned against. A cluster left empty restarts at the point that fits its
own cluster worst (largest ``eps``), and the points are assigned once more,
so every centre keeps a sample unless the points coincide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .cache_kernels import kernel
from .cache_sort import group, zeros
from .device import Device
from .photons import PointTree

_PROGRAM = "cache_clusters.cl"
_RESTART_ROUNDS = 3  # rounds of restarting empty clusters after the iterations


@dataclass
class Clusters:
    """Result of the clustering, read back to the host."""

    cluster_of: np.ndarray  # int32 (N,): centre index of each point
    sample_of: np.ndarray  # int32 (K,): sample point of each centre, -1 if empty
    centre_pos: np.ndarray  # float32 (K, 3), normalised
    centre_nrm: np.ndarray  # float32 (K, 3)
    iterations: int
    changed_fraction: float
    converged: bool
    restarts: int  # empty clusters restarted at another point


def _k(device: Device, name: str) -> cl.Kernel:
    return kernel(device, _PROGRAM, name)


def cluster(device: Device, pos: cl.Buffer, nrm: cl.Buffer, n: int, seeds: cl.Buffer, k: int,
            alpha: float, max_iterations: int, converge_fraction: float) -> Clusters:
    """Cluster ``n`` points (float4 normalised positions/normals) around
    ``k`` seed points (int buffer of point indices)."""
    queue = device.queue
    cpos, cnrm = device.empty(16 * k), device.empty(16 * k)
    _k(device, "Cache_seed_centres")(queue, (k,), None, seeds, np.int32(k), pos, nrm, cpos, cnrm)
    tree = _CentreTree(device, cpos, k)
    clusters = device.empty(4 * n)
    cl.enqueue_fill_buffer(queue, clusters, np.full(1, -1, np.int32), 0, 4 * n)
    update = _k(device, "Cache_update_centres")
    changed = np.zeros(1, np.int32)
    for iterations in range(1, int(max_iterations) + 1):
        counter = zeros(device, 4)
        tree.assign(pos, nrm, n, cpos, cnrm, alpha, clusters, counter)
        cl.enqueue_copy(queue, changed, counter)
        if iterations == max_iterations or changed[0] <= converge_fraction * n:
            break
        members = group(device, clusters, n, k)
        update(queue, (k,), None, members.start, members.end, members.order, pos, nrm, np.int32(k), cpos, cnrm)
    # a cluster left empty restarts at the worst-fitting point of a larger
    # cluster, then every point is assigned once more
    samples, sample_of = device.empty(4 * k), np.empty(k, np.int32)
    restarts = 0
    for attempt in range(_RESTART_ROUNDS + 1):
        members = group(device, clusters, n, k)
        _k(device, "Cache_pick_samples")(queue, (k,), None, members.start, members.end, members.order, pos, nrm,
                                         np.int32(k), cpos, cnrm, np.float32(alpha), samples)
        cl.enqueue_copy(queue, sample_of, samples)
        empty = np.flatnonzero(sample_of < 0).astype(np.int32)
        if not len(empty) or attempt == _RESTART_ROUNDS:
            break
        donors = _restart_points(device, members, pos, nrm, k, cpos, cnrm, alpha)[: len(empty)]
        if not len(donors):
            break  # only coinciding points are left to restart from
        empty = empty[: len(donors)]
        _k(device, "Cache_move_centres")(queue, (len(empty),), None, device.buffer(empty), device.buffer(donors),
                                         np.int32(len(empty)), pos, nrm, cpos, cnrm)
        restarts += len(empty)
        tree.assign(pos, nrm, n, cpos, cnrm, alpha, clusters, zeros(device, 4))
    cluster_of = np.empty(n, np.int32)
    c4, n4 = np.empty((k, 4), np.float32), np.empty((k, 4), np.float32)
    for host, buf in ((cluster_of, clusters), (c4, cpos), (n4, cnrm)):
        cl.enqueue_copy(queue, host, buf)
    fraction = float(changed[0]) / max(n, 1)
    return Clusters(
        cluster_of=cluster_of,
        sample_of=sample_of,
        centre_pos=c4[:, :3].copy(),
        centre_nrm=n4[:, :3].copy(),
        iterations=iterations,
        changed_fraction=fraction,
        converged=changed[0] <= converge_fraction * n,
        restarts=restarts,
    )


class _CentreTree:
    """The point kd-tree over the ``k`` centres, built once where they start
    (the seeds). Before each assignment every node's box is refit to where
    its centres have moved, which keeps the search exact without a rebuild
    per iteration (a build is many small launches, slower than the refit)."""

    def __init__(self, device: Device, cpos: cl.Buffer, k: int):
        start = np.empty((k, 4), np.float32)
        cl.enqueue_copy(device.queue, start, cpos)
        self.device = device
        self.tree = PointTree.build(device, start[:, :3])
        self.boxes = device.empty(32 * self.tree.node_count)  # lo, hi float4 per node

    def assign(self, pos, nrm, n: int, cpos, cnrm, alpha: float, clusters, changed) -> None:
        """Each point joins its centre of smallest eps (Cache_assign);
        ``changed`` counts the points whose cluster changed."""
        queue, tree = self.device.queue, self.tree
        _k(self.device, "Cache_tree_boxes")(queue, (tree.node_count,), None, *tree.kernel_args(),
                                            tree.node_buffer, np.int32(tree.node_count), cpos, self.boxes)
        _k(self.device, "Cache_assign")(queue, (n,), None, pos, nrm, np.int32(n), cpos, cnrm, *tree.kernel_args(),
                                        self.boxes, np.float32(alpha), clusters, changed)


def _restart_points(device: Device, members, pos, nrm, k: int, cpos, cnrm, alpha: float) -> np.ndarray:
    """Points to restart empty clusters from, best first: each cluster's
    member farthest (by eps > 0) from its centre, largest eps first."""
    worst, worst_e = device.empty(4 * k), device.empty(4 * k)
    _k(device, "Cache_worst_members")(device.queue, (k,), None, members.start, members.end, members.order, pos,
                                      nrm, np.int32(k), cpos, cnrm, np.float32(alpha), worst, worst_e)
    idx, err = np.empty(k, np.int32), np.empty(k, np.float32)
    cl.enqueue_copy(device.queue, idx, worst)
    cl.enqueue_copy(device.queue, err, worst_e)
    usable = np.flatnonzero((idx >= 0) & (err > 0.0))
    usable = usable[np.lexsort((idx[usable], -err[usable]))]
    return idx[usable].astype(np.int32)
