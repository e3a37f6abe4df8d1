"""Evaluated meshes of every object instance into world-space triangle arrays."""

from __future__ import annotations

import numpy as np

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


class MeshCache:
    """Per-mesh local arrays, exported once however often the mesh is instanced."""

    def __init__(self):
        self._arrays: dict = {}

    def local_arrays(self, obj):
        """(positions (T,3,3), normals (T,3,3), uvs (T,3,2), slot ids (T,)) in object space."""
        data = getattr(obj, "data", None)
        key = (obj.name_full, data.as_pointer() if data is not None else 0)
        if key not in self._arrays:
            self._arrays[key] = _mesh_arrays(obj)
        return self._arrays[key]


def _mesh_arrays(obj):
    mesh = obj.to_mesh()
    try:
        if mesh is None:
            return None
        mesh.calc_loop_triangles()
        count = len(mesh.loop_triangles)
        if count == 0:
            return None
        verts = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", verts)
        verts = verts.reshape(-1, 3)
        tri_verts = np.empty(count * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", tri_verts)
        tri_loops = np.empty(count * 3, np.int32)
        mesh.loop_triangles.foreach_get("loops", tri_loops)
        slots = np.empty(count, np.int32)
        mesh.loop_triangles.foreach_get("material_index", slots)
        # corner normals carry flat, smooth, sharp-edge and custom normals alike
        corner = np.empty(len(mesh.loops) * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", corner)
        normals = corner.reshape(-1, 3)[tri_loops].reshape(count, 3, 3)
        uv_layer = mesh.uv_layers.active
        if uv_layer is not None:
            uv = np.empty(len(mesh.loops) * 2, np.float32)
            uv_layer.uv.foreach_get("vector", uv)
            uvs = uv.reshape(-1, 2)[tri_loops].reshape(count, 3, 2)
        else:
            uvs = np.zeros((count, 3, 2), np.float32)
        positions = verts[tri_verts].reshape(count, 3, 3)
        materials = [m for m in mesh.materials]
        return positions, normals, uvs, slots, materials
    finally:
        obj.to_mesh_clear()


def transform(positions, normals, uvs, matrix):
    """World positions (float64), unit world normals and UVs of object-space arrays."""
    m = np.asarray(matrix, np.float64)
    lin, offset = m[:3, :3], m[:3, 3]
    world = positions.astype(np.float64) @ lin.T + offset
    try:
        normal_matrix = np.linalg.inv(lin).T
    except np.linalg.LinAlgError:
        normal_matrix = lin
    n = normals.astype(np.float64) @ normal_matrix.T
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)
    if np.linalg.det(lin) < 0:
        # a mirroring transform flips the winding: keep normals and winding consistent
        world, n, uvs = world[:, ::-1], n[:, ::-1], uvs[:, ::-1]
    return world, n.astype(np.float32), np.ascontiguousarray(uvs)
