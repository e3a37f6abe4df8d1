"""Leaf blocks of a triangle kd-tree (kdtree_blocks.cl): each leaf's
triangles laid out four to a block, coordinate by coordinate, so that
traversal tests a leaf's triangles four at a time with the same arithmetic
as one at a time (the same hits). Measured on a CPU device, where OpenCL's
float4 is one SIMD register (README, "Leaf blocks"); other devices keep
the one-at-a-time test, which was not measured against blocks there.
"""

from __future__ import annotations

import numpy as np
import pyopencl.array as cla

from ..device import Device, primitives
from ..device.constants import KD_BLOCK_ROWS

PROGRAM = "accel/kdtree_blocks.cl"
BLOCK_BYTES = KD_BLOCK_ROWS * 16
MAX_BYTES = 256 << 20  # largest block array made; a tree that needs more keeps the one-at-a-time test


def programs() -> list[tuple[str, dict]]:
    """The program making blocks (for building it up front)."""
    return [(PROGRAM, {})]


def wanted(device: Device) -> bool:
    """Whether trees get blocks on ``device``: on CPU devices."""
    return device.is_cpu


def make(device: Device, nodes: cla.Array, leaf_tris: cla.Array, verts: cla.Array, node_count: int) -> cla.Array | None:
    """The blocks of a tree's ``node_count`` nodes, each leaf's first block
    written into its split; None (the nodes untouched) where no leaf holds a
    triangle or they would take more than MAX_BYTES (or one buffer can)."""
    if node_count <= 0:
        return None
    first = device.array(node_count, np.int32)
    device.kernel(PROGRAM, "KdBlocks_count")(node_count, nodes.data, np.int32(node_count), first.data)
    total = primitives.exclusive_scan_total(device, first.data, node_count)
    if total == 0 or total * BLOCK_BYTES > min(MAX_BYTES, device.max_alloc_bytes):
        return None
    blocks = device.array(total * KD_BLOCK_ROWS * 4, np.float32)
    device.kernel(PROGRAM, "KdBlocks_fill")(node_count, nodes.data, first.data, leaf_tris.data, verts.data,
                                             np.int32(node_count), blocks.data)
    return blocks


def count(blocks: cla.Array | None) -> int:
    """Blocks in a block array (0 for None)."""
    return 0 if blocks is None else len(blocks) // (KD_BLOCK_ROWS * 4)
