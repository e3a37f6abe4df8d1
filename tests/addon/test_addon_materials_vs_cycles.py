"""Materials as Cycles renders them: a smooth sphere of each Principled
setting (rough metals and plastics, the specular layer, rough glass), the
Glossy and Glass nodes, textures on Roughness, Metallic and a normal map,
and Mix and Add Shaders (with a Transparent BSDF through a textured Fac),
under a small point light and under a uniform world, rendered by Cycles and by GPU GI's path tracer in the same process.

Image means agree within 3% per channel; the per-pixel error on display
values (Reinhard, then sRGB) stays within DISPLAY_TOLERANCE, which covers
the two renders' noise at these sample counts (two Cycles renders with
different seeds differ by up to half of it).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import render_to_array

from blender_addon.final import LAST_RUN

SIZE = 48
CYCLES_SAMPLES, GPUGI_SAMPLES = 512, 256
MEAN_TOLERANCE = 0.03
DISPLAY_TOLERANCE = 0.06  # relative RMSE of display values

# name -> Principled inputs (or a shader node and its inputs)
MATERIALS = {
    **{f"plastic_r{r}": dict(roughness=r) for r in (0.05, 0.3, 0.7, 1.0)},
    **{f"metal_r{r}": dict(metallic=1.0, roughness=r) for r in (0.05, 0.3, 0.7, 1.0)},
    "glass_r0.1": dict(transmission=1.0, roughness=0.1),
    "glass_r0.5": dict(transmission=1.0, roughness=0.5),
    **{f"specular_{level}": {"roughness": 0.4, "Specular IOR Level": level} for level in (0.0, 0.5, 1.0)},
    "glossy_node": dict(node="ShaderNodeBsdfGlossy", roughness=0.3),
    "glass_node": dict(node="ShaderNodeBsdfGlass", roughness=0.2),
    "metal_anisotropic": {"metallic": 1.0, "roughness": 0.4, "Anisotropic": 0.8, "Anisotropic Rotation": 0.1},
    "plastic_anisotropic": {"roughness": 0.3, "Anisotropic": 1.0},
    "glossy_node_anisotropic": dict(node="ShaderNodeBsdfGlossy", roughness=0.4, Anisotropy=-0.5),
    "metal_r0.7_ggx": dict(metallic=1.0, roughness=0.7, distribution="GGX"),
    "diffuse_rough": {"roughness": 0.5, "Diffuse Roughness": 0.8},
    "diffuse_node_rough": dict(node="ShaderNodeBsdfDiffuse", roughness=1.0),
    "textured": dict(textured="values"),
    "normal_map": dict(textured="normals"),
    "mix": dict(mixed="ShaderNodeMixShader"),
    "add": dict(mixed="ShaderNodeAddShader"),
    "cutout": dict(mixed="cutout"),
    "tinted_transparent": dict(mixed="tinted"),
}
BASE = (0.8, 0.45, 0.2, 1.0)


def _textured(bpy, mat, what):
    """Principled with (``what`` "values") a packed texture, roughness
    0.25/0.6 in green and metallic 0/1 in blue, through Separate Color, or
    ("normals") a normal map tilting the normal around the sphere: Non-Color
    byte images on the sphere's UVs."""
    tree = mat.node_tree
    node = tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = BASE

    def image(name, texels):
        img = bpy.data.images.new(name, len(texels), 1)
        img.colorspace_settings.name = "Non-Color"
        img.pixels = [c for texel in texels for c in (*texel, 1.0)]
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = img
        return tex

    if what == "values":
        packed = image("packed", [(1.0, 0.25, 0.0), (1.0, 0.6, 1.0)] * 4)
        separate = tree.nodes.new("ShaderNodeSeparateColor")
        tree.links.new(packed.outputs["Color"], separate.inputs["Color"])
        tree.links.new(separate.outputs["Green"], node.inputs["Roughness"])
        tree.links.new(separate.outputs["Blue"], node.inputs["Metallic"])
        return mat
    angles = 2 * np.pi * np.arange(8) / 8
    tilts = np.stack([0.4 * np.sin(angles), 0.3 * np.cos(angles)], axis=1)
    normals = np.concatenate([tilts, np.sqrt(1.0 - (tilts ** 2).sum(axis=1, keepdims=True))], axis=1)
    bumps = image("bumps", [tuple(0.5 * n + 0.5) for n in normals])
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(bumps.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], node.inputs["Normal"])
    return mat


