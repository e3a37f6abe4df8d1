"""Passes, mode and presets through Blender: the view layer's toggles decide
what is registered and written, the light passes add up to Combined in the
saved file, and the compositor's Denoise node takes our denoising passes."""

import os
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT, pass_rgb, render_multilayer

from blender_addon.final import LAST_RUN
from blender_addon.passes import PASSES, enabled_passes
from gpu_core.settings import PRESETS

LIGHT_TOGGLES = ("use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_glossy_direct",
                 "use_pass_glossy_indirect", "use_pass_transmission_direct", "use_pass_transmission_indirect",
                 "use_pass_emit", "use_pass_environment")
SUMMED = ("Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect", "Transmission Direct",
          "Transmission Indirect", "Emission", "Environment")


def _cornell(bpy, percent=12, samples=4):
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "cornell_box.blend"))
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    scene.render.resolution_percentage = percent
    scene.gpugi.mode = "REFERENCE"
    scene.gpugi.samples, scene.gpugi.diffuse_bounces = samples, 2
    scene.gpugi.denoise = False  # the passes as rendered: they add up to Combined only so
    return scene


def _enable_all(view_layer):
    for toggle in LIGHT_TOGGLES:
        setattr(view_layer, toggle, True)
    view_layer.gpugi.use_pass_caustics = True
    view_layer.cycles.denoising_store_passes = True


def _render_multilayer(bpy, scene, path):
    channels = render_multilayer(bpy, scene, "GPUGI", path)
    assert not LAST_RUN.get("error"), LAST_RUN
    return channels



def test_toggles_decide_the_registered_passes(bpy_module):
    scene = _cornell(bpy_module)
    view_layer = scene.view_layers[0]
    assert [spec.name for spec in enabled_passes(view_layer)] == ["Combined"]
    _enable_all(view_layer)
    view_layer.use_pass_z = view_layer.use_pass_normal = True
    assert [spec.name for spec in enabled_passes(view_layer)] == [spec.name for spec in PASSES]
    view_layer.use_pass_glossy_indirect = False
    assert "Glossy Indirect" not in {spec.name for spec in enabled_passes(view_layer)}
    # a toggle that does not exist (the Cycles add-on disabled) reads as off
    bare = SimpleNamespace(**{toggle: False for toggle in LIGHT_TOGGLES}, use_pass_z=False, use_pass_normal=False,
                           gpugi=SimpleNamespace(use_pass_caustics=False))
    assert [spec.name for spec in enabled_passes(bare)] == ["Combined"]


def test_light_passes_in_the_saved_file_add_up_to_combined(bpy_module, tmp_path):
    scene = _cornell(bpy_module)
    _enable_all(scene.view_layers[0])
    channels = _render_multilayer(bpy_module, scene, tmp_path / "passes.exr")
    assert set(LAST_RUN["passes"]) == {"Combined"} | {spec.name for spec in PASSES[3:]}
    combined = pass_rgb(channels, "Combined")
    total = sum(pass_rgb(channels, name) for name in SUMMED)
    np.testing.assert_allclose(total, combined, rtol=1e-5, atol=1e-6)
    for name in ("Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Transmission Indirect"):
        assert pass_rgb(channels, name).mean() > 1e-3, name
    assert 0.0 < pass_rgb(channels, "Caustics").mean() < pass_rgb(channels, "Diffuse Indirect").mean() + 0.1
    assert channels["ViewLayer.Denoising Albedo.R"].max() > 0.5


def test_compositor_finds_the_passes_and_denoises_with_them(bpy_module, tmp_path):
    bpy = bpy_module
    scene = _cornell(bpy, percent=25, samples=2)
    scene.gpugi.diffuse_bounces = 0  # no caustic fireflies, which a denoiser removes along with their energy
    view_layer = scene.view_layers[0]
    view_layer.cycles.denoising_store_passes = True
    view_layer.use_pass_diffuse_direct = True
    tree = bpy.data.node_groups.new("compositor", "CompositorNodeTree")
    scene.compositing_node_group = tree
    layers = tree.nodes.new("CompositorNodeRLayers")
    outputs = {socket.name for socket in layers.outputs if socket.enabled}
    assert {"Image", "Diffuse Direct", "Denoising Albedo", "Denoising Normal"} <= outputs
    assert "Glossy Direct" not in outputs and "Caustics" not in outputs
    view_layer.gpugi.use_pass_caustics = True  # our own toggle also refreshes the sockets
    assert "Caustics" in {socket.name for socket in layers.outputs if socket.enabled}
    denoise = tree.nodes.new("CompositorNodeDenoise")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(layers.outputs["Image"], denoise.inputs["Image"])
    tree.links.new(layers.outputs["Denoising Albedo"], denoise.inputs["Albedo"])
    tree.links.new(layers.outputs["Denoising Normal"], denoise.inputs["Normal"])
    tree.links.new(denoise.outputs[0], out.inputs[0])

    def render(compositing):
        scene.render.use_compositing = compositing
        settings = scene.render.image_settings
        settings.media_type = "IMAGE"
        settings.file_format, settings.color_depth = "OPEN_EXR", "32"
        path = str(tmp_path / f"image_{compositing}.exr")
        scene.render.filepath, scene.render.use_file_extension = path, False
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(path)
        try:
            return np.array(img.pixels[:], np.float64).reshape(img.size[1], img.size[0], 4)[..., :3]
        finally:
            bpy.data.images.remove(img)

    noisy, denoised = render(False), render(True)
    assert "Denoising Albedo" in LAST_RUN["passes"]

    def roughness(img):  # mean difference between horizontal neighbours
        return np.abs(np.diff(img, axis=1)).mean()

    # same brightness, much less pixel-to-pixel noise
    assert denoised.mean() == pytest.approx(noisy.mean(), rel=0.1)
    assert roughness(denoised) < 0.7 * roughness(noisy)


def test_gi_mode_light_passes_add_up_to_combined(bpy_module, tmp_path):
    scene = _cornell(bpy_module, percent=12, samples=2)
    scene.gpugi.preset = "DRAFT"
    scene.gpugi.mode = "GI"
    _enable_all(scene.view_layers[0])
    channels = _render_multilayer(bpy_module, scene, tmp_path / "gi.exr")
    assert LAST_RUN["stats"]["mode"] == "gi" and not LAST_RUN["warnings"]
    combined = pass_rgb(channels, "Combined")
    np.testing.assert_allclose(sum(pass_rgb(channels, name) for name in SUMMED), combined, rtol=1e-5, atol=1e-5)
    # the cache's indirect light lands in Diffuse Indirect (and, seen in the mirror, Glossy Indirect)
    for name in ("Diffuse Indirect", "Glossy Indirect", "Caustics"):
        assert pass_rgb(channels, name).mean() > 1e-3, name


def test_preset_sets_its_values_and_an_edit_makes_it_custom(bpy_empty):
    settings = bpy_empty.context.scene.gpugi
    assert settings.preset == "CUSTOM"
    for name, values in PRESETS.items():
        settings.preset = name.upper()
        assert settings.preset == name.upper()
        for key, value in values.items():
            assert getattr(settings, key) == pytest.approx(value), (name, key)
        assert settings.render_settings().samples == values["samples"]
    settings.samples += 1
    assert settings.preset == "CUSTOM"
    assert settings.render_settings().samples == PRESETS["reference"]["samples"] + 1
