"""Blender lights to gpu_core light rows (power in watts, sun in W/m^2)."""

from __future__ import annotations

import numpy as np

from gpu_core.scene import AREA_ELLIPSE, AREA_RECTANGLE, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN


def light_row(light, matrix) -> dict | None:
    """A row for gpu_core.scene.Lights.make, or None for an unsupported type."""
    m = np.asarray(matrix, np.float64)
    position = m[:3, 3]
    axis_x, axis_y, axis_z = m[:3, 0], m[:3, 1], m[:3, 2]
    direction = -axis_z / max(np.linalg.norm(axis_z), 1e-30)
    color = np.asarray(light.color[:3], np.float64)
    row = {"name": light.name, "position": tuple(position), "direction": tuple(direction)}
    if light.type == "POINT":
        row.update(kind=LIGHT_POINT, power=tuple(color * light.energy), radius=light.shadow_soft_size)
    elif light.type == "SPOT":
        row.update(
            kind=LIGHT_SPOT,
            power=tuple(color * light.energy),
            radius=light.shadow_soft_size,
            spot_angle=light.spot_size,
            spot_blend=light.spot_blend,
        )
    elif light.type == "SUN":
        row.update(kind=LIGHT_SUN, power=tuple(color * light.energy), sun_angle=light.angle)
    elif light.type == "AREA":
        size_x = light.size
        size_y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        row.update(
            kind=LIGHT_AREA,
            power=tuple(color * light.energy),
            axis_u=tuple(axis_x * size_x),
            axis_v=tuple(axis_y * size_y),
            shape=AREA_ELLIPSE if light.shape in ("DISK", "ELLIPSE") else AREA_RECTANGLE,
        )
    else:
        return None
    return row
