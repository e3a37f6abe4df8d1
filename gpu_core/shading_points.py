"""Shading points of the irradiance cache (kernels/gi_points.cl).

One camera ray per pixel through its centre, followed through mirrors and
glass to the first surface with a diffuse lobe: that surface's position and
normal are where irradiance is interpolated, and ``factor`` turns its
irradiance into the pixel's radiance (throughput x diffuse albedo / pi).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .device import Device


LOBE_DIFFUSE, LOBE_GLOSSY, LOBE_TRANSMISSION = 0, 1, 2  # kernels/gi_points.cl GI_LOBE_*


@dataclass
class ShadingPoints:
    """Per-pixel first diffuse hits of a render window, rows from the bottom."""

    positions: np.ndarray  # (N, 3) float32, scene frame of the upload
    normals: np.ndarray  # (N, 3) float32 unit, facing the camera path
    factor: np.ndarray  # (N, 3) float32: pixel radiance per unit irradiance
    lobe: np.ndarray  # (N,) int32: the camera path's first lobe, LOBE_*
    pixels: np.ndarray  # (N, 2) int32 (x, y) inside the window
    valid: np.ndarray  # (W*H,) bool: which pixels of the window have a point
    width: int
    height: int


GROUP = 64  # work-group size: fixed, so PoCL compiles each kernel once, not per size


def launch_size(n: int) -> tuple[tuple[int], tuple[int]]:
    """Global and local sizes covering ``n`` bound-checked work items."""
    return (-(-n // GROUP) * GROUP,), (GROUP,)


def surface_args(up) -> list:
    """Arguments matching SURFACE_PARAMS in kernels/surface.h, in order."""
    return [up.normals, up.uvs, up.material_ids, up.materials, up.atlas, up.texture_infos]


def trace(device: Device, up, window: tuple[int, int, int, int], max_bounces: int) -> ShadingPoints:
    """Shading points of the pixels in ``window`` = (x0, y0, x1, y1) of the
    full image, for a scene uploaded by the renderer (``up``)."""
    x0, y0, x1, y1 = window
    w, h = x1 - x0, y1 - y0
    n = w * h
    pos, nrm, factor = (np.zeros((n, 4), np.float32) for _ in range(3))
    if n:
        buffers = [device.empty(pos.nbytes) for _ in range(3)]
        program = device.program("gi_points.cl")
        cl.Kernel(program, "GiPoints_trace")(
            device.queue, *launch_size(n), *up.tree.kernel_args(), *surface_args(up), up.camera,
            np.array(window, np.int32), np.int32(max_bounces), *buffers,
        )
        for host, buf in zip((pos, nrm, factor), buffers):
            cl.enqueue_copy(device.queue, host, buf)
    valid = pos[:, 3] > 0
    index = np.nonzero(valid)[0]
    pixels = np.stack([index % max(w, 1), index // max(w, 1)], axis=1).astype(np.int32)
    return ShadingPoints(
        positions=np.ascontiguousarray(pos[valid, :3]),
        normals=np.ascontiguousarray(nrm[valid, :3]),
        factor=np.ascontiguousarray(factor[valid, :3]),
        lobe=factor[valid, 3].astype(np.int32),
        pixels=pixels,
        valid=valid,
        width=w,
        height=h,
    )
