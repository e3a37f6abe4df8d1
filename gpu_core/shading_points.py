"""Shading points of the irradiance cache (kernels/gi_points.cl).

Camera rays through a grid of ``subpixels`` x ``subpixels`` positions in
each pixel, followed through mirrors and glass to the first surface with a
diffuse lobe: that surface's position and normal are where irradiance is
interpolated, and ``factor`` turns its irradiance into radiance (throughput
x diffuse albedo / pi); a pixel's radiance is the mean over its points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .device import Device


LOBE_DIFFUSE, LOBE_GLOSSY, LOBE_TRANSMISSION = 0, 1, 2  # kernels/gi_points.cl GI_LOBE_*


@dataclass
class ShadingPoints:
    """First diffuse hits of the camera rays of a render window."""

    positions: np.ndarray  # (N, 3) float32, scene frame of the upload
    normals: np.ndarray  # (N, 3) float32 unit, facing the camera path
    factor: np.ndarray  # (N, 3) float32: pixel radiance per unit irradiance
    lobe: np.ndarray  # (N,) int32: the camera path's first lobe, LOBE_*
    pixels: np.ndarray  # (N, 2) int32 (x, y) inside the window, rows from the bottom
    width: int
    height: int
    subpixels: int  # points per pixel side: up to subpixels^2 points per pixel

    @property
    def pixel_index(self) -> np.ndarray:
        """(N,) index of each point's pixel in the window, row by row."""
        return self.pixels[:, 1] * self.width + self.pixels[:, 0]


GROUP = 64  # work-group size: fixed, so PoCL compiles each kernel once, not per size


def launch_size(n: int) -> tuple[tuple[int], tuple[int]]:
    """Global and local sizes covering ``n`` bound-checked work items."""
    return (-(-n // GROUP) * GROUP,), (GROUP,)


def surface_args(up) -> list:
    """Arguments matching SURFACE_PARAMS in kernels/surface.h, in order."""
    return [up.normals, up.uvs, up.material_ids, up.materials, up.atlas, up.texture_infos]


def trace(device: Device, up, window: tuple[int, int, int, int], max_bounces: int,
          subpixels: int = 2) -> ShadingPoints:
    """Shading points of the pixels in ``window`` = (x0, y0, x1, y1) of the
    full image, for a scene uploaded by the renderer (``up``); pixels
    without a diffuse surface (the world, a light) get no point."""
    x0, y0, x1, y1 = window
    w, h = x1 - x0, y1 - y0
    sub = max(1, int(subpixels))
    n = w * h * sub * sub
    pos, nrm, factor = (np.zeros((n, 4), np.float32) for _ in range(3))
    if n:
        buffers = [device.empty(pos.nbytes) for _ in range(3)]
        program = device.program("gi_points.cl")
        cl.Kernel(program, "GiPoints_trace")(
            device.queue, *launch_size(n), *up.tree.kernel_args(), *surface_args(up), up.camera,
            np.array(window, np.int32), np.int32(sub), np.int32(max_bounces), *buffers,
        )
        for host, buf in zip((pos, nrm, factor), buffers):
            cl.enqueue_copy(device.queue, host, buf)
    valid = pos[:, 3] > 0
    pixel = np.nonzero(valid)[0] // (sub * sub)
    pixels = np.stack([pixel % max(w, 1), pixel // max(w, 1)], axis=1).astype(np.int32)
    return ShadingPoints(
        positions=np.ascontiguousarray(pos[valid, :3]),
        normals=np.ascontiguousarray(nrm[valid, :3]),
        factor=np.ascontiguousarray(factor[valid, :3]),
        lobe=factor[valid, 3].astype(np.int32),
        pixels=pixels,
        width=w,
        height=h,
        subpixels=sub,
    )
