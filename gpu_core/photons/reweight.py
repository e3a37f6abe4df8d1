"""Photon maps reweighted in place when only the lights' power or colour
changed (photon_reweight.cl): each photon is scaled by its emitter's new
power over the power it was traced with, and every node of the photon
trees sums its photons again. A photon's path depends on the surfaces and
on where the lights are and how they shine, not on how bright they are, so
the maps stay a sample of the edited scene's light: with one emitter they
are the maps a fresh trace gives; with several, the photons stay shared
among emitters as they were, each weighted for its emitter's new power
(unbiased, the noise spread as before)."""

from __future__ import annotations

import numpy as np

from ..device import Device
from .emit import Emitter
from .trace import PhotonMaps

PROGRAM = "photons/photon_reweight.cl"


def programs() -> list[tuple[str, dict]]:
    """The program reweighting builds."""
    return [(PROGRAM, {})]


def reweight_maps(device: Device, maps: PhotonMaps, scales: np.ndarray, traced: list[Emitter],
                  emitters: list[Emitter]) -> None:
    """Scale the photons of ``maps``, traced for ``traced``, by ``scales``
    ((E, 4) float32, a row per emitter, emit.reweight_scales) to the power
    of ``emitters``; refit their trees, drop what was computed from them
    (the illumination cut) and restate their light power."""
    table = device.to_device(np.ascontiguousarray(scales, np.float32))
    scale = device.kernel(PROGRAM, "PhotonReweight_scale")
    refit = device.kernel(PROGRAM, "PhotonReweight_refit")
    for tree in (maps.global_map, maps.caustic_map):
        if tree is None or tree.point_count == 0:
            continue
        power, direction, _ = tree.photon_args()
        scale(tree.point_count, power, table, np.int32(len(scales)), np.int32(tree.point_count))
        refit(tree.node_count, tree.node_buffer, power, direction, np.int32(tree.node_count))
    maps.derived.clear()
    stats = maps.stats
    # each map's emitted power moves by each emitter's change of carried
    # power (exact where all of an emitter's photons leave with the same
    # power; a spot's falloff weighs its photons, and this is its expectation)
    change = sum((np.asarray(new.carried, np.float64) - np.asarray(old.carried, np.float64)
                  for old, new in zip(traced, emitters)), np.zeros(3))
    for name in stats["emitted_power"]:
        stats["emitted_power"][name] = np.maximum(np.asarray(stats["emitted_power"][name]) + change, 0.0).tolist()
    stats["light_power"] = sum((e.power for e in emitters), np.zeros(3)).tolist()
    stats["reweighted"] = stats.get("reweighted", 0) + 1
