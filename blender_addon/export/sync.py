"""The exported scene kept across edits: what the viewport syncs after each one.

Blender says what an edit touched in ``depsgraph.updates`` (an object's
geometry, transform or shading; a material, light, world or image
datablock). ``SceneSync`` keeps, from one edit to the next, each object's
triangulated local mesh, each instance's world-space arrays, the material
table and the images' pixels, and exports again only what an update
invalidates: a moved object is transformed again, an edited mesh
triangulated again, an edited material exported again in its row (an
edited image reads every material again, other images' pixels kept).
Lights and the world are read at every sync (a few values each). The sync
names the scene parts that changed (gpu_core's PARTS), so the renderer
re-uploads only those and skips hashing the rest.

A one-shot export (F12, ``blender -b``) is a sync with nothing kept.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields

import numpy as np

from gpu_core.scene import Lights, Materials, Scene

from .lights import light_row
from .materials import MaterialTable
from .mesh import GEOMETRY_TYPES, LocalMesh, MeshCache, radial_tangents, transform
from .world import world_radiance

# object types that never render anything by themselves
SILENT_TYPES = {"CAMERA", "EMPTY", "ARMATURE", "LIGHT_PROBE", "SPEAKER", "LATTICE"}
# instances between two polls of should_stop
_POLL_EVERY = 2000
# per-object ray visibility switches (Object > Visibility) this engine does not honour
_RAY_VISIBILITY = ("visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission", "visible_shadow")


@dataclass(frozen=True)
class Update:
    """One entry of ``depsgraph.updates``, read at once (the ID it names is
    only valid during the update)."""

    kind: str  # "object", "material", "node_tree", "image", "texture", "light", "world", "scene", "data", "other"
    name: str
    geometry: bool = False
    transform: bool = False
    shading: bool = False


def read_updates(depsgraph) -> list[Update]:
    """The depsgraph's updates since the last evaluation, as ``Update`` records."""
    import bpy

    kinds = (("object", bpy.types.Object), ("material", bpy.types.Material), ("node_tree", bpy.types.NodeTree),
             ("image", bpy.types.Image), ("texture", bpy.types.Texture), ("light", bpy.types.Light),
             ("world", bpy.types.World), ("scene", bpy.types.Scene), ("data", bpy.types.ID))
    records = []
    for update in depsgraph.updates:
        datablock = update.id
        kind = next((name for name, cls in kinds if isinstance(datablock, cls)), "other")
        records.append(Update(kind, getattr(datablock, "name_full", ""), update.is_updated_geometry,
                              update.is_updated_transform, update.is_updated_shading))
    return records


@dataclass
class _Instance:
    """One instance's exported arrays and what they were made from."""

    local: LocalMesh
    matrix: bytes
    slot_rows: bytes
    tangent_kinds: dict  # material row -> the tangent it reads (MaterialTable.tangents_of)
    world: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    tangents: np.ndarray | None
    ids: np.ndarray


@dataclass
class SyncStats:
    """What one sync exported (the viewport's stats print it)."""

    meshes_triangulated: int = 0
    instances_transformed: int = 0
    materials_exported: int = 0  # materials read from Blender (the edited ones after an edit)
    edits: set = field(default_factory=set)
    ms: float = 0.0

    def as_dict(self) -> dict:
        return {"meshes_triangulated": self.meshes_triangulated, "instances_transformed": self.instances_transformed,
                "materials_exported": self.materials_exported, "edits": sorted(self.edits),
                "main_thread_ms": round(self.ms, 2)}


