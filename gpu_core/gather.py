"""Final gathering at the irradiance sample points [WZPB09] (kernels/gather.cl).

From each sample point, ``strata``² stratified cosine-distributed rays; the
radiance arriving along a ray that hits a diffuse point y is
albedo(y) / pi x E(y), with E(y) from the illumination cut. With cosine
sampling the sample's irradiance is pi times the mean arriving radiance,
i.e. the mean of albedo(y) E(y). Each sample also gets the harmonic mean
distance R_j of its hits, which scales its interpolation weight.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .device import Device
from .shading_points import launch_size, surface_args

_ROWS_PER_LAUNCH = 1 << 20  # gather rays per launch (bounds device memory)


@dataclass
class GatherResult:
    irradiance: np.ndarray  # (M, 3) float32 at the sample points
    harmonic_distance: np.ndarray  # (M,) float32 R_j (inf where no ray hit)
    stats: dict


def gather(device: Device, up, positions, normals, strata: int, irradiance_at, seed: int = 0) -> GatherResult:
    """Irradiance at sample points (``positions``, unit ``normals``, (M, 3))
    of a scene uploaded by the renderer; ``irradiance_at(points, normals)``
    gives the irradiance (K, 3) at gather hits (the illumination cut)."""
    started = time.perf_counter()
    pos = np.zeros((len(positions), 4), np.float32)
    nrm = np.zeros_like(pos)
    pos[:, :3], nrm[:, :3] = positions, normals
    m, rays = len(pos), max(1, int(strata)) ** 2
    irradiance = np.zeros((m, 3), np.float32)
    inv_distance = np.zeros(m, np.float64)  # sum of 1 / hit distance per sample
    hit_count = np.zeros(m, np.int64)
    per_launch = max(1, _ROWS_PER_LAUNCH // rays)
    trace_ms = lookup_ms = 0.0
    program = device.program("gather.cl")
    for first in range(0, m, per_launch):
        count = min(per_launch, m - first)
        rows = slice(first, first + count)
        began = time.perf_counter()
        hit_pos, hit_nrm, hit_alb = _trace(device, program, up, pos[rows], nrm[rows], int(strata), seed + first)
        trace_ms += (time.perf_counter() - began) * 1e3
        # radiance arriving along each ray: albedo / pi x E at its hit, times pi for cosine sampling
        began = time.perf_counter()
        hit = hit_pos[:, 3] > 0
        arriving = np.zeros((len(hit_pos), 3), np.float64)
        if hit.any():
            e = np.asarray(irradiance_at(hit_pos[hit, :3], hit_nrm[hit, :3]), np.float64)
            arriving[hit] = hit_alb[hit, :3] * np.clip(np.nan_to_num(e, nan=0.0, posinf=0.0), 0.0, None)
        lookup_ms += (time.perf_counter() - began) * 1e3
        irradiance[rows] = arriving.reshape(count, rays, 3).mean(axis=1)
        with np.errstate(divide="ignore"):
            inv_distance[rows] = np.where(hit, 1.0 / np.maximum(hit_pos[:, 3], 1e-30), 0.0).reshape(count, rays).sum(axis=1)
        hit_count[rows] = hit.reshape(count, rays).sum(axis=1)
    # harmonic mean distance of each sample's hits
    harmonic = np.full(m, np.inf, np.float32)
    some = inv_distance > 0
    harmonic[some] = hit_count[some] / inv_distance[some]
    stats = {
        "samples": m, "rays_per_sample": rays, "hit_fraction": float(hit_count.sum()) / max(m * rays, 1),
        "ms": {"trace": trace_ms, "lookup": lookup_ms, "total": (time.perf_counter() - started) * 1e3},
    }
    return GatherResult(irradiance, harmonic, stats)


def _trace(device: Device, program, up, pos: np.ndarray, nrm: np.ndarray, strata: int, seed: int):
    """Gather rays of a batch of samples: hit positions (w = distance, -1 =
    nothing diffuse hit), normals and albedos, (count * strata², 4) each."""
    n = len(pos) * strata * strata
    out = [np.empty((n, 4), np.float32) for _ in range(3)]
    buffers = [device.empty(a.nbytes) for a in out]
    cl.Kernel(program, "Gather_rays")(
        device.queue, *launch_size(n), *up.tree.kernel_args(), *surface_args(up), device.buffer(pos), device.buffer(nrm),
        np.int32(len(pos)), np.int32(strata), np.uint32(seed & 0xFFFFFFFF), *buffers,
    )
    for host, buf in zip(out, buffers):
        cl.enqueue_copy(device.queue, host, buf)
    return out
