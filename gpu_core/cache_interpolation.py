"""Interpolation of cached irradiance to shading points (kernels/cache_interpolation.cl).

    E(x) = sum_j w_j E_j / sum_j w_j,  w_j = 1 / (|x - x_j| / R_j + sqrt(2 - 2 n . n_j))

over the samples j with |x - x_j| < a R_j, n . n_j > 0.01 and x not behind
them, (x - x_j) . (n + n_j) >= -behind R_j. A point no sample covers takes
the irradiance of the nearest sample with n . n_j > 0.01, else of the
nearest sample, so no point is left without a value.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from . import cache_grid
from .cache_frame import Frame, finite_rows, float4
from .cache_kernels import kernel
from .cache_sort import group, zeros
from .device import Device

_PROGRAM = "cache_interpolation.cl"
COVER = 0.5  # default a: a sample covers points within a R_j
BEHIND = 0.02  # default tolerance of the in-front test, in units of R_j
_MIN_R = 1e-6  # R_j bounds, in units of the largest side of the box of
_MAX_R = 1e6  # samples and points (zero, negative or NaN R_j -> the minimum)
_MAX_COVER = 2.0  # a coverage radius this large already spans the whole box


def interpolate(device: Device, samples_pos, samples_n, samples_E, samples_R, points, normals,
                a: float = COVER, behind: float = BEHIND):
    """Irradiance (N, 3) float32 at ``points`` with unit ``normals`` from the
    samples (positions (M, 3), unit normals (M, 3), irradiance (M, 3),
    harmonic-mean distances (M,)), and stats: ``covered`` (fraction of points
    with at least one accepted sample), ``fallback`` (points given their
    nearest sample's value), ``fallback_any_normal`` (of those, points with
    no sample facing their way), ``ms``."""
    started = time.perf_counter()
    spos = finite_rows("samples_pos", samples_pos, 3, np.float32)
    snrm = finite_rows("samples_n", samples_n, 3, np.float32)
    sirr = finite_rows("samples_E", samples_E, 3, np.float32)
    srad = np.asarray(samples_R, np.float64).reshape(-1)
    pts = finite_rows("points", points, 3, np.float32)
    nrm = finite_rows("normals", normals, 3, np.float32)
    m, n = len(spos), len(pts)
    if not (len(snrm) == len(sirr) == len(srad) == m):
        raise ValueError("samples_pos, samples_n, samples_E and samples_R differ in length")
    if len(nrm) != n:
        raise ValueError("points and normals differ in length")
    if not (np.isfinite(a) and a > 0.0 and np.isfinite(behind) and behind >= 0.0):
        raise ValueError(f"a must be > 0 and behind >= 0 (finite), not {a}, {behind}")
    stats = {"points": n, "samples": m, "ms": {}}
    if n == 0 or m == 0:
        stats.update(covered=0.0, fallback=0, fallback_any_normal=0)
        return np.zeros((n, 3), np.float32), stats
    frame = Frame.around(spos, pts)
    radius = np.nan_to_num(srad / frame.extent, nan=_MIN_R, posinf=_MAX_R)
    radius = np.clip(radius, _MIN_R, _MAX_R)
    spos4 = frame.to_device(spos)
    spos4[:, 3] = np.minimum(a * radius, _MAX_COVER)
    queue = device.queue
    d_spos, d_snrm, d_sirr = device.buffer(spos4), device.buffer(float4(snrm)), device.buffer(float4(sirr))
    d_srad = device.buffer(radius.astype(np.float32))
    d_pos, d_nrm = device.buffer(frame.to_device(pts)), device.buffer(float4(nrm))
    # hash grid of coverage spheres, one level per power-of-two radius
    table = 1 << max(2 * m - 1, 1).bit_length()
    cells, keys, levels = device.empty(16 * m), device.empty(4 * m), zeros(device, 4)
    kernel(device, _PROGRAM, "Cache_sample_cells")(queue, (m,), None, d_spos, np.int32(m), np.uint32(table - 1),
                                                   cells, keys, levels)
    buckets = group(device, keys, m, table)
    level_bits = np.zeros(1, np.uint32)
    cl.enqueue_copy(queue, level_bits, levels)
    # uniform grid of sample positions for the nearest-sample fallback
    lo, hi = spos4[:, :3].min(axis=0), spos4[:, :3].max(axis=0)
    grid = cache_grid.build(device, d_spos, m, lo, hi, m)
    queue.finish()
    stats["ms"]["build"] = (time.perf_counter() - started) * 1e3
    began = time.perf_counter()
    out, flag = device.empty(16 * n), device.empty(4 * n)
    kernel(device, _PROGRAM, "Cache_interpolate")(
        queue, (n,), None, d_pos, d_nrm, np.int32(n), d_spos, d_snrm, d_sirr, d_srad, cells,
        buckets.start, buckets.end, buckets.order, np.uint32(table - 1), np.uint32(level_bits[0]),
        *grid.kernel_args(), np.int32(m), np.float32(behind), out, flag,
    )
    irradiance, flags = np.empty((n, 4), np.float32), np.empty(n, np.int32)
    cl.enqueue_copy(queue, irradiance, out)
    cl.enqueue_copy(queue, flags, flag)
    stats["ms"]["interpolate"] = (time.perf_counter() - began) * 1e3
    kinds = np.bincount(flags, minlength=4)
    stats.update(covered=float(kinds[1]) / n, fallback=int(kinds[2] + kinds[3]), fallback_any_normal=int(kinds[3]))
    stats["ms"]["total"] = (time.perf_counter() - started) * 1e3
    return np.ascontiguousarray(irradiance[:, :3]), stats
