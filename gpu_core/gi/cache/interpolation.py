"""Interpolation of cached irradiance to shading points (interpolation.cl).

    E(x) = sum_j w_j E_j(x) / sum_j w_j,  w_j = 1 / (|x - x_j| / R_j + sqrt(2 - 2 n . n_j))

with E_j(x) = E_j + (x - x_j) . grad E_j where the samples' translational
gradients are given (bounded: GRADIENT_LIMIT; a point no sample covers
takes its nearest facing sample's carried from the edge of its coverage),

over the samples j with |x - x_j| < a R_j, n . n_j > 0.01 and x not behind
them, (x - x_j) . (n + n_j) >= -behind R_j. A point no sample covers takes
the irradiance of the nearest sample with n . n_j > 0.01, else of the
nearest sample, so no point is left without a value. Samples and points
are read from the device, in the cache's normalised frame (frame.py).
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ...device import Device, primitives
from ...device.layout import finite_rows, float4_rows
from ...device.timer import StageTimer
from . import grid as cache_grid
from .frame import Frame

_PROGRAM = "gi/cache/interpolation.cl"
COVER = 0.5  # default a: a sample covers points within a R_j
BEHIND = 0.02  # default tolerance of the in-front test, in units of R_j
_MIN_R = 1e-6  # R_j bounds, in units of the largest side of the box of
_MAX_R = 1e6  # samples and points (zero, negative or NaN R_j -> the minimum)
_MAX_COVER = 2.0  # a coverage radius this large already spans the whole box
_SLOTS = 27  # cells a sample is listed in, at most: 3 per axis
# A sample's gradient changes its irradiance by at most this fraction over
# R_j (the demo scenes at 256², F12 against Cycles: 1.0 and 0.25 measured
# worse overall than 0.5; README, "Irradiance gradients")
GRADIENT_LIMIT = 0.5


_DEFINES = {"CACHE_MIN_R": f"{_MIN_R!r}f", "CACHE_MAX_R": f"{_MAX_R!r}f", "CACHE_MAX_COVER": f"{_MAX_COVER!r}f",
            "CACHE_SLOTS": _SLOTS, "CACHE_GRADIENT_LIMIT": f"{GRADIENT_LIMIT!r}f"}


def programs() -> list[tuple[str, dict]]:
    """The programs interpolation builds."""
    return [(_PROGRAM, _DEFINES), ("gi/cache/grid.cl", {})]


def _k(device: Device, name: str):
    return device.kernel(_PROGRAM, name, _DEFINES)


def interpolate_on_device(device: Device, spos: cl.Buffer, snrm: cl.Buffer, sirr: cl.Buffer, srad: cl.Buffer,
                          m: int, pos: cl.Buffer, nrm: cl.Buffer, n: int, a: float = COVER,
                          behind: float = BEHIND, flag: cl.Buffer | None = None,
                          sgrad: cl.Buffer | None = None) -> tuple[cl.Buffer, dict]:
    """Irradiance (float4 per point, on the device) at the ``n`` points
    ``pos`` (float4) with unit normals ``nrm`` from the ``m`` samples
    (float4 positions, unit normals and irradiance, float harmonic-mean
    distances R_j, and where given their translational gradients
    ``sgrad``, three float4 rows each as gather.GatherResult holds them, in
    scene units), and stats: ``covered`` (fraction of points with at
    least one accepted sample), ``fallback`` (points given their nearest
    sample's value), ``fallback_any_normal`` (of those, points with no
    sample facing their way), ``ms``. ``flag`` (int per point), when given,
    receives 1 where a point is covered, 2 or 3 where it took a nearest
    sample's value, 0 where there are no samples."""
    if not (np.isfinite(a) and a > 0.0 and np.isfinite(behind) and behind >= 0.0):
        raise ValueError(f"a must be > 0 and behind >= 0 (finite), not {a}, {behind}")
    timer = StageTimer(device.queue)
    stats = {"points": n, "samples": m, "ms": timer.ms}
    out = device.zeros(16 * n)
    if n == 0 or m == 0:
        if flag is not None and n:
            cl.enqueue_fill_buffer(device.queue, flag, np.int32(0), 0, 4 * n)
        stats.update(covered=0.0, fallback=0, fallback_any_normal=0)
        return out, stats
    with timer.stage("build"):
        frame = Frame.on_device(device, (spos, m), (pos, n))
        high = frame.centre.astype(np.float32)
        low = (frame.centre - high).astype(np.float32)
        # samples in the frame, w = coverage radius a R_j; R_j and the bounded gradients in frame units
        d_spos, d_srad, d_sgrad = device.empty(16 * m), device.empty(4 * m), device.empty(48 * m)
        sgrad = device.zeros(48 * m) if sgrad is None else sgrad
        _k(device, "Cache_prepare_samples")(
            m, spos, srad, sirr, sgrad, np.int32(m), np.append(high, 0).astype(np.float32),
            np.append(low, 0).astype(np.float32), np.float32(frame.extent), np.float32(a), d_spos, d_srad, d_sgrad)
        d_pos = frame.normalise(device, pos, n)
        # hash grid of coverage spheres, one level per power-of-two radius:
        # each sample listed in up to _SLOTS cells, about 16 buckets a sample
        table = 1 << max(16 * m - 1, 1).bit_length()
        slots = _SLOTS * m
        cells, keys, levels = device.empty(16 * slots), device.empty(4 * slots), device.zeros(4)
        _k(device, "Cache_sample_cells")(m, d_spos, np.int32(m), np.uint32(table - 1), cells, keys, levels)
        buckets = primitives.group(device, keys, slots, table + 1)
        entry_cell, entry_pos = device.empty(16 * slots), device.empty(16 * slots)
        _k(device, "Cache_bucket_entries")(slots, buckets.order, np.int32(slots), cells, d_spos, entry_cell, entry_pos)
        level_bits = device.scalar(levels, np.uint32)
        # uniform grid of sample positions for the nearest-sample fallback
        lo, hi = primitives.bounds(device, d_spos, m)
        grid = cache_grid.build(device, d_spos, m, lo[:3], hi[:3], m)
    with timer.stage("interpolate"):
        flag = device.empty(4 * n) if flag is None else flag
        _k(device, "Cache_interpolate")(
            n, d_pos, nrm, np.int32(n), d_spos, snrm, sirr, d_sgrad, d_srad, entry_cell, entry_pos, buckets.start,
            buckets.end, buckets.order, np.uint32(table - 1), np.uint32(level_bits), *grid.kernel_args(), np.int32(m),
            np.float32(behind), out, flag)
        kinds = _flag_counts(device, flag, n)
    stats.update(covered=float(kinds[1]) / n, fallback=int(kinds[2] + kinds[3]), fallback_any_normal=int(kinds[3]))
    stats["ms"]["total"] = timer.ms["build"] + timer.ms["interpolate"]
    return out, stats