def _mixed(bpy, mat, how):
    """A Mix Shader (Fac 0.4) or an Add Shader of a Diffuse BSDF and a
    rough Glossy BSDF, or ("cutout") a Principled BSDF mixed with a
    Transparent BSDF by stripes of an image on the Fac, or ("tinted") with
    an orange Transparent BSDF at Fac 0.4."""
    tree = mat.node_tree
    out = tree.nodes["Material Output"]
    if how == "tinted":
        node = tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = BASE
        mix = tree.nodes.new("ShaderNodeMixShader")
        transparent = tree.nodes.new("ShaderNodeBsdfTransparent")
        transparent.inputs["Color"].default_value = (0.9, 0.5, 0.2, 1.0)
        mix.inputs["Fac"].default_value = 0.4
        tree.links.new(transparent.outputs[0], mix.inputs[1])
        tree.links.new(node.outputs[0], mix.inputs[2])
        tree.links.new(mix.outputs[0], out.inputs["Surface"])
        return mat
    if how == "cutout":
        node = tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = BASE
        mix = tree.nodes.new("ShaderNodeMixShader")
        transparent = tree.nodes.new("ShaderNodeBsdfTransparent")
        stripes = bpy.data.images.new("stripes", 8, 1)
        stripes.colorspace_settings.name = "Non-Color"
        stripes.pixels = [c for i in range(8) for c in ((1.0,) * 3 if i % 2 else (0.2,) * 3) + (1.0,)]
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = stripes
        tree.links.new(tex.outputs["Color"], mix.inputs["Fac"])
        tree.links.new(transparent.outputs[0], mix.inputs[1])
        tree.links.new(node.outputs[0], mix.inputs[2])
        tree.links.new(mix.outputs[0], out.inputs["Surface"])
        return mat
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    diffuse, glossy = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = BASE
    glossy.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    glossy.inputs["Roughness"].default_value = 0.3
    combine = tree.nodes.new(how)
    shaders = [socket for socket in combine.inputs if socket.type == "SHADER"]
    tree.links.new(diffuse.outputs[0], shaders[0])
    tree.links.new(glossy.outputs[0], shaders[1])
    if how == "ShaderNodeMixShader":
        combine.inputs["Fac"].default_value = 0.4
    tree.links.new(combine.outputs[0], out.inputs["Surface"])
    return mat


def _material(bpy, name, spec):
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    spec = dict(spec)
    if "textured" in spec:
        return _textured(bpy, mat, spec["textured"])
    if "mixed" in spec:
        return _mixed(bpy, mat, spec["mixed"])
    node_kind = spec.pop("node", None)
    distribution = spec.pop("distribution", None)
    if node_kind is None:
        node = tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = BASE
        node.distribution = distribution or node.distribution
        for key, value in spec.items():
            socket = {"roughness": "Roughness", "metallic": "Metallic", "transmission": "Transmission Weight"}.get(key, key)
            node.inputs[socket].default_value = value
        return mat
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(node_kind)
    node.inputs["Color"].default_value = BASE
    for key, value in spec.items():
        node.inputs["Roughness" if key == "roughness" else key].default_value = value
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def _scene(bpy, material, lighting):
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0)
    sphere = bpy.context.object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_material(bpy, material, MATERIALS[material]))
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    cam.location, cam.rotation_euler = (0.0, -4.0, 0.0), (np.pi / 2, 0.0, 0.0)
    cam.data.lens = 60.0
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("world")
    background = world.node_tree.nodes["Background"]
    if lighting == "point":
        light = bpy.data.objects.new("light", bpy.data.lights.new("light", "POINT"))
        light.data.energy, light.data.shadow_soft_size = 200.0, 0.1
        light.location = (1.5, -2.5, 2.0)
        scene.collection.objects.link(light)
        background.inputs["Strength"].default_value = 0.0
    else:
        background.inputs["Color"].default_value = (0.6, 0.7, 0.9, 1.0)
        background.inputs["Strength"].default_value = 1.0
        # a floor below gives the world something to be reflected against
        bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, -1.0))
        floor = bpy.data.materials.new("floor")
        floor.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.3, 0.3, 0.3, 1.0)
        floor.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
        bpy.context.object.data.materials.append(floor)
    scene.world = world
    render = scene.render
    render.resolution_x = render.resolution_y = SIZE
    render.resolution_percentage = 100
    cycles = scene.cycles
    cycles.device, cycles.samples = "CPU", CYCLES_SAMPLES
    cycles.use_adaptive_sampling = cycles.use_denoising = False
    cycles.max_bounces, cycles.diffuse_bounces, cycles.glossy_bounces = 8, 1, 8
    cycles.transmission_bounces, cycles.transparent_max_bounces = 8, 8
    cycles.blur_glossy, cycles.sample_clamp_direct, cycles.sample_clamp_indirect = 0.0, 0.0, 0.0
    cycles.pixel_filter_type, cycles.filter_width = "BOX", 1.0
    gpugi = scene.gpugi
    gpugi.mode, gpugi.samples, gpugi.denoise = "REFERENCE", GPUGI_SAMPLES, False
    gpugi.noise_threshold = 0.0  # every pixel takes every sample, as Cycles does here
    gpugi.diffuse_bounces, gpugi.max_bounces = 1, 8
    gpugi.clamp = 0.0
    return scene


