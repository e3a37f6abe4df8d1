"""The plain-numpy scene gpu_core renders, and its validation on entry.

Everything is a struct of arrays in world space, in Blender's units:
light power in watts (sun: W/m^2), emission as radiance (colour x strength),
world colour x strength as radiance. Positions are float64 so that a scene far
from the origin keeps its precision until the renderer recentres it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, fields

import numpy as np

from .errors import SceneError

LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, LIGHT_AREA = 0, 1, 2, 3
LIGHT_KIND_NAMES = {LIGHT_POINT: "point", LIGHT_SPOT: "spot", LIGHT_SUN: "sun", LIGHT_AREA: "area"}
AREA_RECTANGLE, AREA_ELLIPSE = 0, 1
CAMERA_PERSP, CAMERA_ORTHO = 0, 1


@dataclass
class Materials:
    """One row per material; a triangle's ``material_ids`` entry indexes it."""

    base_color: np.ndarray  # (M, 3) float32, linear
    metallic: np.ndarray  # (M,) float32
    roughness: np.ndarray  # (M,) float32
    transmission: np.ndarray  # (M,) float32
    ior: np.ndarray  # (M,) float32
    emission: np.ndarray  # (M, 3) float32, colour x strength (radiance)
    alpha: np.ndarray  # (M,) float32
    texture_id: np.ndarray  # (M,) int32 into Scene.textures, -1 for none
    names: list[str] = field(default_factory=list)

    @staticmethod
    def make(rows: list[dict]) -> "Materials":
        """Materials from dicts with the field names above (missing ones default)."""
        defaults = dict(
            base_color=(0.8, 0.8, 0.8),
            metallic=0.0,
            roughness=0.5,
            transmission=0.0,
            ior=1.5,
            emission=(0.0, 0.0, 0.0),
            alpha=1.0,
            texture_id=-1,
            name="",
        )
        rows = [{**defaults, **row} for row in rows] or [dict(defaults, name="default")]

        def column(key, dtype, width=None):
            shape = (len(rows), width) if width else (len(rows),)
            return np.array([row[key] for row in rows], dtype=dtype).reshape(shape)

        return Materials(
            base_color=column("base_color", np.float32, 3),
            metallic=column("metallic", np.float32),
            roughness=column("roughness", np.float32),
            transmission=column("transmission", np.float32),
            ior=column("ior", np.float32),
            emission=column("emission", np.float32, 3),
            alpha=column("alpha", np.float32),
            texture_id=column("texture_id", np.int32),
            names=[row["name"] for row in rows],
        )

    def __len__(self) -> int:
        return len(self.base_color)


@dataclass
class Lights:
    """One row per light (emissive meshes are triangles, not rows here)."""

    kind: np.ndarray  # (L,) int32, LIGHT_*
    position: np.ndarray  # (L, 3) float64
    direction: np.ndarray  # (L, 3) float32, unit, where the light points (its -Z)
    axis_u: np.ndarray  # (L, 3) float32, area light: full size along its X
    axis_v: np.ndarray  # (L, 3) float32, area light: full size along its Y
    power: np.ndarray  # (L, 3) float32, colour x watts (sun: colour x W/m^2)
    radius: np.ndarray  # (L,) float32, point/spot soft radius
    spot_angle: np.ndarray  # (L,) float32, full cone angle in radians
    spot_blend: np.ndarray  # (L,) float32, 0..1
    sun_angle: np.ndarray  # (L,) float32, angular diameter in radians
    shape: np.ndarray  # (L,) int32, AREA_RECTANGLE or AREA_ELLIPSE
    names: list[str] = field(default_factory=list)

    @staticmethod
    def make(rows: list[dict]) -> "Lights":
        """Lights from dicts with the field names above (missing ones default)."""
        defaults = dict(
            kind=LIGHT_POINT,
            position=(0.0, 0.0, 0.0),
            direction=(0.0, 0.0, -1.0),
            axis_u=(1.0, 0.0, 0.0),
            axis_v=(0.0, 1.0, 0.0),
            power=(0.0, 0.0, 0.0),
            radius=0.0,
            spot_angle=np.pi / 4,
            spot_blend=0.15,
            sun_angle=0.0,
            shape=AREA_RECTANGLE,
            name="",
        )
        rows = [{**defaults, **row} for row in rows]

        def column(key, dtype, width=None):
            shape = (len(rows), width) if width else (len(rows),)
            return np.array([row[key] for row in rows], dtype=dtype).reshape(shape)

        return Lights(
            kind=column("kind", np.int32),
            position=column("position", np.float64, 3),
            direction=column("direction", np.float32, 3),
            axis_u=column("axis_u", np.float32, 3),
            axis_v=column("axis_v", np.float32, 3),
            power=column("power", np.float32, 3),
            radius=column("radius", np.float32),
            spot_angle=column("spot_angle", np.float32),
            spot_blend=column("spot_blend", np.float32),
            sun_angle=column("sun_angle", np.float32),
            shape=column("shape", np.int32),
            names=[row["name"] for row in rows],
        )

    def __len__(self) -> int:
        return len(self.kind)

    def subset(self, keep: np.ndarray) -> "Lights":
        names = [n for n, k in zip(self.names, keep) if k] if self.names else []
        return Lights(
            **{
                name: getattr(self, name)[keep]
                for name in (
                    "kind position direction axis_u axis_v power radius "
                    "spot_angle spot_blend sun_angle shape"
                ).split()
            },
            names=names,
        )


