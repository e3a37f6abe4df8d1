"""Normalised coordinates of the irradiance cache and checks of its inputs.

Positions go to the device moved and scaled (in float64) so that their box
is centred at the origin with largest side 1: the kernels then see the same
numbers for a scene at any scale or distance from the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Frame:
    """How positions were normalised: ``(p - centre) / extent``."""

    centre: np.ndarray  # float64 (3,)
    extent: float

    @staticmethod
    def around(*point_sets: np.ndarray) -> "Frame":
        """The frame of the box around every point of every set."""
        pts = [np.asarray(p, np.float64).reshape(-1, 3) for p in point_sets]
        pts = [p for p in pts if len(p)]
        if not pts:
            return Frame(np.zeros(3), 1.0)
        lo = np.min([p.min(axis=0) for p in pts], axis=0)
        hi = np.max([p.max(axis=0) for p in pts], axis=0)
        extent = float((hi - lo).max())
        if not extent > 0.0:  # one point, or all at one place
            extent = 1.0
        return Frame((lo + hi) / 2.0, extent)

    def to_device(self, points: np.ndarray) -> np.ndarray:
        """(N, 4) float32 normalised positions."""
        out = np.zeros((len(points), 4), np.float32)
        out[:, :3] = (np.asarray(points, np.float64) - self.centre) / self.extent
        return out

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """Normalised (N, 3) positions back in scene units, float32."""
        return (np.asarray(points, np.float64) * self.extent + self.centre).astype(np.float32)


def float4(vectors: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 4) float32 with w = 0."""
    out = np.zeros((len(vectors), 4), np.float32)
    out[:, :3] = vectors
    return out


def finite_rows(name: str, array, columns: int, dtype) -> np.ndarray:
    """``array`` as a contiguous (N, columns) array, or ValueError."""
    arr = np.ascontiguousarray(np.asarray(array, dtype).reshape(-1, columns))
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError(f"{name} holds NaN or infinite values")
    return arr
