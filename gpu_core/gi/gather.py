"""Final gathering at the irradiance sample points [WZPB09] (gather.cl).

From each sample point, ``strata``² stratified cosine-distributed rays; the
radiance arriving along a ray that hits a diffuse point y is
albedo(y) / pi x E(y), with E(y) from the illumination cut (looked up on
the device, inside the gather kernel; its nodes carry the caustic map's
light too: cut.with_caustics).
With cosine sampling the sample's irradiance is pi times the mean arriving
radiance, i.e. the mean of albedo(y) E(y). Each sample also gets the
harmonic mean distance R_j of its hits, which scales its interpolation
weight, and its translational irradiance gradient [Ward and Heckbert 1992]
from the rays' radiance and first-hit distances, cell by cell, which
carries its irradiance to the points it covers. Nothing but a hit count
comes back to the host.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl

from ..device import Device, primitives
from ..errors import check_stop
from ..scene.upload import SceneBuffers
from .cut import Cut, lookup_defines

_PROGRAM = "gi/gather.cl"
GROUP = 64  # work-items gathering one sample point
_RAYS_PER_LAUNCH = 1 << 18  # gather rays per launch: bounds a launch's time, and so the wait for Esc


def _defines(device: Device, scene_defines: dict | None) -> dict:
    group = min(GROUP, int(device.device.max_work_group_size))
    return {**(scene_defines or {}), **lookup_defines(0), "GATHER_GROUP": 1 << (group.bit_length() - 1)}


def programs(device: Device, scene_defines: dict) -> list[tuple[str, dict]]:
    """The programs gathering builds."""
    return [(_PROGRAM, _defines(device, scene_defines))]


@dataclass
class GatherResult:
    """Per sample point, on the device: irradiance (float4), harmonic mean
    hit distance R_j (float, inf where no ray hit), hit count, and the
    translational irradiance gradient (three float4 rows dE/dx, dE/dy,
    dE/dz, rgb each)."""

    device: Device
    e: cl.Buffer
    distance: cl.Buffer
    hits: cl.Buffer
    gradient: cl.Buffer
    count: int
    stats: dict = field(default_factory=dict)

    @property
    def irradiance(self) -> np.ndarray:
        """(M, 3) float32, read back (tests and statistics)."""
        return self.device.read_xyz(self.e, self.count)

    @property
    def harmonic_distance(self) -> np.ndarray:
        """(M,) float32, read back."""
        return self.device.read(self.distance, self.count, np.float32)

    @property
    def translational_gradient(self) -> np.ndarray:
        """(M, 3 channels, 3 axes) float32, read back."""
        rows = self.device.read(self.gradient, 3 * self.count, np.dtype((np.float32, 4))).reshape(self.count, 3, 4)
        return rows[:, :, :3].transpose(0, 2, 1)


def gather(device: Device, buffers: SceneBuffers, positions: cl.Buffer, normals: cl.Buffer, m: int, strata: int,
           cut: Cut, seed: int = 0, max_specular: int = 8, scene_defines: dict | None = None,
           should_stop: Callable[[], bool] | None = None) -> GatherResult:
    """Irradiance at ``m`` sample points (float4 ``positions`` and unit
    ``normals`` on the device, in the scene's device frame) from ``cut``;
    ``should_stop`` is polled after each batch of samples (RenderCancelled)."""
    strata = max(1, int(strata))
    rays = strata * strata
    e, distance, hits, gradient = device.empty(16 * m), device.empty(4 * m), device.empty(4 * m), device.empty(48 * m)
    defines = _defines(device, scene_defines)
    group = defines["GATHER_GROUP"]
    kernel = device.kernel(_PROGRAM, "Gather_samples", defines)
    per_launch = max(1, _RAYS_PER_LAUNCH // rays)
    cells = device.empty(16 * rays * min(per_launch, m))  # each ray's radiance and first-hit distance
    for first in range(0, m, per_launch):
        count = min(per_launch, m - first)
        kernel.groups(count, group, *buffers.kernel_args(), *cut.kernel_args(), positions, normals, np.int32(first),
                      np.int32(first + count), np.int32(strata), np.int32(max_specular), np.uint32(seed & 0xFFFFFFFF),
                      cells, e, distance, hits, gradient)
        if should_stop is not None and first + count < m:
            device.queue.finish()
            check_stop(should_stop)
    total_hits = primitives.sum_ints(device, hits, m)
    stats = {"samples": m, "rays_per_sample": rays, "hit_fraction": total_hits / max(m * rays, 1)}
    return GatherResult(device, e, distance, hits, gradient, m, stats)



