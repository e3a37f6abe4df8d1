"""The pixel filter of the scene's film, as Cycles applies it: an edge seen
through each filter type, GPU GI against Cycles in the same process."""

import numpy as np
import pytest
from conftest import render_to_array

from blender_addon.export.camera import pixel_filter
from gpu_core.scene import FILTER_BLACKMAN_HARRIS, FILTER_BOX, FILTER_GAUSSIAN

WIDTH, HEIGHT = 32, 16


def _edge_scene(bpy):
    """An emitting plane right of x = 0.3 px from the centre, seen by an
    orthographic camera at one unit per pixel, on a black world."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = WIDTH, HEIGHT, 100
    scene.view_settings.view_transform = "Standard"
    data = bpy.data.cameras.new("camera")
    data.type, data.ortho_scale = "ORTHO", WIDTH
    camera = bpy.data.objects.new("camera", data)
    camera.location = (0.0, 0.0, 10.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    mesh = bpy.data.meshes.new("emitter")
    mesh.from_pydata([(0.3, -50, 0), (100, -50, 0), (100, 50, 0), (0.3, 50, 0)], [], [(0, 1, 2, 3)])
    material = bpy.data.materials.new("emission")
    nodes = material.node_tree.nodes
    nodes.clear()
    emission, output = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(emission.outputs[0], output.inputs[0])
    mesh.materials.append(material)
    scene.collection.objects.link(bpy.data.objects.new("emitter", mesh))
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_adaptive_sampling = "CPU", 1024, False
    scene.cycles.use_denoising = False
    scene.gpugi.mode, scene.gpugi.samples, scene.gpugi.denoise = "REFERENCE", 1024, False
    return scene


@pytest.mark.parametrize("kind, width", [("BOX", 1.0), ("GAUSSIAN", 1.5), ("BLACKMAN_HARRIS", 1.5),
                                         ("BLACKMAN_HARRIS", 2.5)])
def test_an_edge_through_each_pixel_filter_matches_cycles(bpy_module, tmp_path, kind, width):
    scene = _edge_scene(bpy_module)
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = kind, width
    ours = render_to_array(bpy_module, scene, "GPUGI", str(tmp_path / "ours.exr"))[..., 0].mean(axis=0)
    cycles = render_to_array(bpy_module, scene, "CYCLES", str(tmp_path / "cycles.exr"))[..., 0].mean(axis=0)
    assert cycles[WIDTH // 2] > 0.5 and cycles[0] == 0.0  # the edge is where it should be
    np.testing.assert_allclose(ours, cycles, atol=0.015)


def test_the_export_reads_cycles_pixel_filter_else_blenders_filter_size(bpy_module):
    scene = _edge_scene(bpy_module)
    assert pixel_filter(scene) == (FILTER_BLACKMAN_HARRIS, pytest.approx(1.5))  # Blender's default film
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "GAUSSIAN", 2.0
    assert pixel_filter(scene) == (FILTER_GAUSSIAN, pytest.approx(2.0))
    scene.cycles.pixel_filter_type = "BOX"
    assert pixel_filter(scene)[0] == FILTER_BOX
