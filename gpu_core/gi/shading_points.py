"""Shading points of the irradiance cache (shading_points.cl).

Camera rays through a grid of ``subpixels`` x ``subpixels`` positions in
each pixel, followed through mirrors and glass to the first surface with a
diffuse lobe. The grid stays on the device (the image kernel reads the GI
cache through it), and the slots that found a surface are compacted on the
device into the list of points the cache works on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ..device import Device, primitives
from ..scene.upload import SceneBuffers
from .points import DevicePoints

_PROGRAM = "gi/shading_points.cl"


def programs(scene_defines: dict) -> list[tuple[str, dict]]:
    """The programs this stage builds."""
    return [(_PROGRAM, scene_defines)]


@dataclass
class ShadingPoints(DevicePoints):
    """First diffuse hits of the camera rays of a render window, on the device."""

    device: Device
    grid_pos: cl.Buffer  # float4 per grid slot: xyz, w = 1 where a surface was found
    grid_nrm: cl.Buffer  # float4 per grid slot
    pos: cl.Buffer  # float4 per point (the slots with a surface, in slot order)
    nrm: cl.Buffer  # float4 per point, unit, facing the camera path
    pixel: cl.Buffer  # int2 per point: (x, y) in the window, rows from the bottom
    slot: cl.Buffer  # int per point: its grid slot, pixel * subpixels^2 + sub-position
    count: int
    width: int
    height: int
    subpixels: int  # points per pixel side: up to subpixels^2 points per pixel

    @property
    def grid_size(self) -> int:
        """Slots of the whole grid, points or not."""
        return self.width * self.height * self.subpixels**2

    def scatter(self, values: cl.Buffer) -> cl.Buffer:
        """A grid of float4 holding each point's value (``values``, float4 per
        point) in its slot and zero elsewhere."""
        grid = self.device.zeros(16 * self.grid_size)
        self.device.kernel(_PROGRAM, "ShadingPoints_scatter")(self.count, values, self.slot, np.int32(self.count), grid)
        return grid


def subset(points: ShadingPoints, index: cl.Buffer, count: int) -> ShadingPoints:
    """The points ``index`` (int per point, ``count`` of them) of ``points``,
    on the same grid (their slots and pixels kept)."""
    device = points.device
    slot = primitives.gather_ints(device, points.slot, index, count)
    pixel = device.empty(8 * max(count, 1))
    device.kernel(_PROGRAM, "ShadingPoints_pixels")(count, slot, np.int32(count), np.int32(points.width),
                                                    np.int32(points.subpixels**2), pixel)
    return ShadingPoints(device, points.grid_pos, points.grid_nrm, primitives.gather_rows(device, points.pos, index, count),
                         primitives.gather_rows(device, points.nrm, index, count), pixel, slot, count, points.width,
                         points.height, points.subpixels)


def trace(device: Device, buffers: SceneBuffers, window: tuple[int, int, int, int], max_bounces: int,
          subpixels: int = 2, scene_defines: dict | None = None) -> ShadingPoints:
    """Shading points of the pixels in ``window`` = (x0, y0, x1, y1) of the
    full image; rays that reach no diffuse surface (the world, a light) give
    no point. ``scene_defines``: the scene's program features (plan)."""
    x0, y0, x1, y1 = window
    w, h = x1 - x0, y1 - y0
    sub = max(1, int(subpixels))
    n = w * h * sub * sub
    grid_pos, grid_nrm = device.empty(16 * n), device.empty(16 * n)
    device.kernel(_PROGRAM, "ShadingPoints_trace", scene_defines)(
        n, *buffers.kernel_args(), np.array(window, np.int32), np.int32(sub), np.int32(max_bounces), grid_pos, grid_nrm)
    slot, count = _slots_with_points(device, grid_pos, n)
    pos, nrm = primitives.gather_rows(device, grid_pos, slot, count), primitives.gather_rows(device, grid_nrm, slot, count)
    pixel = device.empty(8 * count)
    device.kernel(_PROGRAM, "ShadingPoints_pixels")(count, slot, np.int32(count), np.int32(w), np.int32(sub * sub), pixel)
    return ShadingPoints(device, grid_pos, grid_nrm, pos, nrm, pixel, slot, count, w, h, sub)


def _slots_with_points(device: Device, grid_pos: cl.Buffer, n: int) -> tuple[cl.Buffer, int]:
    """The slots that found a surface, in slot order, and how many."""
    flags = device.empty(4 * n)
    device.kernel(_PROGRAM, "ShadingPoints_found")(n, grid_pos, np.int32(n), flags)
    return primitives.compact(device, flags, n)
