"""Adaptive seeding over a screen-space quadtree (seeding.cl).

The quadtree covers the image in square cells; its leaves are single pixels
(or 2x2, 4x4, ... pixel blocks on images over a million pixels). Level ``l``
is a dense ``dims[l]`` grid of nodes, level 0 the root. Per node the device
computes the mean position and normal of its shading points and the mean
of their errors ``eps`` to that mean; ``count`` seeds are then handed down
from the root in proportion to error, never more than a node's points, and
each leaf's seeds are its points closest (by ``eps``) to the leaf mean.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from ...device.primitives import Groups, exclusive_scan_total, group
from ...device import Device

_PROGRAM = "gi/cache/seeding.cl"
_MAX_LEAF_CELLS = 1 << 20  # leaves grow past one pixel above this


@dataclass
class Level:
    """Device arrays of one quadtree level (nodes row-major, ``dims`` = (w, h))."""

    dims: tuple[int, int]
    psum: cl.Buffer  # float4: summed normalised positions
    nsum: cl.Buffer  # float4: summed normals
    count: cl.Buffer  # int: shading points
    # float rows of ``size``: row r the summed eps of the node's points to
    # the mean of its ancestor r levels up (row 0: its own; rows 0 to the level's index)
    err: cl.Buffer
    budget: cl.Buffer  # int: seeds handed to the node

    @property
    def size(self) -> int:
        return self.dims[0] * self.dims[1]


@dataclass
class QuadTree:
    """The levels (root first) and the points grouped by leaf cell."""

    levels: list[Level]
    leaves: Groups
    leaf_shift: int  # a leaf covers 2**leaf_shift pixels on a side
    ms: dict = field(default_factory=dict)


def _k(device: Device, name: str):
    return device.kernel(_PROGRAM, name)


def _dims2(dims: tuple[int, int]) -> np.ndarray:
    return np.array(dims, np.int32)


def level_dims(width: int, height: int) -> tuple[int, list[tuple[int, int]]]:
    """Leaf shift and each level's node grid, root first."""
    shift = 0
    while ((width + (1 << shift) - 1) >> shift) * ((height + (1 << shift) - 1) >> shift) > _MAX_LEAF_CELLS:
        shift += 1
    leaf_w = (width + (1 << shift) - 1) >> shift
    leaf_h = (height + (1 << shift) - 1) >> shift
    depth = max(max(leaf_w, leaf_h) - 1, 0).bit_length()
    dims = [(-(-leaf_w // (1 << (depth - l))), -(-leaf_h // (1 << (depth - l)))) for l in range(depth + 1)]
    return shift, dims


def build(device: Device, pos: cl.Buffer, nrm: cl.Buffer, pixels: cl.Buffer, n: int,
          width: int, height: int, alpha: float) -> QuadTree:
    """Node sums, counts and errors of every level for ``n`` shading points
    (float4 normalised positions and normals, int2 pixels)."""
    shift, dims = level_dims(width, height)
    depth = len(dims) - 1
    levels = [
        Level(d, device.empty(16 * d[0] * d[1]), device.empty(16 * d[0] * d[1]), device.empty(4 * d[0] * d[1]),
              device.empty(4 * (l + 1) * d[0] * d[1]), device.zeros(4 * d[0] * d[1]))
        for l, d in enumerate(dims)
    ]
    leaf = levels[-1]
    # group the points by leaf cell
    keys = device.empty(4 * n)
    _k(device, "Cache_leaf_keys")(n, pixels, np.int32(n), np.int32(shift),
                                  np.int32(leaf.dims[0]), keys)
    leaves = group(device, keys, n, leaf.size)
    members = (leaves.start, leaves.end, leaves.order, pos, nrm)
    # sums and means, leaves first, then each parent from its children (the
    # means of every level in one array, root first)
    firsts = np.concatenate(([0], np.cumsum([lv.size for lv in levels]))).astype(np.int32)
    means = device.empty(32 * int(firsts[-1]))
    _k(device, "Cache_leaf_sums")(leaf.size, *members, np.int32(leaf.size),
                                  leaf.psum, leaf.nsum, leaf.count, means, firsts[depth])
    pyramid = _k(device, "Cache_pyramid_sums")
    for l in range(depth - 1, -1, -1):
        parent, child = levels[l], levels[l + 1]
        pyramid(parent.size, child.psum, child.nsum, child.count, _dims2(child.dims),
                parent.psum, parent.nsum, parent.count, _dims2(parent.dims), means, firsts[l])
    # errors: each leaf's points against every ancestor's mean in one pass,
    # then summed upwards level by level, every ancestor's row at once
    _k(device, "Cache_leaf_errors")(leaf.size, *members, _dims2(leaf.dims), np.int32(depth), means,
                                    np.float32(alpha), leaf.err)
    pyramid_errors = _k(device, "Cache_pyramid_errors")
    for l in range(depth - 1, -1, -1):
        parent, child = levels[l], levels[l + 1]
        pyramid_errors(parent.size, child.err, _dims2(child.dims), parent.err, _dims2(parent.dims), np.int32(l + 1))
    return QuadTree(levels=levels, leaves=leaves, leaf_shift=shift)


def seed(device: Device, tree: QuadTree, pos: cl.Buffer, nrm: cl.Buffer, count: int, alpha: float,
         rng_seed: int) -> tuple[cl.Buffer, int]:
    """Hand ``count`` seeds down the tree; returns the seeds' point indices
    (int buffer) and how many there are (``count`` capped by the points)."""
    root = tree.levels[0]
    root_count = int(device.scalar(root.count))
    device.write(root.budget, np.array([min(int(count), root_count)], np.int32))
    distribute = _k(device, "Cache_distribute")
    for l, (parent, child) in enumerate(zip(tree.levels[:-1], tree.levels[1:])):
        distribute(parent.size, parent.budget, _dims2(parent.dims), child.count, child.err,
                   _dims2(child.dims), child.budget, np.uint32(rng_seed & 0xFFFFFFFF), np.int32(l))
    leaf = tree.levels[-1]
    offsets = device.empty(4 * leaf.size)
    device.copy(offsets, leaf.budget, 4 * leaf.size)
    total = exclusive_scan_total(device, offsets, leaf.size)
    seeds = device.empty(4 * total)
    if total:
        lv = tree.leaves
        _k(device, "Cache_leaf_seeds")(leaf.size, lv.start, lv.end, lv.order, pos, nrm,
                                       leaf.psum, leaf.nsum, leaf.count, leaf.budget, offsets,
                                       np.int32(leaf.size), np.float32(alpha), seeds)
    return seeds, total


def read(device: Device, tree: QuadTree) -> list[dict]:
    """Per level, root first: ``count``, normalised ``mean`` position, unit
    mean ``normal``, mean ``error`` (0 for empty nodes) and seed ``budget``,
    each shaped ``(h, w, ...)``."""
    out = []
    for lv in tree.levels:
        w, h = lv.dims
        psum, nsum = np.empty((h, w, 4), np.float32), np.empty((h, w, 4), np.float32)
        count, err, budget = np.empty((h, w), np.int32), np.empty((h, w), np.float32), np.empty((h, w), np.int32)
        for host, buf in ((psum, lv.psum), (nsum, lv.nsum), (count, lv.count), (err, lv.err), (budget, lv.budget)):
            device.to_host(buf, host)
        safe = np.maximum(count, 1)[..., None]
        length = np.linalg.norm(nsum[..., :3], axis=-1, keepdims=True)
        out.append({
            "count": count,
            "mean": psum[..., :3] / safe,
            "normal": np.where(length > 1e-12, nsum[..., :3] / np.maximum(length, 1e-30), 0.0),
            "error": err / safe[..., 0],
            "budget": budget,
        })
    return out
