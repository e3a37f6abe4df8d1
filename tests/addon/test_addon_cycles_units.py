"""Looks and units match Cycles: direct light of each light type on a diffuse plane.

Cycles (in the same process, max bounces 0 so only direct light) and GPU GI
render the same .blend; the image means agree within 3 % and every pixel
away from shadow and cone edges agrees within a tolerance set by the noise
of the two estimates.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import render_to_array

from blender_addon.final import LAST_RUN

SIZE = 48
# (Cycles samples, GPU GI samples, per-pixel relative tolerance): lights that
# are points or directions only need anti-aliasing and are held tighter; where
# the light itself is sampled (area, world, mesh) both estimates carry noise
DELTA_SAMPLES = (64, 16, 0.02)
SAMPLED_SAMPLES = (1024, 256, 0.08)
MASK_SAMPLES = 64  # the shadowless Cycles render that only locates soft-shadow borders
TINT = (1.0, 0.85, 0.6, 1.0)  # coloured light: a channel mix-up cannot pass


def _diffuse(bpy, name, color):
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = color
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def _emission(bpy, strength):
    mat = bpy.data.materials.new("emitter")
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new("ShaderNodeEmission")
    node.inputs["Color"].default_value = TINT
    node.inputs["Strength"].default_value = strength
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _light(bpy, kind, location, rotation=(0.0, 0.0, 0.0), **props):
    data = bpy.data.lights.new(kind.lower(), kind)
    data.color = TINT[:3]
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(kind.lower(), data)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)


def _world(bpy, color, strength):
    world = bpy.data.worlds.new("world")
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = color
    background.inputs["Strength"].default_value = strength
    bpy.context.scene.world = world


def _area(shape, **sizes):
    def build(bpy):
        _light(bpy, "AREA", (0.4, 0.2, 3.0), (0.2, 0.1, 0.0), energy=300.0, shape=shape, **sizes)

    return build


def _emissive_mesh(bpy):
    # a square out of view, tilted towards the visible plane
    bpy.ops.mesh.primitive_plane_add(size=1.5, location=(3.6, 0.0, 1.8), rotation=(0.0, -2.2, 0.0))
    bpy.context.object.data.materials.append(_emission(bpy, 40.0))


CASES = {
    # point and spot lights stand just outside the view: this test is about the light they give
    "point": (lambda bpy: _light(bpy, "POINT", (2.2, 0.5, 3.0), energy=300.0, shadow_soft_size=0.1), DELTA_SAMPLES),
    "spot": (lambda bpy: _light(bpy, "SPOT", (2.0, 1.8, 3.5), (0.3, 0.3, 0.0), energy=800.0, spot_size=1.0,
                                spot_blend=0.3, shadow_soft_size=0.05), DELTA_SAMPLES),
    "sun": (lambda bpy: _light(bpy, "SUN", (0.0, 0.0, 5.0), (0.4, 0.2, 0.0), energy=3.0, angle=math.radians(3)),
            DELTA_SAMPLES),
    "area_square": (_area("SQUARE", size=1.0), SAMPLED_SAMPLES),
    "area_rectangle": (_area("RECTANGLE", size=1.5, size_y=0.5), SAMPLED_SAMPLES),
    "area_disk": (_area("DISK", size=1.2), SAMPLED_SAMPLES),
    "area_ellipse": (_area("ELLIPSE", size=1.6, size_y=0.6), SAMPLED_SAMPLES),
    "world": (lambda bpy: _world(bpy, (0.5, 0.6, 0.8, 1.0), 1.5), SAMPLED_SAMPLES),
    "emissive_mesh": (_emissive_mesh, SAMPLED_SAMPLES),
}


def _plane_scene(bpy, case):
    """A diffuse plane filling the view, a small diffuse box casting a shadow, a camera above."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=30.0)
    bpy.context.object.data.materials.append(_diffuse(bpy, "plane", (0.8, 0.8, 0.8, 1.0)))
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(0.6, -0.4, 1.0))
    bpy.context.object.name = "box"
    bpy.context.object.data.materials.append(_diffuse(bpy, "box", (0.5, 0.7, 0.3, 1.0)))
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    cam.location = (0.0, 0.0, 8.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    _world(bpy, (0.0, 0.0, 0.0, 1.0), 0.0)
    add_light, (cycles_samples, gpugi_samples, _) = CASES[case]
    add_light(bpy)
    render = scene.render
    render.resolution_x = render.resolution_y = SIZE
    render.resolution_percentage = 100
    cycles = scene.cycles
    cycles.device, cycles.samples, cycles.max_bounces = "CPU", cycles_samples, 0
    cycles.use_adaptive_sampling = cycles.use_denoising = False
    scene.gpugi.samples = gpugi_samples
    scene.gpugi.noise_threshold = 0.0  # every pixel takes every sample, like Cycles here
    scene.gpugi.mode = "REFERENCE"  # direct light only, like Cycles with max bounces 0
    scene.gpugi.diffuse_bounces = 0
    scene.gpugi.denoise = False  # like Cycles here: light transport as rendered, pixel by pixel
    return scene


def _box3(values):
    """Mean of each pixel's 3x3 neighbourhood (edges repeated), per channel."""
    pad = [(1, 1), (1, 1)] + [(0, 0)] * (values.ndim - 2)
    padded = np.pad(values, pad, mode="edge")
    h, w = values.shape[:2]
    return sum(padded[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9.0


def _grow(mask):
    """``mask`` and every pixel next to it."""
    return _box3(mask.astype(np.float64)) > 0.0


def _edges(image, threshold=0.03):
    """Pixels near a box or cone edge: where a channel departs from its
    neighbourhood mean (a smooth falloff does not)."""
    rgb = image[..., :3]
    local = _box3(rgb)
    return _grow((np.abs(rgb - local) > threshold * local + 1e-3).any(axis=-1))


def _penumbra(shadowed, unshadowed):
    """Pixels the box shadows only in part (soft-shadow edges): neither fully
    lit nor fully dark compared with a render where the box casts no shadow."""
    ratio = shadowed[..., :3].mean(axis=-1) / np.maximum(unshadowed[..., :3].mean(axis=-1), 1e-6)
    return _grow((ratio > 0.02) & (ratio < 0.95))


@pytest.mark.cycles
@pytest.mark.parametrize("case", list(CASES))
def test_direct_light_on_a_diffuse_plane_matches_cycles(bpy_empty, tmp_path, case):
    bpy = bpy_empty
    scene = _plane_scene(bpy, case)
    ours = render_to_array(bpy, scene, "GPUGI", str(tmp_path / "gpugi.exr"))
    assert not LAST_RUN.get("error") and not LAST_RUN.get("warnings"), LAST_RUN
    cycles = render_to_array(bpy, scene, "CYCLES", str(tmp_path / "cycles.exr"))
    bpy.data.objects["box"].visible_shadow = False
    scene.cycles.samples = MASK_SAMPLES
    unshadowed = render_to_array(bpy, scene, "CYCLES", str(tmp_path / "unshadowed.exr"))
    assert ours.shape == cycles.shape == (SIZE, SIZE, 4)
    ours, cycles = ours[..., :3].astype(np.float64), cycles[..., :3].astype(np.float64)
    assert cycles.mean() > 0.05  # the light reaches the plane

    # image means per channel
    np.testing.assert_allclose(ours.mean(axis=(0, 1)), cycles.mean(axis=(0, 1)), rtol=0.03)

    # every pixel away from edges and soft-shadow borders (fully lit and fully shadowed ones included)
    smooth = ~(_edges(cycles) | _penumbra(cycles, unshadowed))
    assert smooth.mean() > 0.5
    relative = CASES[case][1][2]
    tolerance = relative * cycles + relative / 20
    worst = (np.abs(ours - cycles) / tolerance)[smooth].max()
    assert worst <= 1.0, f"worst pixel is {worst:.2f} times the tolerance"
