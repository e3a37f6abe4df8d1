"""The pixel filter, as Cycles' film has it: each camera sample is offset
from its pixel's centre along x and y independently, drawn in proportion to
the filter, so a pixel averages the image under the (separable) filter.

Cycles' filters over Blender's Filter Width w: a box w pixels wide; a
Gaussian exp(-72 (t - 1/2)^2) over 3 w; a Blackman-Harris window over 2 w
(t in [0, 1] across the support). The image kernel reads the inverse CDF as
a table of FILTER_TABLE_SIZE offsets (image.cl, Image_filter_offset).
"""

from __future__ import annotations

import numpy as np

from ..device.constants import FILTER_BLACKMAN_HARRIS, FILTER_BOX, FILTER_GAUSSIAN, FILTER_TABLE_SIZE

_SUPPORT = {FILTER_BOX: 1.0, FILTER_GAUSSIAN: 3.0, FILTER_BLACKMAN_HARRIS: 2.0}  # support / width
_WIDTH_RANGE = (0.01, 10.0)  # Cycles' Filter Width bounds, in pixels
_FINE = 4096  # steps of the CDF before it is inverted


def _shape(kind: int, t: np.ndarray) -> np.ndarray:
    """The filter across its support, t in [0, 1]."""
    if kind == FILTER_GAUSSIAN:
        return np.exp(-72.0 * (t - 0.5) ** 2)
    if kind == FILTER_BLACKMAN_HARRIS:
        a = 2.0 * np.pi * t
        return 0.35875 - 0.48829 * np.cos(a) + 0.14128 * np.cos(2 * a) - 0.01168 * np.cos(3 * a)
    return np.ones_like(t)


def filter_table(kind: int, width: float) -> np.ndarray:
    """float32 offsets from the pixel centre, in pixels, at u = i / (N - 1):
    the inverse CDF of the filter (an unknown kind is a box; a width that is
    not finite or out of Cycles' range is bounded, 1 px when not finite)."""
    kind = kind if kind in _SUPPORT else FILTER_BOX
    width = float(width) if np.isfinite(width) else 1.0
    support = float(np.clip(width, *_WIDTH_RANGE)) * _SUPPORT[kind]
    t = np.linspace(0.0, 1.0, _FINE + 1)
    f = _shape(kind, t)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]))])
    cdf /= cdf[-1]
    u = np.linspace(0.0, 1.0, FILTER_TABLE_SIZE)
    return ((np.interp(u, cdf, t) - 0.5) * support).astype(np.float32)
