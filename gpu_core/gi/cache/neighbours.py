"""Cache samples checked against their nearest samples (neighbours.cl).

Lone outliers: a few gather rays that hit a small, very bright spot (a
focused caustic) make one sample far brighter than its neighbours, and
interpolation would spread it into a blotch on the wall. Each sample's
irradiance is brought down to OUTLIER_RATIO times the median of its
NEIGHBOURS nearest samples' (luminance); where the neighbours see the light
too, nothing changes. Where no neighbour saw any light (their median is 0)
there is nothing to bring a sample down to: its light is shared instead,
evenly between it and the samples that list it among their neighbours and
face its way, so the neighbourhood keeps it. A surface lit only by a small,
bright object is such a place: most of its samples' rays miss the object,
and dropping the light of the few that meet it made the floor of
light_spot.blend a quarter too dark.

Neighbour clamping [Krivanek et al. 2006]: a sample's harmonic-mean hit
distance R_j sets how far it is trusted (interpolation.py), and a sample
in the open beside one in a crevice (under a sphere, in a corner) has a far
larger R_j: it would cover the crevice with the brighter irradiance of the
open. Each R_j is clamped to R_k + |x_j - x_k| over its neighbours k, in
RADIUS_ROUNDS rounds, so that a small R_j also bounds the samples around
it, one neighbour further each round. On the Cornell box at Final this
took the display error against Cycles from 0.037 to 0.031 (README). A
sample whose rays all escaped has an infinite R_j; where no neighbour
within those rounds bounds it, it takes the largest finite R_j: with an
infinite one it covered the whole scene with a weight no other sample could
match (the floor of light_spot.blend lost half its indirect light at 3,600
cache points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ...accel.point_tree import PointTree
from ...device import Device, primitives

NEIGHBOURS = 8  # samples a cache sample is compared with
OUTLIER_RATIO = 4.0  # largest irradiance of a sample over its neighbours' median
SHARE_COS = 0.9  # samples whose normals are within about 25 degrees share a lone sample's light
RADIUS_ROUNDS = 8  # rounds of neighbour clamping (the Cornell box's radii settle within 6)
_PROGRAM = "gi/cache/neighbours.cl"
_DEFINES = {"KNN_K": NEIGHBOURS + 1, "NEIGHBOURS": NEIGHBOURS, "OUTLIER_RATIO": f"{OUTLIER_RATIO!r}f",
            "NEIGHBOURS_SHARE_COS": f"{SHARE_COS!r}f"}


def programs() -> list[tuple[str, dict]]:
    return [(_PROGRAM, _DEFINES)]


@dataclass
class Checked:
    """The samples' irradiance with lone outliers brought down (or, among
    dark neighbours, their light shared) and their distances R_j clamped by
    their neighbours', and how many of each."""

    irradiance: cl.Buffer  # float4 per sample
    radii: cl.Buffer  # float per sample
    outliers_clamped: int
    radii_clamped: int
    radii_bounded: int = 0  # infinite R_j (no gather ray hit) bounded by the largest finite one


def check(device: Device, positions: cl.Buffer, normals: cl.Buffer, irradiance: cl.Buffer, radii: cl.Buffer,
          m: int) -> Checked:
    """The ``m`` samples (float4 positions, unit normals and irradiance,
    float R_j) checked against their NEIGHBOURS nearest; with no more
    samples than that, as they are."""
    if m <= NEIGHBOURS:
        return Checked(irradiance, radii, 0, 0)
    tree = PointTree.from_device(device, primitives.indexed_points(device, positions, m))
    clamped, excess, out = device.empty(16 * m), device.empty(16 * m), device.empty(16 * m)
    ids, dists = device.empty(4 * NEIGHBOURS * m), device.empty(4 * NEIGHBOURS * m)
    counts, receivers = device.zeros(8), device.zeros(4 * m)
    device.kernel(_PROGRAM, "Neighbours_clamp_outliers", _DEFINES)(
        m, *tree.kernel_args(), positions, normals, irradiance, np.int32(m), clamped, excess, ids, dists, receivers,
        counts)
    device.kernel(_PROGRAM, "Neighbours_share_excess", _DEFINES)(
        m, ids, normals, clamped, excess, receivers, np.int32(m), out)
    # Jacobi rounds between two buffers, the gathered R_j left as they are
    clamp_radii = device.kernel(_PROGRAM, "Neighbours_clamp_radii", _DEFINES)
    turns = [device.empty(4 * m), device.empty(4 * m)]
    now = radii
    for round_ in range(RADIUS_ROUNDS):
        last = round_ == RADIUS_ROUNDS - 1
        clamp_radii(m, ids, dists, radii, now, np.int32(m), np.int32(last), turns[round_ % 2], counts)
        now = turns[round_ % 2]
    bound = device.zeros(4)
    device.kernel(_PROGRAM, "Neighbours_finite_max", _DEFINES)(m, now, np.int32(m), bound)
    device.kernel(_PROGRAM, "Neighbours_bound_infinite", _DEFINES)(m, now, np.int32(m), bound, counts)
    outliers_clamped, radii_clamped, radii_bounded = device.read(counts, 3, np.int32)
    return Checked(out, now, int(outliers_clamped), int(radii_clamped), int(radii_bounded))
