"""Depsgraph to gpu_core Scene: meshes, instances, materials, lights, world, camera.

Reads only evaluated data and never writes to the user's scene.
"""

from __future__ import annotations

import numpy as np

from gpu_core.errors import GpuGiError
from gpu_core.scene import Lights, Materials, Scene

from .camera import CameraError, scene_camera
from .lights import light_row
from .materials import MaterialTable
from .mesh import GEOMETRY_TYPES, MeshCache, transform
from .world import world_radiance

# object types that never render anything by themselves
_SILENT_TYPES = {"CAMERA", "EMPTY", "ARMATURE", "LIGHT_PROBE", "SPEAKER", "LATTICE"}
# instances between two polls of should_stop
_POLL_EVERY = 2000
# per-object ray visibility switches (Object > Visibility) this engine does not honour
_RAY_VISIBILITY = ("visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission", "visible_shadow")


class ExportError(GpuGiError):
    """The scene cannot be exported (e.g. no camera); the message says why."""


def export_scene(depsgraph, camera=None, camera_object=None, should_stop=None) -> Scene:
    """A gpu_core Scene of everything ``depsgraph`` renders.

    ``camera`` (a gpu_core Camera) replaces the render camera, as the viewport
    does; otherwise ``camera_object`` or the scene's camera is used.
    ``should_stop`` is polled every few thousand instances; when it answers
    True the export ends early and the caller is expected to cancel.
    """
    scene = depsgraph.scene
    warnings: list[str] = []
    if camera is None:
        camera = _render_camera(depsgraph, camera_object or scene.camera, warnings)

    table = MaterialTable()
    meshes = MeshCache()
    parts: dict[str, list] = {"tris": [], "normals": [], "uvs": [], "ids": []}
    light_rows = []
    skipped_types: set[str] = set()
    checked: set[str] = set()
    for number, inst in enumerate(depsgraph.object_instances):
        if should_stop is not None and number % _POLL_EVERY == _POLL_EVERY - 1 and should_stop():
            break
        if not inst.show_self:
            continue  # an instancer hidden in renders (e.g. "Show Instancer: Render" off)
        obj = inst.object
        if obj.type == "LIGHT":
            row = light_row(obj.data, inst.matrix_world, warnings)
            if row is not None:
                light_rows.append(row)
            continue
        if obj.type not in GEOMETRY_TYPES:
            if obj.type not in _SILENT_TYPES:
                skipped_types.add(obj.type)
            continue
        local = meshes.local_mesh(obj)
        if local is None:
            continue
        if obj.name_full not in checked:
            checked.add(obj.name_full)
            _warn_object_settings(obj, warnings)
        world, normals, uvs = transform(local, inst.matrix_world)
        slot_rows = _slot_rows(obj, local.materials, table)
        parts["tris"].append(world)
        parts["normals"].append(normals)
        parts["uvs"].append(uvs)
        parts["ids"].append(slot_rows[np.clip(local.slots, 0, len(slot_rows) - 1)])

    warnings.extend(f"{kind} objects are not supported and were skipped" for kind in sorted(skipped_types))
    warnings.extend(table.warnings)
    world_color = world_radiance(scene.world, warnings)
    count = sum(len(t) for t in parts["tris"])
    return Scene(
        triangles=np.concatenate(parts["tris"]) if count else np.zeros((0, 3, 3)),
        normals=np.concatenate(parts["normals"]) if count else np.zeros((0, 3, 3), np.float32),
        uvs=np.concatenate(parts["uvs"]) if count else np.zeros((0, 3, 2), np.float32),
        material_ids=np.concatenate(parts["ids"]).astype(np.int32) if count else np.zeros(0, np.int32),
        materials=Materials.make(table.rows),
        lights=Lights.make(light_rows),
        camera=camera,
        world_color=world_color,
        textures=table.textures,
        warnings=list(dict.fromkeys(warnings)),
    )


def _render_camera(depsgraph, camera_object, warnings: list[str]):
    """The gpu_core camera of the render camera object, or ExportError."""
    if camera_object is None:
        raise ExportError("the scene has no active camera; add one or set Scene > Camera")
    if camera_object.type != "CAMERA":
        raise ExportError(f"the active camera '{camera_object.name}' is not a camera object")
    try:
        return scene_camera(depsgraph.scene, camera_object.evaluated_get(depsgraph), warnings)
    except CameraError as err:
        raise ExportError(str(err)) from err


def _warn_object_settings(obj, warnings: list[str]) -> None:
    """Name the object settings this engine renders as if they were off."""
    hidden = [name[len("visible_"):] for name in _RAY_VISIBILITY if not getattr(obj, name, True)]
    if hidden:
        warnings.append(f"object '{obj.name}': hiding it from {', '.join(hidden)} rays is not supported; "
                        "it is seen by every ray")
    if getattr(obj, "is_holdout", False) or getattr(obj, "is_shadow_catcher", False):
        warnings.append(f"object '{obj.name}': holdout and shadow catcher are not supported; rendered as a surface")


def _slot_rows(obj, mesh_materials: list, table: MaterialTable) -> np.ndarray:
    """Material row of each material slot of ``obj``; meshes without slots
    (geometry-nodes instances) use their own material list."""
    slots = obj.material_slots
    rows = []
    for i in range(max(len(slots), len(mesh_materials), 1)):
        if i < len(slots):
            material = slots[i].material
        else:
            material = mesh_materials[i] if i < len(mesh_materials) else None
        rows.append(table.index(material))
    return np.asarray(rows, np.int32)
