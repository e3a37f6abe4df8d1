"""What crosses between the host and the device: a GI render keeps its data
on the device and moves little more than its scene and its image."""

from __future__ import annotations

import dataclasses

import numpy as np
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights, Materials
from gpu_core.settings import RenderSettings

SIZE = 32
GI = RenderSettings(mode="gi", samples=2, global_photons=40_000, caustic_photons=40_000, photon_k=30,
                    cache_seeds=200, gather_rays=64, light_passes=True, denoising_passes=True)


def mirrored_room():
    faces = [quad((0, 0, -1), 2), quad((0, 0, 1), 2, flip=True), quad((0, -1, 0), 2, normal_axis=1),
             quad((0, 1, 0), 2, normal_axis=1, flip=True), quad((-1, 0, 0), 2, normal_axis=0),
             quad((1, 0, 0), 2, normal_axis=0, flip=True), quad((0.5, 0, -0.98), 0.6)]
    tris = np.concatenate(faces)
    ids = np.array([0] * 12 + [1, 1], np.int32)
    mats = Materials.make([dict(base_color=(0.6,) * 3), dict(base_color=(0.9,) * 3, metallic=1.0, roughness=0.0)])
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 0.5), power=(100,) * 3)])
    camera = camera_looking_down(height=0.9, half_width=1.0, size=SIZE)
    camera.clip_start, camera.clip_end = 1e-3, 20.0
    return make_scene(tris, ids, mats, lights, camera)


def test_a_gi_render_reads_back_little_more_than_its_passes(device):
    result = Renderer(device).render(mirrored_room(), GI)
    moved = result.stats["transfers"]
    passes = sum(p.nbytes for p in result.passes.values()) - result.passes["Denoising Depth"].nbytes
    # the device writes float4 colour passes: what is read back is at most 4/3 of the float3 passes,
    # and everything else that comes back (counts, sums, the cache's sample choice) is small
    assert moved["to_host"] < 4 / 3 * passes + 64 * 1024
    assert {"global_photons", "caustic_photons", "final_gather", "caustics"} <= set(result.stats["plan"])


def test_a_camera_move_uploads_only_the_camera(device):
    renderer = Renderer(device)
    scene = mirrored_room()
    renderer.render(scene, GI)
    camera = dataclasses.replace(scene.camera, matrix=scene.camera.matrix.copy())
    camera.matrix[1, 3] += 0.05
    moved = renderer.render(dataclasses.replace(scene, camera=camera), GI).stats["transfers"]
    # the camera row and the cache's small tables; no triangles, no photons
    assert moved["to_device"] < 16 * 1024


def test_a_move_uploads_the_moved_corners_and_keeps_the_other_attribute_buffers(device):
    renderer = Renderer(device)
    scene = mirrored_room()
    renderer.render(scene, GI)
    held = renderer._buffers
    triangles = scene.triangles.copy()
    triangles[-2:] += (0.05, 0.0, 0.0)  # the mirror panel moved; every other array shared
    after = renderer.render(dataclasses.replace(scene, triangles=triangles), GI)
    assert "kdtree_overlay" in after.stats["plan"]
    buffers = renderer._buffers
    for name in ("normals", "uvs", "material_ids", "tangents"):
        assert getattr(buffers, name) is getattr(held, name), name
    # the moved triangles' overlay tree, the light and emitter tables and the cache's small tables
    assert after.stats["transfers"]["to_device"] < 16 * 1024
