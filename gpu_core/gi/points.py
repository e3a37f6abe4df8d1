"""Points on the device with float4 positions and unit normals (shading
points, cache samples), and their host copies for tests and statistics."""

from __future__ import annotations

import numpy as np


class DevicePoints:
    """A mixin for dataclasses with ``device``, ``pos``, ``nrm`` (float4
    buffers) and ``count``."""

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) float32 positions, read back."""
        return self.device.read_xyz(self.pos, self.count)

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) float32 unit normals, read back."""
        return self.device.read_xyz(self.nrm, self.count)