@dataclass
class Camera:
    """A pinhole or orthographic camera and the pixels to render.

    ``window`` (x0, x1, y0, y1) is the image rectangle in camera space: on the
    plane z = -1 for a perspective camera (sensor fit and lens shift already
    applied), in scene units for an orthographic one. ``border`` (x0, y0, x1,
    y1) is the pixel window to render, x1/y1 exclusive; rows count from the
    bottom, as in Blender's render result.
    """

    matrix: np.ndarray  # (4, 4) float64, camera to world (camera looks down -Z)
    window: tuple[float, float, float, float]
    width: int
    height: int
    kind: int = CAMERA_PERSP
    clip_start: float = 0.1
    clip_end: float = 1000.0
    border: tuple[int, int, int, int] | None = None

    @property
    def pixel_window(self) -> tuple[int, int, int, int]:
        if self.border is None:
            return (0, 0, self.width, self.height)
        return self.border


@dataclass
class ValidationReport:
    """What validation dropped or repaired, for stats and warnings."""

    dropped_nonfinite_triangles: int = 0
    dropped_degenerate_triangles: int = 0
    repaired_material_ids: int = 0
    repaired_normals: int = 0
    dropped_lights: int = 0
    repaired_materials: int = 0
    messages: list[str] = field(default_factory=list)

    def as_stats(self) -> dict:
        return {
            "dropped_nonfinite_triangles": self.dropped_nonfinite_triangles,
            "dropped_degenerate_triangles": self.dropped_degenerate_triangles,
            "repaired_material_ids": self.repaired_material_ids,
            "repaired_normals": self.repaired_normals,
            "dropped_lights": self.dropped_lights,
            "repaired_materials": self.repaired_materials,
        }


