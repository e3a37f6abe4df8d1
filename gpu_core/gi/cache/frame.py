"""Normalised coordinates of the irradiance cache.

The cache works on positions moved and scaled so that their box is centred
at the origin with largest side 1: the kernels then see the same numbers
for a scene at any scale or distance from the origin. The frame comes from
the points' bounds (reduced on the device); positions are normalised on the
device (frame.cl), with the centre split into two floats so the result is
as close as float32 allows to the float64 one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ...device import Device, primitives
from ...device.layout import float4_rows

_PROGRAM = "gi/cache/frame.cl"


@dataclass
class Frame:
    """How positions were normalised: ``(p - centre) / extent``."""

    centre: np.ndarray  # float64 (3,)
    extent: float

    @staticmethod
    def from_bounds(lo, hi) -> "Frame":
        """The frame of the box lo..hi; a unit one for an empty or flat-to-a-point box."""
        lo, hi = np.asarray(lo, np.float64)[:3], np.asarray(hi, np.float64)[:3]
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (hi < lo).any():
            return Frame(np.zeros(3), 1.0)
        extent = float((hi - lo).max())
        if not extent > 0.0:  # one point, or all at one place
            extent = 1.0
        return Frame((lo + hi) / 2.0, extent)

    @staticmethod
    def around(*point_sets: np.ndarray) -> "Frame":
        """The frame of the box around every point of every host set."""
        pts = [np.asarray(p, np.float64).reshape(-1, 3) for p in point_sets]
        pts = [p for p in pts if len(p)]
        if not pts:
            return Frame(np.zeros(3), 1.0)
        return Frame.from_bounds(np.min([p.min(axis=0) for p in pts], axis=0),
                                 np.max([p.max(axis=0) for p in pts], axis=0))

    @staticmethod
    def on_device(device: Device, *point_sets: tuple[cl.Buffer, int]) -> "Frame":
        """The frame of the box around every (float4 buffer, count) set."""
        bounds = [primitives.bounds(device, buf, n) for buf, n in point_sets if n > 0]
        if not bounds:
            return Frame(np.zeros(3), 1.0)
        return Frame.from_bounds(np.min([b[0][:3] for b in bounds], axis=0), np.max([b[1][:3] for b in bounds], axis=0))

    def normalise(self, device: Device, points: cl.Buffer, n: int) -> cl.Buffer:
        """A new buffer of the ``n`` float4 ``points`` in this frame (w = 0)."""
        high = self.centre.astype(np.float32)
        low = (self.centre - high).astype(np.float32)
        out = device.empty(16 * n)
        device.kernel(_PROGRAM, "Cache_normalise")(
            n, points, np.int32(n), np.append(high, 0).astype(np.float32), np.append(low, 0).astype(np.float32),
            np.float32(self.extent), out)
        return out

    def to_device(self, points: np.ndarray) -> np.ndarray:
        """(N, 4) float32 normalised positions, computed on the host."""
        return float4_rows((np.asarray(points, np.float64) - self.centre) / self.extent)

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """Normalised (N, 3) positions back in scene units, float32."""
        return (np.asarray(points, np.float64) * self.extent + self.centre).astype(np.float32)
