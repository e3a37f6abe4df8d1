"""The one device copy of a scene that every kernel reads.

``upload(device, scene, tables, previous, changed)`` makes the
``SceneBuffers``: the triangle kd-tree, the triangle attributes, and the
tables of scene/tables.py. Parts that did not change keep the buffers of
``previous``, so an edit moves only what it touched (a material colour edit
uploads the 64-byte rows of the materials, not the triangles).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pyopencl as cl

from ..accel import kdtree, kdtree_overlay
from ..device import Device
from ..device.layout import float4_rows
from ..device.timer import StageTimer
from .model import PARTS, Scene
from .tables import SceneTables


@dataclass
class SceneBuffers:
    """A validated scene on the device, in its frame (positions relative to ``center``)."""

    device: Device
    center: np.ndarray  # (3,) float64
    radius: float  # of the scene's bounding sphere
    tree: kdtree.KdTree
    normals: cl.Buffer  # float4 per triangle corner
    uvs: cl.Buffer  # float2 per triangle corner
    tangents: cl.Buffer  # float4 per triangle corner (one zero row when the scene has none)
    material_ids: cl.Buffer  # int per triangle
    materials: cl.Buffer  # Material rows
    lights: cl.Buffer  # Light rows
    light_count: int
    emit_tris: cl.Buffer  # emissive triangle ids
    emit_cdf: cl.Buffer
    emit_count: int
    atlas: cl.Buffer  # float4 texels
    texture_infos: cl.Buffer
    camera: cl.Buffer  # one Camera row
    world: np.ndarray  # float4: rgb radiance, w = 1 for a transparent film (set per render)
    sources: tuple = ()  # the host arrays of normals, uvs, material ids and tangents uploaded

    def kernel_args(self, transparent: bool = False) -> list:
        """Arguments matching SCENE_PARAMS in shading/scene.h, in order."""
        world = self.world.copy()
        world[3] = 1.0 if transparent else 0.0
        return [*self.tree.kernel_args(), self.normals, self.uvs, self.tangents, self.material_ids, self.materials,
                self.atlas, self.texture_infos, self.lights, np.int32(self.light_count), self.emit_tris,
                self.emit_cdf, np.int32(self.emit_count), self.camera, world]


def upload(device: Device, scene: Scene, tables: SceneTables, previous: SceneBuffers | None = None,
           changed=PARTS, timer: StageTimer | None = None, should_stop: Callable[[], bool] | None = None,
           tree_rows: np.ndarray | None = None) -> SceneBuffers:
    """The device copy of a validated ``scene`` whose ``tables`` are built;
    the buffers of ``previous`` stay where no part they hold is in
    ``changed`` (the plan says which). With ``tree_rows`` (the plan's
    triangles moved since the base of ``previous``'s tree) the kd-tree is
    that base joined with a tree over them (accel/kdtree_overlay.py), else
    it is built whole. The kd-tree build is timed as "kdtree", the rest as
    "upload"; ``should_stop`` is polled during the kd-tree build
    (RenderCancelled)."""
    timer = timer or StageTimer()
    moved = previous is None or not np.array_equal(tables.center, previous.center)
    changed = set(PARTS) if moved else set(changed)
    old = previous if not moved else None
    if old is None or "geometry" in changed:
        with timer.stage("kdtree"):
            if tree_rows is not None and old is not None:
                base = old.tree.base if old.tree.base is not None else old.tree
                moved_tris = (scene.triangles[tree_rows] - tables.center).astype(np.float32)
                tree = kdtree_overlay.overlay(device, base, tree_rows, moved_tris, should_stop)
            else:
                tree = kdtree.build(device, (scene.triangles - tables.center).astype(np.float32), should_stop)
        with timer.stage("upload"):
            geometry = (tree, *_attributes(device, scene, old))
    else:
        geometry = (old.tree, old.normals, old.uvs, old.material_ids, old.tangents)
    with timer.stage("upload"):
        if old is None or changed & {"geometry", "materials"}:
            emitters = (device.to_device(tables.emit_tris), device.to_device(tables.emit_cdf), len(tables.emit_tris))
        else:
            emitters = (old.emit_tris, old.emit_cdf, old.emit_count)
        if old is None or "materials" in changed:
            materials = (device.to_device(tables.materials), device.to_device(tables.atlas),
                         device.to_device(tables.texture_infos))
        else:
            materials = (old.materials, old.atlas, old.texture_infos)
        if old is None or changed & {"lights", "geometry", "materials"}:
            lights = (device.to_device(tables.lights), len(tables.lights))
        else:
            lights = (old.lights, old.light_count)
        camera = device.to_device(tables.camera) if old is None or "camera" in changed else old.camera
    return SceneBuffers(
        device=device, center=tables.center, radius=tables.radius, tree=geometry[0], normals=geometry[1],
        uvs=geometry[2], material_ids=geometry[3], tangents=geometry[4], materials=materials[0], lights=lights[0],
        light_count=lights[1], emit_tris=emitters[0], emit_cdf=emitters[1], emit_count=emitters[2], atlas=materials[1],
        texture_infos=materials[2], camera=camera, world=np.append(scene.world_color, 0.0).astype(np.float32),
        sources=_sources(scene))


def _sources(scene: Scene) -> tuple:
    """The host arrays the triangle attributes are uploaded from."""
    return (scene.normals, scene.uvs, scene.material_ids, scene.tangents)


def _attributes(device: Device, scene: Scene, old: SceneBuffers | None) -> list:
    """The normals, uvs, material ids and tangents on the device: the
    buffers of ``old`` for the arrays it was uploaded from (the very same
    objects: a moved object leaves the others' arrays as they were),
    uploads of the others."""
    uploads = (lambda: float4_rows(scene.normals.reshape(-1, 3)),
               lambda: np.ascontiguousarray(scene.uvs.reshape(-1, 2), np.float32),
               lambda: scene.material_ids, lambda: _corner_tangents(scene))
    held = (old.normals, old.uvs, old.material_ids, old.tangents) if old is not None else (None,) * 4
    sources = old.sources if old is not None else ()
    return [buffer if i < len(sources) and sources[i] is array else device.to_device(upload())
            for i, (array, buffer, upload) in enumerate(zip(_sources(scene), held, uploads))]


def _corner_tangents(scene: Scene) -> np.ndarray:
    """The float4 corner tangents the kernels read: the scene's, or one zero
    row without any."""
    if not len(scene.tangents):
        return np.zeros((1, 4), np.float32)
    return np.ascontiguousarray(scene.tangents.reshape(-1, 4), np.float32)
