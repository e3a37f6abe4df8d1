"""Validation of a scene on entry: what cannot be rendered is dropped or
repaired, counted and described, never raised (but for a camera that cannot
make an image)."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from ..device.layout import rows_differ
from ..errors import SceneError
from .model import Camera, Lights, Materials, Scene, ValidationReport


def validate(scene: Scene, memo: "GeometryMemo | None" = None) -> Scene:
    """Check and repair a scene in place-free fashion; returns a new Scene.

    Triangles with non-finite coordinates or zero area are dropped; material
    ids out of range point at an added default material; non-finite or zero
    corner normals are replaced by the face normal; lights with negative or
    non-finite power or position are dropped. Every repair is counted in
    ``scene.report`` and described in ``scene.warnings``. A camera that cannot
    produce an image raises SceneError. ``memo`` keeps the checked geometry
    of the last scene it saw: a scene with the very same geometry arrays
    (callers put new arrays in a scene for what changed and never write into
    one already rendered) is not checked again.
    """
    report = ValidationReport()
    warnings = list(scene.warnings)
    _check_camera(scene.camera)
    tris, normals, uvs, mat_ids, tangents, needs_default = (memo or GeometryMemo()).geometry(scene, report)
    materials = _with_default_material(scene.materials) if needs_default else scene.materials
    materials, repaired = _finite_materials(materials)
    report.repaired_materials = len(repaired)
    if repaired:
        warnings.append(f"material(s) with NaN/Inf or negative values repaired with defaults: {', '.join(repaired)}")
    lights = _valid_lights(scene.lights, report, warnings)
    warnings += _geometry_warnings(report)
    world = np.asarray(scene.world_color, np.float32).reshape(3)
    if not np.isfinite(world).all() or (world < 0).any():
        warnings.append("world colour was negative or not finite; used black")
        world = np.zeros(3, np.float32)
    report.messages = warnings
    return Scene(triangles=tris, normals=normals, uvs=uvs, material_ids=mat_ids,
                 materials=materials, lights=lights, camera=scene.camera, world_color=world,
                 textures=list(scene.textures), texture_closest=list(scene.texture_closest), tangents=tangents,
                 warnings=warnings, report=report)


_GEOMETRY_COUNTS = ("dropped_nonfinite_triangles", "dropped_degenerate_triangles", "repaired_material_ids",
                    "repaired_normals")


class GeometryMemo:
    """The checked geometry of the last scene validated with it, and the
    repairs counted, keyed by its arrays (by identity) and material count.
    A scene whose arrays are new but of the same shapes (an object moved or
    reshaped in place) has only its rows that differ checked, where neither
    the last scene nor those rows needed a repair; an array of the last
    scene's that it shares, or whose rows are all equal to them, gives its
    checked array of the last time, the very same object (the upload and
    the plan's memos then know it unchanged)."""

    def __init__(self):
        self._key: tuple = ()
        self._result: tuple = ()

    def geometry(self, scene: Scene, report: ValidationReport) -> tuple:
        """(triangles, normals, uvs, material ids, corner tangents, whether a
        default material is needed) of ``scene``, its repairs counted in ``report``."""
        key = (scene.triangles, scene.normals, scene.uvs, scene.material_ids, scene.tangents, len(scene.materials))
        if not (len(key) == len(self._key) and all(a is b for a, b in zip(key[:5], self._key[:5]))
                and key[5] == self._key[5]):
            changed = self._changed_rows(key)
            result = self._patched(scene, *changed) if changed is not None else None
            self._key, self._result = key, result or _checked_geometry(scene)
        *geometry, counts = self._result
        for name, value in counts.items():
            setattr(report, name, value)
        return tuple(geometry)

    def _changed_rows(self, key: tuple) -> tuple[np.ndarray, list[bool]] | None:
        """The triangle rows where ``key``'s arrays differ from the last
        scene's and, per array, whether any of its rows does, when only
        those rows need checking: the last scene needed no repair, and
        every array has its shape and type."""
        if not self._result or any(self._result[-1].values()) or self._result[5] or key[5] != self._key[5]:
            return None
        arrays = [np.asarray(a) for a in key[:5]]
        if any(a.ndim == 0 or a.shape != b.shape or a.dtype != b.dtype for a, b in zip(arrays, self._key[:5])):
            return None
        changed, differs = np.zeros(len(arrays[0]), bool), []
        for new, old in zip(arrays, self._key[:5]):
            rows = rows_differ(new, old) if new.size and new is not old else None
            differs.append(rows is not None and bool(rows.any()))
            if differs[-1]:
                changed |= rows
        return np.flatnonzero(changed), differs

    def _patched(self, scene: Scene, rows: np.ndarray, differs: list[bool]) -> tuple | None:
        """The last result with ``rows`` checked again and written into
        copies of the arrays that ``differs`` names, or None where one of
        them needs a repair (the whole scene is checked)."""
        has_tangents = np.size(scene.tangents) > 0
        part = replace(scene, triangles=scene.triangles[rows], normals=scene.normals[rows], uvs=scene.uvs[rows],
                       material_ids=scene.material_ids[rows],
                       tangents=scene.tangents[rows] if has_tangents else scene.tangents)
        *checked, needs_default, counts = _checked_geometry(part)
        if needs_default or any(counts.values()):
            return None
        geometry = []
        for whole, rows_checked, differ in zip(self._result[:5], checked, differs):
            if differ:
                whole = whole.copy()
                whole[rows] = rows_checked
            geometry.append(whole)
        return (*geometry, False, counts)


def _checked_geometry(scene: Scene) -> tuple:
    """(triangles, normals, uvs, material ids, corner tangents, whether a
    default material is needed, the repairs counted) of ``scene``."""
    counted = ValidationReport()
    tris, normals, uvs, mat_ids, tangents, cross = _valid_triangles(scene, counted)
    materials, mat_ids = _valid_material_ids(scene.materials, mat_ids, counted)
    normals = _repaired_normals(normals, cross, counted).astype(np.float32, copy=False)
    uvs = np.where(np.isfinite(uvs), uvs, 0.0).astype(np.float32)
    # a corner tangent that is not finite is no tangent (the triangle's UVs give one)
    tangents = np.where(np.isfinite(tangents).all(axis=-1, keepdims=True), tangents, 0.0).astype(np.float32)
    counts = {name: getattr(counted, name) for name in _GEOMETRY_COUNTS}
    return (tris, normals, uvs, mat_ids.astype(np.int32), tangents, materials is not scene.materials, counts)


def _valid_triangles(scene: Scene, report: ValidationReport) -> tuple:
    """The triangles with finite corners and some area, with their normals,
    uvs, material ids, corner tangents (none, or one row per triangle) and
    (unnormalised) face normals."""
    tris = np.asarray(scene.triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(tris)
    normals = _shaped(scene.normals, (n, 3, 3), np.float32)
    uvs = _shaped(scene.uvs, (n, 3, 2), np.float32)
    mat_ids = _shaped(scene.material_ids, (n,), np.int32)
    given = scene.tangents
    tangents = (np.zeros((0, 3, 4), np.float32) if given is None or np.size(given) == 0
                else _shaped(given, (n, 3, 4), np.float32))
    # per triangle only where some coordinate is not finite (numpy reduces short rows slowly)
    finite = np.isfinite(tris).reshape(n, 9).all(axis=1) if not np.isfinite(tris).all() else np.ones(n, bool)
    report.dropped_nonfinite_triangles = int((~finite).sum())
    # column by column (numpy reduces short rows slowly): the cross product
    # of two edges, the longest edge and the largest coordinate
    with np.errstate(invalid="ignore", over="ignore"):
        e1, e2, e3 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0], tris[:, 2] - tris[:, 1]
        cross = np.empty((n, 3))
        for k in range(3):
            i, j = (k + 1) % 3, (k + 2) % 3
            cross[:, k] = e1[:, i] * e2[:, j] - e1[:, j] * e2[:, i]
        area2 = np.sqrt(_squared_lengths(cross))
        longest = np.sqrt(np.maximum(np.maximum(_squared_lengths(e1), _squared_lengths(e2)), _squared_lengths(e3)))
        extent = np.maximum.reduce(np.abs(tris.reshape(n, 9)).T)
        # zero area: a sliver thinner than 1e-12 of its length, or a cross
        # product no larger than the rounding of coordinates this far out
        noise = 64.0 * np.finfo(np.float64).eps * extent * longest
        degenerate = finite & ~(area2 > np.maximum(1e-12 * np.square(longest), noise))
    report.dropped_degenerate_triangles = int(degenerate.sum())
    keep = finite & ~degenerate
    if keep.all():  # nothing dropped: no copies
        return tris, normals, uvs, mat_ids, tangents, cross
    return tris[keep], normals[keep], uvs[keep], mat_ids[keep], tangents[keep] if len(tangents) else tangents, cross[keep]


def _valid_material_ids(materials: Materials, mat_ids: np.ndarray, report: ValidationReport):
    """Material ids out of range point at an added default material."""
    bad_ids = (mat_ids < 0) | (mat_ids >= len(materials))
    report.repaired_material_ids = int(bad_ids.sum())
    if report.repaired_material_ids:
        materials = _with_default_material(materials)
        mat_ids = np.where(bad_ids, len(materials) - 1, mat_ids).astype(np.int32)
    return materials, mat_ids


def _repaired_normals(normals: np.ndarray, cross: np.ndarray, report: ValidationReport) -> np.ndarray:
    """Unit corner normals; non-finite or zero ones become the face normal."""
    with np.errstate(invalid="ignore", over="ignore"):
        unit = np.abs(_squared_lengths(normals.reshape(-1, 3)) - 1.0) < 1e-6  # NaN and Inf compare False
    if unit.all():  # the exporter's normals (the float32 squares near 1 do not overflow)
        return normals
    normals64 = normals.astype(np.float64)  # float32 squares overflow above ~1e19
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.sqrt(_squared_lengths(normals64.reshape(-1, 3))).reshape(normals.shape[:2])
    # a non-finite component makes the length NaN or infinite
    bad_normals = ~(np.isfinite(length) & (length > 1e-12))
    report.repaired_normals = int(bad_normals.any(axis=1).sum())
    with np.errstate(invalid="ignore"):
        scaled = normals64 / np.where(bad_normals, 1.0, length)[..., None]
    if not report.repaired_normals:
        return scaled
    face_n = cross / np.sqrt(_squared_lengths(cross))[:, None]
    return np.where(bad_normals[..., None], face_n[:, None, :], scaled)


def _squared_lengths(vectors: np.ndarray) -> np.ndarray:
    """|v|^2 of (N, 3) vectors, column by column."""
    return vectors[:, 0] * vectors[:, 0] + vectors[:, 1] * vectors[:, 1] + vectors[:, 2] * vectors[:, 2]


def _valid_lights(lights: Lights, report: ValidationReport, warnings: list[str]) -> Lights:
    """The lights with finite, non-negative power and finite shape values."""
    good = np.isfinite(lights.power).all(axis=1) & (lights.power >= 0).all(axis=1)
    for name in ("position", "direction", "axis_u", "axis_v", "radius", "spot_angle", "spot_blend", "sun_angle"):
        values = getattr(lights, name)
        good &= np.isfinite(values).all(axis=tuple(range(1, values.ndim)))
    report.dropped_lights = int((~good).sum())
    if not report.dropped_lights:
        return lights
    names = [nm for nm, g in zip(lights.names, good) if not g]
    warnings.append(f"dropped {report.dropped_lights} light(s) with negative or invalid power/position: "
                    f"{', '.join(names) or 'unnamed'}")
    return lights.subset(good)


def _geometry_warnings(report: ValidationReport) -> list[str]:
    """What the triangle repairs were, in words."""
    counts = [
        (report.dropped_nonfinite_triangles, "dropped {} triangle(s) with NaN/Inf coordinates"),
        (report.dropped_degenerate_triangles, "dropped {} zero-area triangle(s)"),
        (report.repaired_material_ids, "{} triangle(s) had a material index out of range; used the default material"),
        (report.repaired_normals, "{} triangle(s) had invalid normals; used face normals"),
    ]
    return [text.format(count) for count, text in counts if count]


def _shaped(array, shape, dtype) -> np.ndarray:
    """``array`` as ``dtype`` with ``shape``; zeros if it is missing."""
    if array is None:
        return np.zeros(shape, dtype)
    out = np.asarray(array, dtype=dtype)
    if out.shape != shape:
        raise SceneError(f"scene array has shape {out.shape}, expected {shape}")
    return out


_MATERIAL_FIELDS = [f.name for f in fields(Materials) if f.name != "names"]


def _finite_materials(materials: Materials) -> tuple[Materials, list[str]]:
    """Materials with NaN/Inf values set to the defaults and negative emission to 0,
    and the names of the rows that changed (the input itself if none did)."""
    default = Materials.make([{}])
    columns, changed = {}, np.zeros(len(materials), bool)
    for name in _MATERIAL_FIELDS:
        values = np.asarray(getattr(materials, name))
        bad = ~np.isfinite(values) if values.dtype.kind == "f" else np.zeros(values.shape, bool)
        if name == "emission":
            bad |= np.isfinite(values) & (values < 0)
            fixed = np.where(bad, 0.0, values).astype(values.dtype)
        else:
            fixed = np.where(bad, getattr(default, name)[0], values).astype(values.dtype)
        changed |= bad.reshape(len(values), -1).any(axis=1)
        columns[name] = fixed
    if not changed.any():
        return materials, []
    names = [materials.names[i] if i < len(materials.names) and materials.names[i] else f"#{i}" for i in np.nonzero(changed)[0]]
    return Materials(**columns, names=list(materials.names)), names


def _with_default_material(materials: Materials) -> Materials:
    default = Materials.make([{"name": "gpugi-default"}])
    return Materials(
        **{
            name: np.concatenate([getattr(materials, name), getattr(default, name)])
            for name in _MATERIAL_FIELDS
        },
        names=list(materials.names) + default.names,
    )


def _check_camera(camera: Camera) -> None:
    m = np.asarray(camera.matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError("camera matrix is not a finite 4x4 matrix")
    if abs(np.linalg.det(m[:3, :3])) < 1e-20:
        raise SceneError("camera matrix is singular (zero scale?)")
    if camera.width < 1 or camera.height < 1:
        raise SceneError(f"image size {camera.width}x{camera.height} is empty")
    x0, x1, y0, y1 = camera.window
    if not (np.isfinite(camera.window).all() and x1 > x0 and y1 > y0):
        raise SceneError(f"camera window {camera.window} is empty or not finite")
    bx0, by0, bx1, by1 = camera.pixel_window
    if not (0 <= bx0 < bx1 <= camera.width and 0 <= by0 < by1 <= camera.height):
        raise SceneError(f"render border {camera.pixel_window} lies outside the {camera.width}x{camera.height} image")
    if not (0 <= camera.clip_start < camera.clip_end):
        raise SceneError(f"camera clipping {camera.clip_start}..{camera.clip_end} is empty")



