"""Lone outlier cache samples (outliers.cl).

A few gather rays that hit a small, very bright spot (a focused caustic)
make one sample far brighter than its neighbours, and interpolation would
spread it into a blotch on the wall. Each sample's irradiance is brought
down to OUTLIER_RATIO times the median of its OUTLIER_NEIGHBOURS nearest
samples' (luminance); where the neighbours see the light too, nothing
changes.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ...accel.point_tree import PointTree
from ...device import Device, primitives

OUTLIER_NEIGHBOURS = 8  # samples a cache sample is compared with
OUTLIER_RATIO = 4.0  # largest irradiance of a sample over its neighbours' median
_PROGRAM = "gi/cache/outliers.cl"
_DEFINES = {"KNN_K": OUTLIER_NEIGHBOURS + 1, "OUTLIER_RATIO": f"{OUTLIER_RATIO!r}f"}


def programs() -> list[tuple[str, dict]]:
    return [(_PROGRAM, _DEFINES)]


def clamp_outliers(device: Device, positions: cl.Buffer, irradiance: cl.Buffer, m: int) -> tuple[cl.Buffer, int]:
    """The ``m`` samples' irradiance (float4) with lone outliers brought
    down, and how many were; ``positions`` are float4."""
    if m <= OUTLIER_NEIGHBOURS:
        return irradiance, 0
    tree = PointTree.from_device(device, primitives.indexed_points(device, positions, m))
    out, clamped = device.empty(16 * m), device.zeros(4)
    device.kernel(_PROGRAM, "Outliers_clamp", _DEFINES)(m, *tree.kernel_args(), positions, irradiance, np.int32(m),
                                                        out, clamped)
    return out, int(device.scalar(clamped))
