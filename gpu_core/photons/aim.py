"""Where a caustic path can begin: boxes around the triangles whose surface
can bounce light specularly, as photon tracing counts a bounce specular
(photon_trace.cl: a singular lobe, or a glossy one below
CAUSTIC_ROUGHNESS). A caustic photon whose first ray meets none of the
boxes hits nothing, or a surface that ends its caustic path at once with
nothing stored, so the caustic pass does not trace it: the map is the one
it would be, and only the photons that can make a caustic cost a ray
(Jensen's projection maps aim the photons instead, which changes the map).
"""

from __future__ import annotations

import numpy as np

from ..device.constants import CAUSTIC_ROUGHNESS
from ..scene.model import Scene, texture_channel

MAX_BOXES = 8  # boxes each caustic photon is tested against; more specular materials are merged into this many
MERGED_FIRST = 64  # boxes merged in order along the widest axis before the closest pairs are (many materials)
PAD = 1e-5  # boxes grow by this times the largest coordinate of their frame (rounding of vertices and rays)


def specular_rows(materials: np.ndarray, scene: Scene) -> np.ndarray:
    """Per row of the device's material table (MATERIAL_DTYPE), whether a
    shading event there can bounce light specularly: a metal, glass or
    specular-layer lobe whose roughness can fall below CAUSTIC_ROUGHNESS
    (the lowest texel of its roughness texture where one is bound), on the
    row or on a later row of its mix."""
    roughness = materials["roughness"].astype(np.float32)
    metallic = materials["metallic"].astype(np.float32)
    for column, values, extreme in (("roughness_texture", roughness, np.min), ("metallic_texture", metallic, np.max)):
        channels = materials[column.replace("texture", "channel")]
        for row in np.flatnonzero(materials[column] >= 0):
            texels = texture_channel(scene.textures[materials[column][row]], int(channels[row]))
            values[row] = np.clip(extreme(np.nan_to_num(texels, nan=0.0)), 0.0, 1.0)
    layer = np.abs(materials["specular_tint"][:, 3] - 1.0) >= 1e-5  # a dielectric specular layer (bsdf.h)
    lobes = (metallic > 0) | (materials["transmission"] > 0) | layer
    can = (roughness < np.float32(CAUSTIC_ROUGHNESS)) & lobes
    following = materials["mix_next"]
    for row in range(len(can) - 1, -1, -1):  # a chain runs forward: later rows are settled first
        if following[row] > row:
            can[row] |= can[following[row]]
    return can


def caustic_boxes(scene: Scene, materials: np.ndarray, max_boxes: int = MAX_BOXES) -> np.ndarray:
    """Boxes (B, 2, 3: low and high corners, world frame, float64) holding
    every triangle whose material can bounce light specularly: one per
    such material, merged down to ``max_boxes``. (0, 2, 3) when none."""
    rows = specular_rows(materials, scene)
    ids = np.asarray(scene.material_ids)
    chosen = rows[np.clip(ids, 0, max(len(rows) - 1, 0))] if len(rows) else np.zeros(len(ids), bool)
    if not chosen.any():
        return np.zeros((0, 2, 3))
    groups = ids[chosen]
    order = np.argsort(groups, kind="stable")
    tris = scene.triangles[np.flatnonzero(chosen)[order]]
    starts = np.flatnonzero(np.r_[True, np.diff(groups[order]) != 0])
    corners = tris[:, 0], tris[:, 1], tris[:, 2]  # per corner, not numpy's slow reduction over rows of three
    lo = np.minimum.reduceat(np.minimum(np.minimum(*corners[:2]), corners[2]), starts)
    hi = np.maximum.reduceat(np.maximum(np.maximum(*corners[:2]), corners[2]), starts)
    return _merged(np.stack([lo, hi], axis=1), max_boxes)


def _merged(boxes: np.ndarray, max_boxes: int) -> np.ndarray:
    """At most ``max_boxes`` boxes covering ``boxes``: first neighbours
    along the widest axis joined down to MERGED_FIRST, then repeatedly the
    pair whose union has the smallest surface area."""
    if len(boxes) > MERGED_FIRST:
        axis = int(np.argmax(boxes[:, 1].max(axis=0) - boxes[:, 0].min(axis=0)))
        chunks = np.array_split(np.argsort(boxes[:, :, axis].mean(axis=1)), MERGED_FIRST)
        boxes = np.stack([_union(boxes[chunk]) for chunk in chunks])
    while len(boxes) > max_boxes:
        lo = np.minimum(boxes[:, None, 0], boxes[None, :, 0])
        hi = np.maximum(boxes[:, None, 1], boxes[None, :, 1])
        d = hi - lo
        area = d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]
        area[np.diag_indices(len(boxes))] = np.inf
        i, j = np.unravel_index(np.argmin(area), area.shape)
        keep = np.ones(len(boxes), bool)
        keep[j] = False
        boxes[i] = _union(boxes[[i, j]])
        boxes = boxes[keep]
    return boxes


def _union(boxes: np.ndarray) -> np.ndarray:
    return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


def device_boxes(boxes: np.ndarray, center: np.ndarray) -> np.ndarray:
    """World boxes in the device frame (positions minus ``center``) as the
    kernel reads them: float4 low and high corners in turn, grown by PAD
    times the frame's largest coordinate and rounded outwards."""
    local = np.asarray(boxes, np.float64) - np.asarray(center, np.float64)
    pad = PAD * max(float(np.abs(local).max(initial=0.0)), 1e-30)
    lo = np.nextafter((local[:, 0] - pad).astype(np.float32), np.float32(-np.inf))
    hi = np.nextafter((local[:, 1] + pad).astype(np.float32), np.float32(np.inf))
    out = np.zeros((2 * len(boxes), 4), np.float32)
    out[0::2, :3], out[1::2, :3] = lo, hi
    return out