@dataclass
class Scene:
    """Triangles (a soup), their materials, lights, world and camera."""

    triangles: np.ndarray  # (N, 3, 3) float64 world positions
    normals: np.ndarray  # (N, 3, 3) float32 corner normals (world, unit)
    uvs: np.ndarray  # (N, 3, 2) float32
    material_ids: np.ndarray  # (N,) int32
    materials: Materials
    lights: Lights
    camera: Camera
    world_color: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    textures: list[np.ndarray] = field(default_factory=list)  # (H, W, 4) float32, linear
    warnings: list[str] = field(default_factory=list)
    report: ValidationReport = field(default_factory=ValidationReport)

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) of triangles and positional lights; a unit box if empty."""
        points = [self.triangles.reshape(-1, 3)]
        positional = self.lights.kind != LIGHT_SUN
        points.append(self.lights.position[positional])
        pts = np.concatenate([p for p in points if len(p)], axis=0) if any(len(p) for p in points) else None
        if pts is None or len(pts) == 0:
            return np.full(3, -1.0), np.full(3, 1.0)
        return pts.min(axis=0), pts.max(axis=0)


def validate(scene: Scene) -> Scene:
    """Check and repair a scene in place-free fashion; returns a new Scene.

    Triangles with non-finite coordinates or zero area are dropped; material
    ids out of range point at an added default material; non-finite or zero
    corner normals are replaced by the face normal; lights with negative or
    non-finite power or position are dropped. Every repair is counted in
    ``scene.report`` and described in ``scene.warnings``. A camera that cannot
    produce an image raises SceneError.
    """
    report = ValidationReport()
    warnings = list(scene.warnings)
    _check_camera(scene.camera)

    tris = np.asarray(scene.triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(tris)
    normals = _shaped(scene.normals, (n, 3, 3), np.float32)
    uvs = _shaped(scene.uvs, (n, 3, 2), np.float32)
    mat_ids = _shaped(scene.material_ids, (n,), np.int32)

    finite = np.isfinite(tris).all(axis=(1, 2))
    report.dropped_nonfinite_triangles = int((~finite).sum())
    with np.errstate(invalid="ignore", over="ignore"):
        cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        longest = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max(axis=1)
        extent = np.abs(tris).max(axis=(1, 2))
        # zero area: a sliver thinner than 1e-12 of its length, or a cross
        # product no larger than the rounding of coordinates this far out
        noise = 64.0 * np.finfo(np.float64).eps * extent * longest
        degenerate = finite & ~(area2 > np.maximum(1e-12 * np.square(longest), noise))
    report.dropped_degenerate_triangles = int(degenerate.sum())
    keep = finite & ~degenerate
    tris, normals, uvs, mat_ids, cross = tris[keep], normals[keep], uvs[keep], mat_ids[keep], cross[keep]

    materials = scene.materials
    bad_ids = (mat_ids < 0) | (mat_ids >= len(materials))
    report.repaired_material_ids = int(bad_ids.sum())
    if report.repaired_material_ids:
        materials = _with_default_material(materials)
        mat_ids = np.where(bad_ids, len(materials) - 1, mat_ids).astype(np.int32)

    face_n = (cross / np.linalg.norm(cross, axis=1, keepdims=True)).astype(np.float32)
    normals64 = normals.astype(np.float64)  # float32 squares overflow above ~1e19
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.linalg.norm(normals64, axis=2)
    bad_normals = ~(np.isfinite(normals64).all(axis=2) & (length > 1e-12))
    report.repaired_normals = int(bad_normals.any(axis=1).sum())
    with np.errstate(invalid="ignore"):
        normals = np.where(bad_normals[..., None], face_n[:, None, :], normals64 / np.where(bad_normals, 1.0, length)[..., None])
    uvs = np.where(np.isfinite(uvs), uvs, 0.0).astype(np.float32)

    materials, repaired = _finite_materials(materials)
    report.repaired_materials = len(repaired)
    if repaired:
        warnings.append(f"material(s) with NaN/Inf or negative values repaired with defaults: {', '.join(repaired)}")

    lights = scene.lights
    good = np.isfinite(lights.power).all(axis=1) & (lights.power >= 0).all(axis=1)
    for name in ("position", "direction", "axis_u", "axis_v", "radius", "spot_angle", "spot_blend", "sun_angle"):
        values = getattr(lights, name)
        good &= np.isfinite(values).all(axis=tuple(range(1, values.ndim)))
    report.dropped_lights = int((~good).sum())
    if report.dropped_lights:
        names = [nm for nm, g in zip(lights.names, good) if not g]
        warnings.append(f"dropped {report.dropped_lights} light(s) with negative or invalid power/position: {', '.join(names) or 'unnamed'}")
        lights = lights.subset(good)

    if report.dropped_nonfinite_triangles:
        warnings.append(f"dropped {report.dropped_nonfinite_triangles} triangle(s) with NaN/Inf coordinates")
    if report.dropped_degenerate_triangles:
        warnings.append(f"dropped {report.dropped_degenerate_triangles} zero-area triangle(s)")
    if report.repaired_material_ids:
        warnings.append(f"{report.repaired_material_ids} triangle(s) had a material index out of range; used the default material")
    if report.repaired_normals:
        warnings.append(f"{report.repaired_normals} triangle(s) had invalid normals; used face normals")

    world = np.asarray(scene.world_color, np.float32).reshape(3)
    if not np.isfinite(world).all() or (world < 0).any():
        warnings.append("world colour was negative or not finite; used black")
        world = np.zeros(3, np.float32)

    report.messages = warnings
    return Scene(
        triangles=tris,
        normals=normals.astype(np.float32),
        uvs=uvs,
        material_ids=mat_ids.astype(np.int32),
        materials=materials,
        lights=lights,
        camera=scene.camera,
        world_color=world,
        textures=list(scene.textures),
        warnings=warnings,
        report=report,
    )


def _shaped(array, shape, dtype) -> np.ndarray:
    """``array`` as ``dtype`` with ``shape``; zeros if it is missing."""
    if array is None:
        return np.zeros(shape, dtype)
    out = np.asarray(array, dtype=dtype)
    if out.shape != shape:
        raise SceneError(f"scene array has shape {out.shape}, expected {shape}")
    return out


_MATERIAL_FIELDS = "base_color metallic roughness transmission ior emission alpha texture_id".split()


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


def scene_digest(scene: Scene) -> bytes:
    """A digest of everything but the camera: geometry, materials, lights,
    world and textures. Renders of scenes with the same digest can share a
    kd-tree and photon maps."""
    digest = hashlib.blake2b(digest_size=16)
    arrays = [scene.triangles, scene.normals, scene.uvs, scene.material_ids, scene.world_color, *scene.textures]
    arrays += [getattr(scene.materials, f.name) for f in fields(Materials) if f.name != "names"]
    arrays += [getattr(scene.lights, f.name) for f in fields(Lights) if f.name != "names"]
    for array in arrays:
        a = np.ascontiguousarray(array)
        digest.update(str((a.dtype, a.shape)).encode())
        digest.update(a.tobytes())
    return digest.digest()
