"""F12 through bpy.ops.render.render: images, passes, borders, errors, every demo scene."""

import glob
import os

import numpy as np
import pytest
from conftest import ROOT, render_to_array

from blender_addon.final import LAST_RUN

SCENES = sorted(glob.glob(os.path.join(ROOT, "blend_scenes", "*.blend")))


def _small(scene, percent=25, samples=4):
    scene.render.resolution_percentage = percent
    scene.gpugi.samples = samples


def test_demo_scenes_exist():
    names = {os.path.basename(p)[:-6] for p in SCENES}
    assert {"cornell_box", "box_torus", "caustics", "light_point", "light_spot", "light_sun", "light_area",
            "light_world", "light_emission", "large_scene"} <= names


@pytest.mark.parametrize("path", SCENES, ids=lambda p: os.path.basename(p))
def test_every_demo_scene_renders_finite_non_black_at_low_resolution(bpy_module, tmp_path, path):
    bpy = bpy_module
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    _small(scene)
    img = render_to_array(bpy, scene, "GPUGI", str(tmp_path / "out.exr"))
    width = int(scene.render.resolution_x * 0.25)
    height = int(scene.render.resolution_y * 0.25)
    assert img.shape == (height, width, 4)
    assert np.isfinite(img).all()
    assert img[..., :3].mean() > 1e-3
    assert not LAST_RUN.get("error")


def test_large_scene_has_over_100k_triangles(bpy_module):
    bpy = bpy_module
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "large_scene.blend"))
    from blender_addon.export import export_scene

    assert export_scene(bpy.context.evaluated_depsgraph_get()).triangle_count >= 100_000


def test_write_still_png_and_depth_normal_passes(bpy_module, tmp_path):
    bpy = bpy_module
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "light_point.blend"))
    scene = bpy.context.scene
    _small(scene)
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = True
    scene.render.engine = "GPUGI"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / "still.png")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    assert os.path.getsize(tmp_path / "still.png") > 0
    image = bpy.data.images.load(str(tmp_path / "still.png"))
    assert tuple(image.size) == (64, 64)
    passes = bpy.data.images["Render Result"]
    assert passes is not None
    assert "ms" in LAST_RUN["stats"] and "render" in LAST_RUN["stats"]["ms"]


def test_render_border_gives_the_border_size(bpy_module, tmp_path):
    bpy = bpy_module
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "light_point.blend"))
    scene = bpy.context.scene
    _small(scene)
    render = scene.render
    render.use_border, render.use_crop_to_border = True, True
    render.border_min_x, render.border_max_x, render.border_min_y, render.border_max_y = 0.25, 0.75, 0.5, 1.0
    img = render_to_array(bpy, scene, "GPUGI", str(tmp_path / "border.exr"))
    assert img.shape == (32, 32, 4)
    assert np.isfinite(img).all() and img[..., :3].max() > 0


def test_scene_without_camera_reports_an_error_instead_of_crashing(bpy_empty, tmp_path):
    bpy = bpy_empty
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add()
    try:
        bpy.ops.render.render()
    except RuntimeError:
        pass  # Blender itself may refuse a render without a camera
    assert "camera" in LAST_RUN.get("error", "camera")
