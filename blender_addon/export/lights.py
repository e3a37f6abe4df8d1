"""Blender lights to gpu_core light rows, in Cycles' units.

Power is colour x energy x 2^exposure (x the blackbody colour when the
temperature is used) in watts, and W/m^2 for a sun. A light whose
"Normalize" is off keeps its strength per unit of emitting area, so its
power is scaled by the area Cycles would otherwise divide by.
"""

from __future__ import annotations

import math

import numpy as np

from gpu_core.scene import AREA_ELLIPSE, AREA_RECTANGLE, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN

_ELLIPTIC = ("DISK", "ELLIPSE")


def light_row(light, matrix, warnings: list[str]) -> dict | None:
    """A row for gpu_core.scene.Lights.make, or None when the light emits
    nothing this engine can render (the reason goes to ``warnings``)."""
    m = np.array(matrix, np.float64)
    axis_x, axis_y, axis_z = m[:3, 0], m[:3, 1], m[:3, 2]
    z_length = np.linalg.norm(axis_z)
    direction = -axis_z / z_length if z_length > 0 else np.array([0.0, 0.0, -1.0])
    kind = light.type
    if kind == "AREA" and getattr(getattr(light, "cycles", None), "is_portal", False):
        return None  # a portal only guides world sampling in Cycles; it emits nothing
    if kind not in ("POINT", "SPOT", "SUN", "AREA"):
        warnings.append(f"light '{light.name}': type {kind} is not supported; skipped")
        return None
    _warn_unsupported(light, warnings)

    row = {"name": light.name, "position": tuple(m[:3, 3]), "direction": tuple(direction)}
    if kind in ("POINT", "SPOT"):
        row.update(kind=LIGHT_POINT if kind == "POINT" else LIGHT_SPOT, radius=float(light.shadow_soft_size))
        if kind == "SPOT":
            row.update(spot_angle=float(light.spot_size), spot_blend=float(light.spot_blend))
        area = 4.0 * math.pi * light.shadow_soft_size**2 or 4.0
    elif kind == "SUN":
        row.update(kind=LIGHT_SUN, sun_angle=float(light.angle))
        half = 0.5 * light.angle
        area = math.pi * math.sin(half) ** 2 if half > 0 else 1.0
    else:
        size_y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        axis_u, axis_v = axis_x * light.size, axis_y * size_y
        row.update(
            kind=LIGHT_AREA,
            axis_u=tuple(axis_u),
            axis_v=tuple(axis_v),
            shape=AREA_ELLIPSE if light.shape in _ELLIPTIC else AREA_RECTANGLE,
        )
        area = float(np.linalg.norm(axis_u) * np.linalg.norm(axis_v))
        if light.shape in _ELLIPTIC:
            area *= math.pi / 4.0
    power = light_color(light) * float(light.energy) * 2.0 ** float(light.exposure)
    if not light.normalize:
        power = power * area
    row["power"] = tuple(power)
    return row


def light_color(light) -> np.ndarray:
    """RGB colour of a light: its colour, tinted by the blackbody colour when used."""
    color = np.array(light.color[:3], np.float64)
    if getattr(light, "use_temperature", False):
        color = color * np.array(light.temperature_color[:3], np.float64)
    return color


def _warn_unsupported(light, warnings: list[str]) -> None:
    """Name the settings of ``light`` that this engine renders differently."""
    name = f"light '{light.name}'"
    if light.type == "AREA" and light.spread < math.pi - 1e-4:
        warnings.append(f"{name}: spread is not supported; rendered with 180 degrees")
    if light.type == "SPOT" and getattr(light, "use_square", False):
        warnings.append(f"{name}: square spot cones are not supported; rendered round")
    if not light.use_shadow:
        warnings.append(f"{name}: lights without shadows are not supported; it casts shadows")
    if light.use_nodes and light.node_tree is not None:
        warnings.append(f"{name}: light node trees are not supported; used colour x strength")
    factors = (light.diffuse_factor, light.specular_factor, light.transmission_factor)
    if any(abs(f - 1.0) > 1e-6 for f in factors):
        warnings.append(f"{name}: diffuse/specular/transmission factors are not supported; used 1")

