"""Final gathering at the irradiance sample points [WZPB09] (gather.cl).

From each sample point, ``strata``² stratified cosine-distributed rays; the
radiance arriving along a ray that hits a diffuse point y is
albedo(y) / pi x E(y), with E(y) from the illumination cut (looked up on
the device, a batch's lookups sorted along a Morton curve first; its nodes
carry the caustic map's light too: cut.with_caustics).
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
KEY_BITS = 5  # per axis, of the Morton codes that order the cut's lookups (8 measured no better; 4 radix passes)
_RAYS_PER_LAUNCH = 1 << 18  # gather rays per launch: bounds a launch's time, and so the wait for Esc
# device bytes a ray of a batch holds: its cell, hit distance, deferred lookup
# (point, normal, weight), sort key, and the sort's two arrays and index
RAY_BYTES = 16 + 4 + 3 * 16 + 4 + 2 * 8 + 4


def batch_bytes(samples: int, strata: int) -> int:
    """Device memory of a gather's batch of rays (its largest)."""
    rays = strata * strata
    return RAY_BYTES * rays * min(max(1, _RAYS_PER_LAUNCH // rays), max(samples, 1))


def _defines(scene_defines: dict | None) -> dict:
    return {**(scene_defines or {}), **lookup_defines(0), "GATHER_KEY_BITS": KEY_BITS}


def programs(scene_defines: dict) -> list[tuple[str, dict]]:
    """The programs gathering builds."""
    return [(_PROGRAM, _defines(scene_defines))]


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
    out = GatherResult(device, device.empty(16 * m), device.empty(4 * m), device.empty(4 * m), device.empty(48 * m), m)
    job = GatherJob(buffers.kernel_args(), cut.kernel_args(), positions, normals, strata, seed, max_specular,
                    _defines(scene_defines), float(buffers.radius))
    gather_range(device, job, 0, m, out, should_stop)
    rays = strata * strata
    total_hits = primitives.sum_ints(device, out.hits, m)
    out.stats = {"samples": m, "rays_per_sample": rays, "hit_fraction": total_hits / max(m * rays, 1)}
    return out


@dataclass
class GatherJob:
    """What a gather reads: the scene's and the cut's kernel arguments, the
    sample points (device float4 positions and normals), the rays' strata,
    seed and bounce limit, the program's defines and the half-side of a cube
    around the scene (for the lookups' Morton codes)."""

    scene_args: list
    cut_args: list
    positions: cl.Buffer
    normals: cl.Buffer
    strata: int
    seed: int
    max_specular: int
    defines: dict
    extent: float


def gather_range(device: Device, job: GatherJob, first: int, end: int, out: GatherResult,
                 should_stop: Callable[[], bool] | None = None) -> None:
    """Gather the samples first .. end - 1 into ``out``, in batches of about
    _RAYS_PER_LAUNCH rays: each batch's rays traced, their cut lookups
    sorted along a Morton curve and made, then summed per sample."""
    rays = job.strata * job.strata
    trace, lookup, reduce = (device.kernel(_PROGRAM, name, job.defines)
                             for name in ("Gather_rays", "Gather_lookup", "Gather_reduce"))
    per_launch = max(1, _RAYS_PER_LAUNCH // rays)
    slots = rays * max(min(per_launch, end - first), 1)
    cells = device.empty(16 * slots)  # each ray's radiance and first-hit distance
    distances = device.empty(4 * slots)  # each ray's first diffuse hit distance
    lookups = [device.empty(16 * slots) for _ in range(3)]  # each ray's deferred lookup: point, normal, weight
    keys = device.empty(4 * slots)
    i32 = np.int32
    for start in range(first, end, per_launch):
        count = min(per_launch, end - start)
        n = count * rays
        trace(n, *job.scene_args, *job.cut_args, job.positions, job.normals, i32(start), i32(count), i32(job.strata),
              i32(job.max_specular), np.uint32(job.seed & 0xFFFFFFFF), np.float32(job.extent), cells, distances,
              *lookups, keys)
        _, in_order = primitives.sort_pairs(device, keys, None, n, 1 << (3 * KEY_BITS))
        lookup(n, *job.cut_args, in_order, i32(n), *lookups, cells)
        reduce(count, job.normals, i32(start), i32(count), i32(job.strata), cells, distances, out.e, out.distance,
               out.hits, out.gradient)
        if should_stop is not None and start + count < end:
            device.queue.finish()
            check_stop(should_stop)
