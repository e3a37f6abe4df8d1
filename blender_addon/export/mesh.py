"""Evaluated meshes of every object instance into world-space triangle arrays.

All per-element data moves through ``foreach_get`` into numpy; no Python loop
runs over vertices, corners or triangles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .inverse import cofactors

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


@dataclass
class LocalMesh:
    """One evaluated mesh in object space, triangulated."""

    positions: np.ndarray  # (T, 3, 3) float32
    normals: np.ndarray  # (T, 3, 3) float32 corner normals
    uvs: np.ndarray  # (T, 3, 2) float32 of the UV map used for rendering
    slots: np.ndarray  # (T,) int32 material slot of each triangle
    materials: list  # the mesh's own materials, by slot
    # (T, 3, 4) float32 MikkTSpace tangents of the render UV map per corner,
    # w the bitangent's sign; None when not asked for or not computable
    tangents: np.ndarray | None = None
    tangents_asked: bool = False
    # (2, 3): the texture space's centre and half size (generated coordinates
    # run from centre - size to centre + size)
    texspace: np.ndarray = field(default_factory=lambda: np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))


class MeshCache:
    """Local meshes, each exported once however often it is instanced, and
    kept until its object's or its data's geometry is edited."""

    def __init__(self):
        self._meshes: dict = {}
        self.triangulated = 0  # meshes read from Blender so far

    def local_mesh(self, obj, tangents: bool = False) -> LocalMesh | None:
        """The triangulated evaluated mesh of ``obj``, or None if it has no
        faces; with ``tangents`` (a normal map uses them) its corner tangents too."""
        data = obj.data
        key = (obj.name_full, data.name_full if data is not None else "", data.as_pointer() if data is not None else 0)
        kept = self._meshes.get(key, False)
        if kept is False or (tangents and kept is not None and not kept.tangents_asked):
            self._meshes[key] = _triangulate(obj, tangents)
            self.triangulated += 1
        return self._meshes[key]

    def forget(self, name: str) -> None:
        """Drop the meshes of the object or data named ``name`` (its geometry changed)."""
        for key in [k for k in self._meshes if name in (k[0], k[1])]:
            del self._meshes[key]


def _triangulate(obj, tangents: bool = False) -> LocalMesh | None:
    """Read the evaluated mesh of ``obj`` (with ``tangents``, its corner
    tangents); the temporary mesh is always freed."""
    try:
        mesh = obj.to_mesh()
    except RuntimeError:
        return None
    try:
        if mesh is None:
            return None
        mesh.calc_loop_triangles()
        count = len(mesh.loop_triangles)
        if count == 0:
            return None
        verts = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", verts)
        tri_verts = np.empty(count * 3, np.int32)
        mesh.loop_triangles.foreach_get("vertices", tri_verts)
        tri_loops = np.empty(count * 3, np.int32)
        mesh.loop_triangles.foreach_get("loops", tri_loops)
        slots = np.empty(count, np.int32)
        mesh.loop_triangles.foreach_get("material_index", slots)
        # corner normals carry flat faces, smooth faces, sharp edges and custom normals alike
        corner = np.empty(len(mesh.loops) * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", corner)
        uv_layer = _render_uv_layer(mesh)
        if uv_layer is not None:
            uv = np.empty(len(mesh.loops) * 2, np.float32)
            uv_layer.uv.foreach_get("vector", uv)
            uvs = uv.reshape(-1, 2)[tri_loops].reshape(count, 3, 2)
        else:
            uvs = np.zeros((count, 3, 2), np.float32)
        return LocalMesh(
            positions=verts.reshape(-1, 3)[tri_verts].reshape(count, 3, 3),
            normals=corner.reshape(-1, 3)[tri_loops].reshape(count, 3, 3),
            uvs=uvs,
            slots=slots,
            materials=list(mesh.materials),
            tangents=_corner_tangents(mesh, uv_layer, tri_loops) if tangents else None,
            tangents_asked=tangents,
            texspace=np.array([mesh.texspace_location[:], mesh.texspace_size[:]], np.float64),
        )
    finally:
        obj.to_mesh_clear()


def _corner_tangents(mesh, uv_layer, tri_loops: np.ndarray) -> np.ndarray | None:
    """MikkTSpace tangents and bitangent signs of the render UV map at each
    triangle corner, as Cycles reads them; None without UVs or where
    Blender cannot compute them (faces of more than four corners)."""
    if uv_layer is None:
        return None
    try:
        mesh.calc_tangents(uvmap=uv_layer.name)
    except RuntimeError:
        return None
    loops = len(mesh.loops)
    tangent, sign = np.empty(loops * 3, np.float32), np.empty(loops, np.float32)
    mesh.loops.foreach_get("tangent", tangent)
    mesh.loops.foreach_get("bitangent_sign", sign)
    rows = np.concatenate([tangent.reshape(-1, 3), sign[:, None]], axis=1)
    return rows[tri_loops].reshape(-1, 3, 4)


def _render_uv_layer(mesh):
    """The UV map marked for rendering (the camera icon), else the active one."""
    for layer in mesh.uv_layers:
        if layer.active_render:
            return layer
    return mesh.uv_layers.active


def radial_tangents(local: LocalMesh, matrix, axis: str) -> np.ndarray:
    """(T, 3, 4) unit world tangents about ``axis`` ("X", "Y" or "Z") of the
    object's texture space at each corner, w = 1, as Cycles' Tangent node in
    Radial mode (the default of an anisotropic shader): the generated
    coordinate g in 0..1 turned a quarter about the axis through 0.5, then
    by the object's normal matrix (corner order as transform() gives it)."""
    centre, size = local.texspace
    g = (local.positions.astype(np.float64) - centre) / np.where(size != 0.0, size, 1.0) * 0.5
    x, y, z = g[..., 0], g[..., 1], g[..., 2]
    zero = np.zeros_like(x)
    t = np.stack({"X": (zero, -z, y), "Y": (-z, zero, x)}.get(axis, (-y, x, zero)), axis=-1)
    normal_matrix, det = _normal_matrix(np.asarray(matrix, np.float64)[:3, :3])
    t = _unit_rows(_times(t, normal_matrix.T))
    rows = np.concatenate([t, np.ones(t.shape[:-1] + (1,))], axis=-1).astype(np.float32)
    return np.ascontiguousarray(rows[:, ::-1] if det < 0 else rows)


