"""Overlay trees: moving an object rebuilds a kd-tree of its triangles only.

A tree built over all triangles (the base) stays on the device while the
triangles that moved since are gathered into a small tree of their own (the
overlay), and the two are joined under a union root (kdtree_overlay.cl):
traversal visits both subtrees, skips the base's entries of moved
triangles, and finds every hit a tree built afresh would find. While an
object is dragged, each move rebuilds only the overlay of the triangles
that differ from the base's; once too many have moved (``OVERLAY_SHARE``),
the plan builds the whole tree again.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..device import Device, primitives
from ..device.constants import KD_MAX_DEPTH
from ..device.layout import KDNODE_DTYPE, rows_differ
from ..device.timer import StageTimer
from . import kdtree_blocks
from .kdtree import KdTree, build
from .kdtree_build import depth_limit

PROGRAM = "accel/kdtree_overlay.cl"
OVERLAY_SHARE = 0.25  # most triangles an overlay holds, as a share of the scene's


def programs() -> list[tuple[str, dict]]:
    """The programs joining the trees and making the joined tree's blocks
    (the overlay's own build needs kdtree_build's)."""
    return [(PROGRAM, {}), *kdtree_blocks.programs()]


def moved_rows(base_triangles: np.ndarray | None, triangles: np.ndarray) -> np.ndarray | None:
    """Indices of the triangles that differ from the base tree's, when an
    overlay tree over them will do; None when the whole tree must be built
    (no base, another triangle count, too many moved, or a base too deep
    to sit under a union root)."""
    count = len(triangles)
    if (base_triangles is None or base_triangles.shape != triangles.shape or base_triangles.dtype != triangles.dtype
            or count == 0):
        return None
    if depth_limit(count) >= KD_MAX_DEPTH:
        return None
    rows = np.flatnonzero(rows_differ(triangles, base_triangles)).astype(np.int32)
    return rows if len(rows) <= OVERLAY_SHARE * count else None


def overlay(device: Device, base: KdTree, rows: np.ndarray, moved_triangles: np.ndarray,
            should_stop: Callable[[], bool] | None = None) -> KdTree:
    """The base tree joined with a tree over the triangles ``rows``, which
    moved to ``moved_triangles`` (``(len(rows), 3, 3)`` float32; the others
    are where the base has them). With no rows, the base itself."""
    if len(rows) == 0:
        return base
    rows = np.asarray(rows, np.int32)
    count = base.triangle_count
    timer = StageTimer()
    over = build(device, np.asarray(moved_triangles, np.float32).reshape(-1, 3, 3), should_stop, blocks=False)
    with timer.stage("join"):
        # the corners now: the base's, the moved triangles' written over them on the device
        verts = device.array(3 * count, base.verts.dtype)
        device.copy(verts.data, base.verts.data, base.verts.nbytes)
        corners = (3 * rows[:, None] + np.arange(3, dtype=np.int32)).ravel()
        primitives.scatter_rows(device, over.verts.data, device.to_device(corners), len(corners), verts.data)
        nb, no = int(base.stats["nodes"]), int(over.stats["nodes"])
        base_refs, over_refs = int(base.stats["leaf_references"]), int(over.stats["leaf_references"])
        moved = np.zeros(count, np.uint8)
        moved[rows] = 1
        nodes = device.array(1 + nb + no, KDNODE_DTYPE)
        leaf_tris = device.array(base_refs + over_refs, np.int32)
        device.kernel(PROGRAM, "KdOverlay_nodes")(
            1 + nb + no, base.nodes.data, np.int32(nb), over.nodes.data, np.int32(no), np.int32(base_refs),
            nodes.data)
        device.kernel(PROGRAM, "KdOverlay_leaves")(
            base_refs + over_refs, base.leaf_tris.data, np.int32(base_refs), device.to_device(moved),
            over.leaf_tris.data, device.to_device(rows), np.int32(over_refs), leaf_tris.data)
        blocks = kdtree_blocks.make(device, nodes, leaf_tris, verts, 1 + nb + no) if base.blocks is not None else None
    stats = dict(base.stats)
    stats.update(nodes=1 + nb + no, leaf_references=base_refs + over_refs, blocks=kdtree_blocks.count(blocks),
                 overlay_triangles=len(rows),
                 overlay_nodes=no, depth=max(base.stats["depth"], over.stats["depth"]) + 1,
                 ms={"overlay_build": over.stats["ms"]["total"], "join": timer.ms["join"]})
    stats["ms"]["total"] = stats["ms"]["overlay_build"] + stats["ms"]["join"]
    return KdTree(device=device, nodes=nodes, leaf_tris=leaf_tris, verts=verts,
                  bmin=np.minimum(base.bmin, over.bmin), bmax=np.maximum(base.bmax, over.bmax),
                  triangle_count=count, stats=stats, base=base, blocks=blocks)
