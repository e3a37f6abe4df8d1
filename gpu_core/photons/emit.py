"""Photon emission: how much power each emitter sends out in Cycles' units
(photons/photon_emit.h draws the photons), how the photons are shared
among emitters, and which photon maps a scene needs.

Power in watts: the photons of a map carry, all together, the power the
lights emit (kernels: shading/lights.h and photons/photon_emit.h).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..device.constants import LIGHT_SPOT, PHOTON_EMITTER_WORLD
from ..device.layout import EMITTER_DTYPE
from ..scene.model import Scene
from ..scene.tables import SceneTables


@dataclass
class Emitter:
    """One emitter: its light row (or PHOTON_EMITTER_WORLD), the rgb watts
    it emits, and the watts its photons carry before per-photon factors (a
    spot's photons cover its whole cone and the kernel applies the falloff)."""

    row: int
    power: np.ndarray
    carried: np.ndarray


def emitter_powers(scene: Scene, tables: SceneTables) -> list[Emitter]:
    """Every emitter with power, from the scene's light table; the sun and
    the world cover the scene's bounding sphere."""
    radius = tables.radius
    out = []
    for row, light in enumerate(tables.lights):
        total = tables.emitted[row]
        if np.sum(total) > 0:
            carried = total
            if int(light["kind"]) == LIGHT_SPOT:  # P / (4 pi) x the cone's solid angle
                carried = light["power"][:3].astype(np.float64) * 0.5 * (1.0 - float(light["cos_half"]))
            out.append(Emitter(row, total, carried))
    world = np.asarray(scene.world_color, np.float64)
    if np.sum(world) > 0:
        total = 4.0 * np.pi**2 * radius**2 * world
        out.append(Emitter(PHOTON_EMITTER_WORLD, total, total))
    return out


def allocate(emitters: list[Emitter], photons: int) -> np.ndarray:
    """Emitter rows: photons in proportion to power (at least one each)."""
    table = np.zeros(len(emitters), EMITTER_DTYPE)
    if not emitters:
        return table
    weight = np.array([e.power.sum() for e in emitters])
    counts = np.maximum(1, np.rint(photons * weight / weight.sum())).astype(np.int64)
    table["first"] = np.concatenate([[0], np.cumsum(counts)[:-1]])
    table["count"] = counts
    table["light"] = [e.row for e in emitters]
    per_photon = np.array([e.carried for e in emitters]) / counts[:, None]
    table["power"][:, :3] = np.minimum(per_photon, np.finfo(np.float32).max)
    return table


# the largest reweighting factor: photon powers scaled past it could leave float range
_LARGEST_SCALE = 1e20
# light-table fields a photon's path depends on: where a light is and how it
# shines, not how bright it is (power, radiance and the shadow-ray pick)
_PATH_FIELDS = ("position", "direction", "axis_u", "axis_v", "radius", "cos_half", "spot_smooth", "sun_norm", "kind",
                "shape")


def reweight_scales(traced: list[Emitter], traced_lights: np.ndarray, emitters: list[Emitter],
                    lights: np.ndarray) -> np.ndarray | None:
    """Per emitter of maps traced for ``traced`` (with light table
    ``traced_lights``), the rgb factor that gives them the power of
    ``emitters`` (light table ``lights``) — or None when the photons' paths
    would differ: another set of emitters, a light moved, turned or
    reshaped, a light row added or removed, or a channel lit that was dark;
    or when a factor leaves float range (a light made 1e40 times brighter:
    a fresh trace carries that power without overflow)."""
    if len(traced) != len(emitters) or len(traced_lights) != len(lights):
        return None
    for name in _PATH_FIELDS:
        if not np.array_equal(traced_lights[name], lights[name]):
            return None
    scales = np.ones((len(emitters), 4), np.float32)
    for i, (old, new) in enumerate(zip(traced, emitters)):
        if old.row != new.row:
            return None
        before, after = np.asarray(old.carried, np.float64), np.asarray(new.carried, np.float64)
        if ((before <= 0) & (after > 0)).any():
            return None
        factor = np.where(before > 0, after / np.where(before > 0, before, 1.0), 0.0)
        if not (np.isfinite(factor).all() and factor.max() <= _LARGEST_SCALE):
            return None
        scales[i, :3] = factor
    return scales


MAPS = ("global", "caustic")


def maps_needed(emitters: list[Emitter], triangle_count: int, specular: bool, global_photons: int,
                caustic_photons: int) -> dict[str, str]:
    """Each map: "built" (with the reason for a caustic map) or "skipped:"
    and why. A caustic map only where a specular surface can focus light."""
    if not emitters:
        return {name: "skipped: no light emits power" for name in MAPS}
    if triangle_count == 0:
        return {name: "skipped: no surfaces" for name in MAPS}
    out = {"global": "built" if global_photons > 0 else "skipped: zero photons asked for"}
    if not specular:
        out["caustic"] = "skipped: no specular or transmissive surface"
    elif caustic_photons <= 0:
        out["caustic"] = "skipped: zero photons asked for"
    else:
        out["caustic"] = "built: specular or transmissive surfaces present"
    return out
