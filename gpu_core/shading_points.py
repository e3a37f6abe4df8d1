"""Shading points of the irradiance cache (kernels/gi_points.cl).

Camera rays through a grid of ``subpixels`` x ``subpixels`` positions in
each pixel, followed through mirrors and glass to the first surface with a
diffuse lobe: irradiance is interpolated at those surfaces' positions and
normals, and the image kernel reads it back at its own camera paths' first
diffuse hits (render.cl, RENDER_GI).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .device import Device

GROUP = 64  # work-group size: fixed, so PoCL compiles each kernel once, not per size


def launch_size(n: int) -> tuple[tuple[int], tuple[int]]:
    """Global and local sizes covering ``n`` bound-checked work items."""
    return (-(-n // GROUP) * GROUP,), (GROUP,)


def surface_args(up) -> list:
    """Arguments matching SURFACE_PARAMS in kernels/surface.h, in order."""
    return [up.normals, up.uvs, up.material_ids, up.materials, up.atlas, up.texture_infos]


@dataclass
class ShadingPoints:
    """First diffuse hits of the camera rays of a render window."""

    positions: np.ndarray  # (N, 3) float32, scene frame of the upload
    normals: np.ndarray  # (N, 3) float32 unit, facing the camera path
    slots: np.ndarray  # (N,) int: place in the grid, pixel * subpixels^2 + sub-position
    width: int
    height: int
    subpixels: int  # points per pixel side: up to subpixels^2 points per pixel

    @property
    def grid_size(self) -> int:
        """Slots of the whole grid, points or not."""
        return self.width * self.height * self.subpixels**2

    @property
    def pixels(self) -> np.ndarray:
        """(N, 2) int32 (x, y) of each point's pixel in the window, rows from the bottom."""
        pixel = self.slots // self.subpixels**2
        return np.stack([pixel % max(self.width, 1), pixel // max(self.width, 1)], axis=1).astype(np.int32)


def trace(device: Device, up, window: tuple[int, int, int, int], max_bounces: int,
          subpixels: int = 2) -> ShadingPoints:
    """Shading points of the pixels in ``window`` = (x0, y0, x1, y1) of the
    full image, for a scene uploaded by the renderer (``up``); rays that
    reach no diffuse surface (the world, a light) give no point."""
    x0, y0, x1, y1 = window
    w, h = x1 - x0, y1 - y0
    sub = max(1, int(subpixels))
    n = w * h * sub * sub
    pos, nrm = np.zeros((n, 4), np.float32), np.zeros((n, 4), np.float32)
    if n:
        buffers = [device.empty(pos.nbytes) for _ in range(2)]
        program = device.program("gi_points.cl")
        cl.Kernel(program, "GiPoints_trace")(
            device.queue, *launch_size(n), *up.tree.kernel_args(), *surface_args(up), up.camera,
            np.array(window, np.int32), np.int32(sub), np.int32(max_bounces), *buffers,
        )
        for host, buf in zip((pos, nrm), buffers):
            cl.enqueue_copy(device.queue, host, buf)
    valid = pos[:, 3] > 0
    return ShadingPoints(
        positions=np.ascontiguousarray(pos[valid, :3]),
        normals=np.ascontiguousarray(nrm[valid, :3]),
        slots=np.nonzero(valid)[0],
        width=w,
        height=h,
        subpixels=sub,
    )