def uncovered(device: Device, flag: cl.Buffer, n: int) -> tuple[cl.Buffer, int]:
    """The indices of the points ``interpolate_on_device`` flagged as not
    covered by any sample, and how many."""
    flags = device.empty(4 * max(n, 1))
    _k(device, "Cache_uncovered")(n, flag, np.int32(n), flags)
    return primitives.compact(device, flags, n)


def _flag_counts(device: Device, flag: cl.Buffer, n: int) -> np.ndarray:
    """How many points have each flag 0..3, counted on the device."""
    one_hot = device.empty(16 * n)
    _k(device, "Cache_flag_one_hot")(n, flag, np.int32(n), one_hot)
    return primitives.sum_int4(device, one_hot, n)


def interpolate(device: Device, samples_pos, samples_n, samples_E, samples_R, points, normals,
                a: float = COVER, behind: float = BEHIND, samples_grad=None):
    """``interpolate_on_device`` on host arrays: samples (positions (M, 3),
    unit normals (M, 3), irradiance (M, 3), harmonic-mean distances (M,),
    optionally translational gradients (M, 3 channels, 3 axes)), points
    (N, 3) with unit normals; returns irradiance (N, 3) and stats."""
    spos = finite_rows("samples_pos", samples_pos, 3, np.float32)
    snrm = finite_rows("samples_n", samples_n, 3, np.float32)
    sirr = finite_rows("samples_E", samples_E, 3, np.float32)
    srad = np.asarray(samples_R, np.float32).reshape(-1)
    pts = finite_rows("points", points, 3, np.float32)
    nrm = finite_rows("normals", normals, 3, np.float32)
    m, n = len(spos), len(pts)
    if not (len(snrm) == len(sirr) == len(srad) == m):
        raise ValueError("samples_pos, samples_n, samples_E and samples_R differ in length")
    if len(nrm) != n:
        raise ValueError("points and normals differ in length")
    up = device.to_device
    sgrad = None
    if samples_grad is not None:
        grad = np.asarray(samples_grad, np.float32).reshape(m, 3, 3)
        if not np.isfinite(grad).all():
            raise ValueError("samples_grad must be finite")
        sgrad = up(float4_rows(grad.transpose(0, 2, 1).reshape(3 * m, 3)))
    out, stats = interpolate_on_device(device, up(float4_rows(spos)), up(float4_rows(snrm)), up(float4_rows(sirr)),
                                       up(srad), m, up(float4_rows(pts)), up(float4_rows(nrm)), n, a, behind,
                                       sgrad=sgrad)
    return device.read_xyz(out, n), stats
