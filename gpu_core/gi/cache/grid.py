"""Uniform grid over points on the device (grid.cl).

Used where the irradiance cache needs the exact nearest of a few thousand
points under a metric bounded below by a multiple of distance: the
interpolation fallback. The kernels visit cells in growing
rings (cache.h) and stop once no unvisited cell can hold a better
point, so the answer equals a brute-force search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ...device.primitives import Groups, group
from ...device import Device

_MAX_DIM = 1024  # cells along one axis


@dataclass
class Grid:
    """Cell geometry plus the points grouped by cell."""

    origin: np.ndarray  # float32 (4,): xyz lower corner, w = cell size
    dims: np.ndarray  # int32 (4,): cells along x, y, z (w unused)
    groups: Groups

    def kernel_args(self) -> list:
        """Arguments matching CACHE_GRID_PARAMS in cache.h, in order."""
        return [self.origin, self.dims, self.groups.start, self.groups.end, self.groups.order]


def cell_shape(lo: np.ndarray, hi: np.ndarray, target_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Origin (w = cell size) and dims of cubic cells over the box, about
    ``target_cells`` of them; flat boxes get one cell across their thin axis."""
    lo = np.asarray(lo, np.float64)
    extent = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    size = max(float(extent.max()), 1e-6)
    target = max(int(target_cells), 1)

    def cells(h: float) -> np.ndarray:
        return np.clip(np.ceil(extent / h), 1, _MAX_DIM)

    low, high = size / _MAX_DIM, size  # cell-size bracket: many cells .. one cell
    for _ in range(40):
        mid = np.sqrt(low * high)
        if np.prod(cells(mid)) > target:
            low = mid
        else:
            high = mid
    h = high * (1.0 + 1e-5)  # the far faces stay inside the last cell
    dims = cells(h).astype(np.int32)
    origin = np.append(lo, h).astype(np.float32)
    return origin, np.append(dims, 0).astype(np.int32)


def build(device: Device, points: cl.Buffer, n: int, lo, hi, target_cells: int) -> Grid:
    """Group ``n`` float4 ``points`` (inside the box lo..hi) by grid cell."""
    origin, dims = cell_shape(lo, hi, target_cells)
    total = int(np.prod(dims[:3]))
    keys = device.empty(4 * n)
    device.kernel("gi/cache/grid.cl", "Cache_grid_keys")(n, points, np.int32(n), origin, dims, keys)
    return Grid(origin=origin, dims=dims, groups=group(device, keys, n, total))
