"""F12 through bpy.ops.render.render: images, passes, borders, errors, every demo scene."""

import glob
import os

import numpy as np
import pytest
from conftest import ROOT, render_multilayer, render_to_array

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


def test_write_still_png_has_the_percentage_size(bpy_module, tmp_path):
    bpy = bpy_module
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "light_point.blend"))
    scene = bpy.context.scene
    _small(scene)
    scene.render.resolution_x, scene.render.resolution_y = 90, 61
    scene.render.engine = "GPUGI"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / "still.png")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(tmp_path / "still.png"))
    assert tuple(image.size) == (90 * 25 // 100, 61 * 25 // 100)
    assert LAST_RUN["passes"] == ["Combined"]
    assert {"export", "render"} <= set(LAST_RUN["stats"]["ms"])


def _sphere_on_plane(bpy):
    """A smooth sphere on a plane under a sun, seen at an angle (every pixel hits something)."""
    bpy.ops.mesh.primitive_plane_add(size=40)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.3, 0.2, 1.0))
    bpy.ops.object.shade_smooth()
    bpy.ops.object.light_add(type="SUN", rotation=(0.3, 0.2, 0.0))
    bpy.ops.object.camera_add(location=(0.5, -6.0, 4.0), rotation=(0.98, 0.0, 0.08))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    scene.render.resolution_x, scene.render.resolution_y = 40, 32
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = True
    return scene


def _render_passes(bpy, scene, engine, path):
    channels = render_multilayer(bpy, scene, engine, path)
    depth = channels["ViewLayer.Depth.Z"]
    normal = np.stack([channels[f"ViewLayer.Normal.{c}"] for c in "XYZ"], axis=-1)
    return depth, normal


def _local_range(values):
    """Largest minus smallest value in each pixel's 3x3 neighbourhood (edges included)."""
    padded = np.pad(values, [(1, 1), (1, 1)] + [(0, 0)] * (values.ndim - 2), mode="edge")
    windows = [padded[1 + dy:padded.shape[0] - 1 + dy, 1 + dx:padded.shape[1] - 1 + dx]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    return np.max(windows, axis=0) - np.min(windows, axis=0)


def test_depth_and_normal_passes_match_cycles(bpy_empty, tmp_path):
    bpy = bpy_empty
    scene = _sphere_on_plane(bpy)
    scene.gpugi.samples = 1
    scene.cycles.samples, scene.cycles.use_denoising = 1, False
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 1.0  # samples stay in their pixels
    depth, normal = _render_passes(bpy, scene, "GPUGI", tmp_path / "gpugi.exr")
    assert LAST_RUN["passes"] == ["Combined", "Depth", "Normal"]
    ref_depth, ref_normal = _render_passes(bpy, scene, "CYCLES", tmp_path / "cycles.exr")
    assert depth.shape == ref_depth.shape == (32, 40)
    # sub-pixel sample positions differ: allow what a pixel's neighbourhood spans
    assert (np.abs(depth - ref_depth) <= _local_range(ref_depth) + 1e-3 * ref_depth).all()
    # normals away from silhouettes, where a sample may hit either surface
    inside = _local_range(ref_normal).max(axis=-1) < 0.5
    assert inside.mean() > 0.8
    assert (np.abs(normal - ref_normal)[inside] <= _local_range(ref_normal)[inside] + 2e-3).all()
    assert depth.min() > 3.0 and np.abs(np.linalg.norm(normal, axis=-1) - 1.0).max() < 1e-3


def test_passes_not_enabled_are_not_written(bpy_empty, tmp_path):
    bpy = bpy_empty
    scene = _sphere_on_plane(bpy)
    layer = scene.view_layers[0]
    layer.use_pass_z, layer.use_pass_normal = False, True
    scene.gpugi.samples = 1
    render_to_array(bpy, scene, "GPUGI", str(tmp_path / "n.exr"))
    assert LAST_RUN["passes"] == ["Combined", "Normal"]


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


@pytest.mark.parametrize("crop", [True, False])
def test_render_border_with_uneven_edges_lands_where_blender_puts_it(bpy_empty, tmp_path, crop):
    bpy = bpy_empty
    bpy.ops.mesh.primitive_plane_add(size=100)
    bpy.ops.object.light_add(type="SUN")
    bpy.ops.object.camera_add(location=(0, 0, 8))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    render = scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = 101, 79, 50
    render.use_border, render.use_crop_to_border = True, crop
    render.border_min_x, render.border_max_x, render.border_min_y, render.border_max_y = 0.23, 0.77, 0.11, 0.61
    scene.gpugi.samples = 1
    img = render_to_array(bpy, scene, "GPUGI", str(tmp_path / "border.exr"))
    assert not LAST_RUN.get("error")
    # Blender truncates border x size: x 11..38, y 4..23 of a 50x39 image
    if crop:
        assert img.shape == (19, 27, 4)
        assert img[..., :3].min() > 0
    else:
        assert img.shape == (39, 50, 4)
        lit = np.argwhere(img[..., 0] > 0)
        assert tuple(lit.min(axis=0)) == (4, 11) and tuple(lit.max(axis=0)) == (22, 37)


def test_scene_without_camera_is_refused_without_a_crash(bpy_empty):
    bpy = bpy_empty
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    scene.render.resolution_x = scene.render.resolution_y = 16
    bpy.ops.mesh.primitive_plane_add()
    with pytest.raises(RuntimeError, match="camera"):
        bpy.ops.render.render()  # Blender checks this before calling the engine


def test_export_error_is_reported_through_the_render_not_raised(bpy_empty, tmp_path):
    bpy = bpy_empty
    scene = _sphere_on_plane(bpy)
    scene.camera.data.type = "PANO"
    scene.render.engine = "GPUGI"
    # the operator turns the engine's error report into RuntimeError; Blender carries on
    with pytest.raises(RuntimeError, match="panoramic"):
        bpy.ops.render.render()
    assert "panoramic" in LAST_RUN["error"]
    assert "stats" not in LAST_RUN