class SceneSync:
    """A depsgraph's scene, exported once and then synced edit by edit."""

    def __init__(self):
        self._meshes = MeshCache()
        self._instances: dict[tuple, _Instance] = {}
        self._pixels: dict = {}  # image name -> linear pixels, kept until the image is edited
        self._table: MaterialTable | None = None
        self._scene: Scene | None = None
        self.stats = SyncStats()

    def export(self, depsgraph, camera, updates: list[Update] | None = None, should_stop=None) -> tuple[Scene, set]:
        """The scene of ``depsgraph`` seen by ``camera`` (a gpu_core Camera)
        and the parts that changed since the last export (all of them the
        first time). ``updates``: the edits since the last export (None: not
        known, everything is exported again). ``should_stop`` is polled every
        few thousand instances; when it answers True the export ends early
        and the caller is expected to cancel."""
        began = time.perf_counter()
        self.stats = SyncStats()
        self._invalidate(updates)
        warnings: list[str] = []
        table = self._material_table()
        triangulated, exported = self._meshes.triangulated, table.exported
        instances, light_rows, order = {}, [], []
        skipped_types: set[str] = set()
        checked: set[str] = set()
        for number, inst in enumerate(depsgraph.object_instances):
            if should_stop is not None and number % _POLL_EVERY == _POLL_EVERY - 1 and should_stop():
                break
            if not inst.show_self:
                continue  # an instancer hidden in renders (e.g. "Show Instancer: Render" off)
            obj = _shown_object(inst)
            if obj.type == "LIGHT":
                row = light_row(obj.data, inst.matrix_world, warnings)
                if row is not None:
                    light_rows.append(row)
                continue
            if obj.type not in GEOMETRY_TYPES:
                if obj.type not in SILENT_TYPES:
                    skipped_types.add(obj.type)
                continue
            local = self._meshes.local_mesh(obj)
            if local is None:
                continue
            if obj.name_full not in checked:
                checked.add(obj.name_full)
                _warn_object_settings(obj, warnings)
            key = _instance_key(inst, obj)
            slot_rows = _slot_rows(obj, local.materials, table)
            tangents = table.tangents_of(slot_rows)
            if "UV" in tangents.values() and not local.tangents_asked:
                local = self._meshes.local_mesh(obj, tangents=True)
                slot_rows = _slot_rows(obj, local.materials, table)
            instances[key] = self._instance(key, inst, local, slot_rows, tangents)
            order.append(key)
        warnings.extend(f"{kind} objects are not supported and were skipped" for kind in sorted(skipped_types))
        warnings.extend(table.warnings)
        self.stats.meshes_triangulated = self._meshes.triangulated - triangulated
        self.stats.materials_exported = table.exported - exported
        scene, edits = self._assemble(instances, order, table, light_rows, world_radiance(depsgraph.scene.world, warnings),
                                      camera, warnings)
        self._instances, self._scene = instances, scene
        self.stats.edits = edits
        self.stats.ms = (time.perf_counter() - began) * 1000.0
        return scene, edits

    # -- what an edit invalidates -------------------------------------------------

    def _invalidate(self, updates: list[Update] | None) -> None:
        """Forget what the updates make stale: everything when they are not
        known. An edit inside a material's node tree, or a node group it
        uses, also updates the material (a node tree alone may be the world's)."""
        if updates is None:
            self._meshes, self._instances, self._pixels, self._table = MeshCache(), {}, {}, None
            return
        for update in updates:
            if update.kind in ("object", "data") and update.geometry:
                self._meshes.forget(update.name)
            if update.kind == "material":
                if self._table is not None:
                    self._table.forget(update.name)  # exported again at its next use, in its row
            elif update.kind in ("image", "texture"):  # every material is read again
                self._pixels.pop(update.name, None)
                self._table = None

    def _material_table(self) -> MaterialTable:
        """The material table kept, or a new one (its images' pixels kept)."""
        if self._table is None:
            self._table = MaterialTable(self._pixels)
        return self._table

    def _instance(self, key: tuple, inst, local: LocalMesh, slot_rows: np.ndarray, kinds: dict) -> _Instance:
        """The instance's arrays: kept when its mesh, matrix, materials and
        the tangents they read are the same. Corner tangents: MikkTSpace's
        (``local``'s) on triangles whose material reads them, radial ones
        where it reads those, zero elsewhere; none without any."""
        matrix = np.asarray(inst.matrix_world, np.float64)
        kept = self._instances.get(key)
        if (kept is not None and kept.local is local and kept.matrix == matrix.tobytes()
                and kept.slot_rows == slot_rows.tobytes() and kept.tangent_kinds == kinds):
            return kept
        self.stats.instances_transformed += 1
        world, normals, uvs, tangents = transform(local, matrix)
        ids = slot_rows[np.clip(local.slots, 0, len(slot_rows) - 1)]
        radial = {kind for kind in kinds.values() if kind != "UV"}
        if radial:
            tangents = np.zeros((len(ids), 3, 4), np.float32) if tangents is None else tangents.copy()
            for kind in radial:
                on = np.isin(ids, [row for row, k in kinds.items() if k == kind])
                tangents[on] = radial_tangents(local, matrix, kind[1])[on]
        return _Instance(local, matrix.tobytes(), slot_rows.tobytes(), kinds, world, normals, uvs, tangents, ids)

    # -- the scene ----------------------------------------------------------------

    def _assemble(self, instances: dict, order: list, table: MaterialTable, light_rows: list, world_color, camera,
                  warnings: list[str]) -> tuple[Scene, set]:
        """The Scene of this sync, sharing the arrays of the last one where
        nothing changed, and the parts that changed."""
        last, edits = self._scene, set()
        same_geometry = (last is not None and list(self._instances) == order
                         and all(self._instances[key] is instances[key] for key in order))
        if same_geometry:
            geometry = (last.triangles, last.normals, last.uvs, last.material_ids, last.tangents)
        else:
            edits.add("geometry")
            parts = [instances[key] for key in order]
            geometry = None
            if last is not None and list(self._instances) == order:
                geometry = _patched(last, [self._instances[key] for key in order], parts)
            if geometry is None:
                geometry = _concatenated(parts)
        materials, lights = Materials.make(table.rows), Lights.make(light_rows)
        if last is None or not (_same_columns(materials, last.materials) and _same_textures(table, last)):
            edits.add("materials")
        else:
            materials = last.materials
        if last is None or not _same_columns(lights, last.lights):
            edits.add("lights")
        else:
            lights = last.lights
        if last is None or not np.array_equal(world_color, last.world_color):
            edits.add("world")
        else:
            world_color = last.world_color
        scene = Scene(triangles=geometry[0], normals=geometry[1], uvs=geometry[2], material_ids=geometry[3],
                      materials=materials, lights=lights, camera=camera, world_color=world_color,
                      textures=list(table.textures), texture_closest=list(table.texture_closest),
                      tangents=geometry[4], warnings=list(dict.fromkeys(warnings)))
        return scene, edits


