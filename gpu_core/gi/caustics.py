"""Caustics seen directly (caustics.cl): the caustic map's density estimate
on the shading points' grid.

A k-photon estimate changes little over a small fraction of its radius
(its photons stay the same), and where caustic photons are sparse that
radius spans many pixels. So the pixels ANCHOR_SPACING apart in rows and
columns (anchors, a sixteenth of the grid) are estimated first; then each
lattice half as far apart takes, in its new slots, the mean of the slots
beside them on the lattice before where those lie on the slot's surface
within SPAN times their radius, and its own estimate elsewhere (a sharp
caustic, an edge, a silhouette). Measured: half the stage's time on the
demo scenes, the image within 0.07% RMS of every slot estimated (README,
"Caustics seen directly").
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..accel.point_tree import DENSITY_FILTER, DENSITY_NORMAL_COS, FILTERS, PointTree, query_defines, search_d2
from .cut import caustic_max_radius
from .shading_points import ShadingPoints

_PROGRAM = "gi/caustics.cl"
ANCHOR_SPACING = 4  # pixels between the anchors estimated first (a power of two)
SPAN = 0.2  # anchors within this fraction of their estimate's radius stand in for the slots between them
SAME_SURFACE_COS = 0.95  # anchors whose normal is within acos(this) of the slot's lie on its surface


def programs(k: int) -> list[tuple[str, dict]]:
    """The program this stage builds for estimates of ``k`` photons."""
    return [(_PROGRAM, query_defines(k))]


def irradiance(caustic_map: PointTree, points: ShadingPoints, k: int) -> cl.Buffer:
    """A grid of float4 (points' slots) holding the caustic irradiance (rgb)
    of the ``k``-photon estimates at ``points``; zero in slots without one."""
    device = points.device
    sub2, width, height = points.subpixels**2, points.width, points.height
    grid = device.empty(16 * points.grid_size)
    max_d2 = search_d2(caustic_max_radius(caustic_map))
    common = (*caustic_map.kernel_args(), *caustic_map.photon_args(), points.grid_pos, points.grid_nrm,
              np.int32(width), np.int32(height), np.int32(sub2), max_d2, np.int32(k), np.int32(FILTERS[DENSITY_FILTER]),
              np.float32(DENSITY_NORMAL_COS))
    spacing = ANCHOR_SPACING

    def lattice(apart: int) -> int:  # the slots of the pixels `apart` apart in rows and columns
        return -(-width // apart) * -(-height // apart) * sub2

    device.kernel(_PROGRAM, "Caustics_anchors", query_defines(k))(lattice(spacing), *common, np.int32(spacing), grid)
    while spacing > 1:  # each level fills the lattice half as far apart from the one before
        device.kernel(_PROGRAM, "Caustics_fill", query_defines(k))(
            lattice(spacing // 2), *common, np.int32(spacing), np.float32(SPAN), np.float32(SAME_SURFACE_COS), grid)
        spacing //= 2
    return grid