def _normal_matrix(lin: np.ndarray) -> tuple[np.ndarray, float]:
    """The matrix normals turn by (the inverse transpose of ``lin``: its
    cofactors over its determinant; itself where it is singular) and
    ``lin``'s determinant."""
    cof, det = cofactors(lin)
    return (cof / det if abs(det) > 1e-300 else lin), det


def _unit_rows(v: np.ndarray) -> np.ndarray:
    """The vectors of the last axis (three long) at unit length; zero ones
    stay zero. Their lengths column by column: numpy's reductions along
    rows this short are several times slower."""
    length = np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])[..., None]
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def _times(rows: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``rows @ matrix`` for vectors along the last axis of any shape, in
    einsum's own loops: not ``@``, whose tall products go to OpenBLAS's
    threads (inverse.py)."""
    return np.einsum("...j,jk->...k", rows, matrix)


def transform(local: LocalMesh, matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """World positions (float64), unit world normals, UVs and unit world
    tangents (None without) of a local mesh.

    Normals use the inverse transpose, tangents the matrix itself; a
    mirroring matrix reverses each triangle's corner order so that winding
    and normals stay consistent, and the bitangents' signs with it.
    """
    m = np.asarray(matrix, np.float64)
    lin, offset = m[:3, :3], m[:3, 3]
    world = _times(local.positions.astype(np.float64), lin.T) + offset
    normal_matrix, det = _normal_matrix(lin)
    n = _unit_rows(_times(local.normals.astype(np.float64), normal_matrix.T))
    uvs, tangents = local.uvs, None
    if local.tangents is not None:
        t = _unit_rows(_times(local.tangents[..., :3].astype(np.float64), lin.T))
        tangents = np.concatenate([t, local.tangents[..., 3:] * (-1.0 if det < 0 else 1.0)], axis=-1).astype(np.float32)
    if det < 0:
        world, n, uvs = world[:, ::-1], n[:, ::-1], uvs[:, ::-1]
        tangents = tangents[:, ::-1] if tangents is not None else None
    return world, n.astype(np.float32), np.ascontiguousarray(uvs), (np.ascontiguousarray(tangents)
                                                                    if tangents is not None else None)
