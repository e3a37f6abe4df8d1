"""Depsgraph to gpu_core Scene: meshes, instances, materials, lights, world, camera.

Reads only evaluated data and never writes to the user's scene.
"""

from __future__ import annotations

import numpy as np

from gpu_core.scene import Lights, Materials, Scene

from .camera import scene_camera
from .lights import light_row
from .materials import MaterialTable
from .mesh import GEOMETRY_TYPES, MeshCache, transform
from .world import world_radiance


class ExportError(Exception):
    """The scene cannot be exported (e.g. no camera); the message says why."""


def export_scene(depsgraph, camera=None, should_stop=None) -> Scene:
    """A gpu_core Scene of everything visible in ``depsgraph``.

    ``camera`` replaces the scene camera (the viewport passes its view);
    ``should_stop`` is polled every few thousand instances.
    """
    scene = depsgraph.scene
    warnings: list[str] = []
    if camera is None:
        cam_obj = scene.camera
        if cam_obj is None:
            raise ExportError("the scene has no active camera; add one or set Scene > Camera")
        try:
            camera = scene_camera(depsgraph, cam_obj.evaluated_get(depsgraph))
        except ValueError as err:
            raise ExportError(str(err)) from err

    table = MaterialTable()
    meshes = MeshCache()
    parts = {"tris": [], "normals": [], "uvs": [], "ids": []}
    light_rows = []
    skipped_types: set[str] = set()
    for number, inst in enumerate(depsgraph.object_instances):
        if should_stop is not None and number % 2000 == 1999 and should_stop():
            break
        obj = inst.object
        if obj.type == "LIGHT":
            row = light_row(obj.data, inst.matrix_world)
            if row is None:
                skipped_types.add(f"light type {obj.data.type}")
            else:
                light_rows.append(row)
            continue
        if obj.type not in GEOMETRY_TYPES:
            if obj.type not in ("CAMERA", "EMPTY", "ARMATURE", "LIGHT_PROBE", "SPEAKER"):
                skipped_types.add(obj.type)
            continue
        if inst.is_instance and not inst.show_self and not inst.show_particles:
            continue
        arrays = meshes.local_arrays(obj)
        if arrays is None:
            continue
        positions, normals, uvs, slots, mesh_materials = arrays
        world, world_n, world_uv = transform(positions, normals, uvs, np.array(inst.matrix_world))
        slot_rows = _slot_rows(obj, mesh_materials, table)
        parts["tris"].append(world)
        parts["normals"].append(world_n)
        parts["uvs"].append(world_uv)
        parts["ids"].append(slot_rows[np.clip(slots, 0, len(slot_rows) - 1)])

    for kind in sorted(skipped_types):
        warnings.append(f"{kind} objects are not supported and were skipped")
    warnings.extend(table.warnings)
    count = sum(len(t) for t in parts["tris"])
    return Scene(
        triangles=np.concatenate(parts["tris"]) if count else np.zeros((0, 3, 3)),
        normals=np.concatenate(parts["normals"]) if count else np.zeros((0, 3, 3), np.float32),
        uvs=np.concatenate(parts["uvs"]) if count else np.zeros((0, 3, 2), np.float32),
        material_ids=np.concatenate(parts["ids"]).astype(np.int32) if count else np.zeros(0, np.int32),
        materials=Materials.make(table.rows),
        lights=Lights.make(light_rows),
        camera=camera,
        world_color=world_radiance(scene.world, warnings),
        textures=table.textures,
        warnings=warnings,
    )


def _slot_rows(obj, mesh_materials, table: MaterialTable) -> np.ndarray:
    """Material row of each material slot of ``obj`` (object-linked slots win)."""
    rows = []
    slots = obj.material_slots
    count = max(len(slots), len(mesh_materials), 1)
    for i in range(count):
        material = None
        if i < len(slots) and slots[i].material is not None:
            material = slots[i].material
        elif i < len(mesh_materials):
            material = mesh_materials[i]
        rows.append(table.index(material))
    return np.asarray(rows, np.int32)