def _shown_object(inst):
    """The object an instance shows. An instance of another object (a
    collection instance, an object instanced by geometry nodes) shows that
    object, ``inst.instance_object``; read through ``inst.object`` instead,
    bpy makes a Python object for the instance's temporary object that is
    never freed (120 bytes per instance and export, bpy 5.0: the memory of a
    viewport grew with every edit). Geometry made by geometry nodes is only
    reachable through ``inst.object`` (its ``instance_object`` is the
    instancer), which keeps that cost."""
    if inst.is_instance:
        source = inst.instance_object
        if source is not None and source != inst.parent:
            return source
    return inst.object


def _instance_key(inst, obj) -> tuple:
    """What names an instance from one sync to the next: the object it shows,
    and for an instance made by another object, that object and the
    instance's id."""
    if inst.is_instance:
        return (obj.name_full, inst.parent.name_full, tuple(inst.persistent_id))
    return (obj.name_full,)


def _concatenated(parts: list[_Instance]) -> tuple:
    """The scene's geometry arrays from its instances' (empty ones without
    any); corner tangents where an instance has them, zero rows elsewhere,
    none at all when no instance has them."""
    if not parts or not sum(len(p.world) for p in parts):
        return (np.zeros((0, 3, 3)), np.zeros((0, 3, 3), np.float32), np.zeros((0, 3, 2), np.float32),
                np.zeros(0, np.int32), np.zeros((0, 3, 4), np.float32))
    tangents = np.zeros((0, 3, 4), np.float32)
    if any(p.tangents is not None for p in parts):
        tangents = np.concatenate([p.tangents if p.tangents is not None else np.zeros((len(p.world), 3, 4), np.float32)
                                   for p in parts])
    return (np.concatenate([p.world for p in parts]), np.concatenate([p.normals for p in parts]),
            np.concatenate([p.uvs for p in parts]), np.concatenate([p.ids for p in parts]).astype(np.int32), tangents)


_FIELDS = ("world", "normals", "uvs", "ids", "tangents")  # an instance's arrays, in the scene's order


def _patched(last: Scene, old: list[_Instance], new: list[_Instance]) -> tuple | None:
    """The last scene's geometry arrays with the rows of the instances that
    changed written in, where every instance kept its triangle count and
    whether it has tangents: an array none of them changed is the last
    scene's itself, the others copies (work in proportion to the scene for
    the copies only, none for the arrays kept). None where the rows moved."""
    if any(len(a.world) != len(b.world) or (a.tangents is None) != (b.tangents is None) for a, b in zip(old, new)):
        return None
    ends = np.cumsum([len(part.world) for part in new])
    changed = [(end - len(b.world), end, a, b) for end, a, b in zip(ends, old, new) if a is not b]
    arrays = []
    for name, whole in zip(_FIELDS, (last.triangles, last.normals, last.uvs, last.material_ids, last.tangents)):
        edited = [(start, end, getattr(b, name)) for start, end, a, b in changed
                  if getattr(b, name) is not None and not np.array_equal(getattr(a, name), getattr(b, name))]
        if edited:
            whole = whole.copy()
            for start, end, rows in edited:
                whole[start:end] = rows
        arrays.append(whole)
    return tuple(arrays)


def _same_columns(a, b) -> bool:
    """Two Materials (or Lights) with equal columns (names aside)."""
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.name != "names")


def _same_textures(table: MaterialTable, last: Scene) -> bool:
    """The table's textures are the last scene's: the same pixels and filters."""
    a, b = table.textures, last.textures
    return (len(a) == len(b) and all(x is y or np.array_equal(x, y) for x, y in zip(a, b))
            and list(table.texture_closest) == list(last.texture_closest))


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
