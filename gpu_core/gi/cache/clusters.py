"""k-means clustering of shading points from the seeds (clusters.cl).

One iteration assigns every shading point to the centre of smallest
``eps``, found exactly through a kd-tree over the centres (refit to the
moved centres, or built again once the refit one costs more), then (but
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

from ...device import primitives
from ...device.primitives import group
from ...device import Device
from ...accel.point_tree import PointTree

_PROGRAM = "gi/cache/clusters.cl"
_RESTART_ROUNDS = 3  # rounds of restarting empty clusters after the iterations


@dataclass
class Clusters:
    """Result of the clustering: device buffers, and each centre's sample on the host."""

    cluster_of: cl.Buffer  # int (N,): centre index of each point
    sample_of: np.ndarray  # int32 (K,): sample point of each centre, -1 if empty
    centre_pos: cl.Buffer  # float4 (K,), normalised
    centre_nrm: cl.Buffer  # float4 (K,)
    iterations: int
    changed_fraction: float
    converged: bool
    restarts: int  # empty clusters restarted at another point


def _k(device: Device, name: str):
    return device.kernel(_PROGRAM, name)


def seed_centres(device: Device, pos: cl.Buffer, nrm: cl.Buffer, seeds: cl.Buffer, k: int) -> tuple:
    """New (positions, normals) float4 buffers of ``k`` centres at the seed
    points (int buffer of indices into ``pos`` and ``nrm``)."""
    cpos, cnrm = device.empty(16 * k), device.empty(16 * k)
    _k(device, "Cache_seed_centres")(k, seeds, np.int32(k), pos, nrm, cpos, cnrm)
    return cpos, cnrm


def cluster(device: Device, pos: cl.Buffer, nrm: cl.Buffer, n: int, centres: tuple, k: int,
            alpha: float, max_iterations: int, converge_fraction: float) -> Clusters:
    """Cluster ``n`` points (float4 normalised positions/normals) around
    ``k`` starting centres (float4 positions and normals in the points'
    frame; the buffers are moved with the centres)."""
    cpos, cnrm = centres
    tree = _CentreTree(device, cpos, k)
    clusters = device.empty(4 * n)
    device.fill(clusters, -1, 4 * n)
    update = _k(device, "Cache_update_centres")
    counts, fresh_work = np.zeros(2, np.int32), None
    for iterations in range(1, int(max_iterations) + 1):
        counter = device.zeros(8)
        tree.assign(pos, nrm, n, cpos, cnrm, alpha, clusters, counter)
        device.to_host(counter, counts)
        changed, work = int(counts[0]), int(counts[1])
        if iterations == max_iterations or changed <= converge_fraction * n:
            break
        members = group(device, clusters, n, k)
        update(k, members.start, members.end, members.order, pos, nrm, np.int32(k), cpos, cnrm)
        fresh_work = work if fresh_work is None else fresh_work
        if _needs_new_tree(work, fresh_work):
            tree, fresh_work = _CentreTree(device, cpos, k), None
    # a cluster left empty restarts at the worst-fitting point of a larger
    # cluster, then every point is assigned once more
    samples, sample_of = device.empty(4 * k), np.empty(k, np.int32)
    restarts = 0
    for attempt in range(_RESTART_ROUNDS + 1):
        members = group(device, clusters, n, k)
        _k(device, "Cache_pick_samples")(k, members.start, members.end, members.order, pos, nrm,
                                         np.int32(k), cpos, cnrm, np.float32(alpha), samples)
        device.to_host(samples, sample_of)
        empty = np.flatnonzero(sample_of < 0).astype(np.int32)
        if not len(empty) or attempt == _RESTART_ROUNDS:
            break
        donors = _restart_points(device, members, pos, nrm, k, cpos, cnrm, alpha)[: len(empty)]
        if not len(donors):
            break  # only coinciding points are left to restart from
        empty = empty[: len(donors)]
        _k(device, "Cache_move_centres")(len(empty), device.to_device(empty), device.to_device(donors),
                                         np.int32(len(empty)), pos, nrm, cpos, cnrm)
        restarts += len(empty)
        tree.assign(pos, nrm, n, cpos, cnrm, alpha, clusters, device.zeros(8))
    fraction = float(changed) / max(n, 1)
    return Clusters(
        cluster_of=clusters,
        sample_of=sample_of,
        centre_pos=cpos,
        centre_nrm=cnrm,
        iterations=iterations,
        changed_fraction=fraction,
        converged=changed <= converge_fraction * n,
        restarts=restarts,
    )


def _needs_new_tree(work: int, fresh_work: int) -> bool:
    """Whether to build the centres' tree again: its boxes are refit to the
    moved centres, and once a search through them evaluates more centres
    (``work``) than one through the tree when fresh did, a new tree costs
    less than the searches it saves."""
    return work > fresh_work


class _CentreTree:
    """The point kd-tree over the ``k`` centres, built where they start
    (the seeds). Before each assignment every node's box is refit to where
    its centres have moved, which keeps the search exact without a rebuild;
    ``cluster`` builds a new one when the refit boxes have grown so loose
    that a search evaluates more centres than it did through the fresh tree
    (where the centres' moves mix surfaces, as in the large scene: each
    assignment then 230-270 -> 150-170 ms at 640x360)."""

    def __init__(self, device: Device, cpos: cl.Buffer, k: int):
        self.device = device
        self.tree = PointTree.from_device(device, primitives.indexed_points(device, cpos, k))
        self.boxes = device.empty(32 * self.tree.node_count)  # lo, hi float4 per node

    def assign(self, pos, nrm, n: int, cpos, cnrm, alpha: float, clusters, counts) -> None:
        """Each point joins its centre of smallest eps (Cache_assign);
        ``counts`` (two ints) counts the points whose cluster changed and
        the centres a sample of the points evaluated."""
        tree = self.tree
        _k(self.device, "Cache_tree_boxes")(tree.node_count, *tree.kernel_args(),
                                            tree.node_buffer, np.int32(tree.node_count), cpos, self.boxes)
        _k(self.device, "Cache_assign")(n, pos, nrm, np.int32(n), cpos, cnrm, *tree.kernel_args(),
                                        self.boxes, np.float32(alpha), clusters, counts)


def _restart_points(device: Device, members, pos, nrm, k: int, cpos, cnrm, alpha: float) -> np.ndarray:
    """Points to restart empty clusters from, best first: each cluster's
    member farthest (by eps > 0) from its centre, largest eps first."""
    worst, worst_e = device.empty(4 * k), device.empty(4 * k)
    _k(device, "Cache_worst_members")(k, members.start, members.end, members.order, pos,
                                      nrm, np.int32(k), cpos, cnrm, np.float32(alpha), worst, worst_e)
    idx, err = np.empty(k, np.int32), np.empty(k, np.float32)
    device.to_host(worst, idx)
    device.to_host(worst_e, err)
    usable = np.flatnonzero((idx >= 0) & (err > 0.0))
    usable = usable[np.lexsort((idx[usable], -err[usable]))]
    return idx[usable].astype(np.int32)