def display(linear: np.ndarray) -> np.ndarray:
    y = np.clip(linear, 0.0, None)
    y = y / (1.0 + y)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)


def compare(bpy, tmp_path, material, lighting, boost: int = 1) -> tuple[np.ndarray, float]:
    """Per-channel mean ratio GPU GI / Cycles and the display RMSE, both
    renderers at ``boost`` times their samples."""
    scene = _scene(bpy, material, lighting)
    scene.cycles.samples, scene.gpugi.samples = CYCLES_SAMPLES * boost, GPUGI_SAMPLES * boost
    ours = render_to_array(bpy, scene, "GPUGI", str(tmp_path / "gpugi.exr"))[..., :3].astype(np.float64)
    assert not LAST_RUN.get("error") and not LAST_RUN.get("warnings"), LAST_RUN
    theirs = render_to_array(bpy, scene, "CYCLES", str(tmp_path / "cycles.exr"))[..., :3].astype(np.float64)
    assert np.isfinite(ours).all()
    a, b = display(ours), display(theirs)
    return ours.mean(axis=(0, 1)) / theirs.mean(axis=(0, 1)), float(np.sqrt(((a - b) ** 2).mean()) / b.mean())


# The near-mirror highlight of a small light is a few very bright pixels
# that both renderers find by chance: at the samples above two renders of
# either one with different seeds differ by more than the tolerance (metal
# roughness 0.05: display RMSE 0.19 between two Cycles renders, 0.22
# between two of ours, 0.16 between ours and Cycles). These cases render
# at NOISE_BOOST times the samples.
NOISE_LIMITED = {("metal_r0.05", "point"), ("plastic_r0.05", "point")}
NOISE_BOOST = 16
# Beyond the test's samples (README, Looks and units), measured: rough
# glass under the small point light is a few bright pixels (the light's
# highlight and its paths through the sphere, on a black image) that Cycles
# finds by chance. At 16 times its samples two Cycles renders with seeds 0
# and 1 differ in their means by 3% (roughness 0.1) and by a relative
# display RMSE of 0.7-1.2, twelve to twenty times the tolerance. GPU GI at
# 32 times its samples against Cycles at 32 times: 0.986-0.990 (roughness
# 0.1) and 1.001-1.005 (Glass node) of its means; roughness 0.5 at 8 times
# both 1.004-1.024. Cycles' evaluation of refraction through microfacets
# that face away (the cosines to the half vector by their absolute
# values), which GPU GI follows, moved roughness 0.5 from 0.96 there.
UNSETTLED = {("glass_r0.1", "point"), ("glass_r0.5", "point"), ("glass_node", "point")}
UNSETTLED_MARK = pytest.mark.xfail(strict=True, reason="Cycles' own noise is above the tolerance")
CASES = [pytest.param(material, lighting, marks=UNSETTLED_MARK)
         if (material, lighting) in UNSETTLED else (material, lighting)
         for material in MATERIALS for lighting in ("point", "world")]


@pytest.mark.cycles
@pytest.mark.slow
@pytest.mark.parametrize("material, lighting", CASES)
def test_sphere_material_matches_cycles(bpy_empty, tmp_path, material, lighting):
    boost = NOISE_BOOST if (material, lighting) in NOISE_LIMITED else 1
    ratio, error = compare(bpy_empty, tmp_path, material, lighting, boost)
    print(f"{material} {lighting}: mean ratio {np.round(ratio, 3)}, display RMSE {error:.3f}")
    np.testing.assert_allclose(ratio, 1.0, atol=MEAN_TOLERANCE)
    assert error < DISPLAY_TOLERANCE
