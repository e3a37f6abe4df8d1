"""Random Blender scenes (hypothesis) through the add-on's export and the
renderer: meshes with modifiers, instances, empty meshes, NaN vertices,
zero-scale objects, materials with nodes the engine does not know, every
light type. Every render either raises a GpuGiError or returns finite,
non-negative pixels, and the user's data is unchanged by the export."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from blender_addon.export import export_scene
from gpu_core.errors import GpuGiError
from gpu_core.renderer import Renderer
from gpu_core.settings import RenderSettings

pytestmark = pytest.mark.fuzz

FUZZ_EXAMPLES = max(1, int(os.environ.get("GPUGI_FUZZ_EXAMPLES", "150")) // 6)
_PRIMITIVES = ("cube", "plane", "sphere", "empty_mesh", "text")
_MODIFIERS = (None, "ARRAY", "SUBSURF", "SOLIDIFY", "MIRROR", "BEVEL")
_NODES = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlass", "ShaderNodeEmission",
          "ShaderNodeBsdfToon", "ShaderNodeSubsurfaceScattering", "ShaderNodeBsdfTranslucent")

objects = st.lists(st.tuples(
    st.sampled_from(_PRIMITIVES), st.sampled_from(_MODIFIERS), st.sampled_from(_NODES),
    st.sampled_from([1.0, 0.0, 1e-6, 1e4, -1.0]),  # scale, mirrored included
    st.tuples(*[st.floats(-5, 5)] * 3), st.booleans(),  # location, one NaN vertex
    st.integers(0, 3)), min_size=0, max_size=4)  # instances in a collection instance
lights = st.lists(st.tuples(st.sampled_from(["POINT", "SUN", "SPOT", "AREA"]),
                            st.sampled_from([0.0, 1e-6, 100.0, 1e12]), st.sampled_from([0.0, 0.1, 100.0])),
                  min_size=0, max_size=2)


def _build(bpy, shapes, light_rows) -> None:
    for kind, modifier, node, scale, location, nan_vertex, instances in shapes:
        if kind == "cube":
            bpy.ops.mesh.primitive_cube_add(location=location)
        elif kind == "plane":
            bpy.ops.mesh.primitive_plane_add(size=4, location=location)
        elif kind == "sphere":
            bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4, location=location)
        elif kind == "text":
            bpy.ops.object.text_add(location=location)
        else:
            mesh = bpy.data.meshes.new("empty")
            obj = bpy.data.objects.new("empty", mesh)
            bpy.context.collection.objects.link(obj)
            bpy.context.view_layer.objects.active = obj
        obj = bpy.context.view_layer.objects.active
        obj.scale = (scale, scale, abs(scale))
        if modifier is not None:
            obj.modifiers.new("fuzz", modifier)
        if nan_vertex and obj.type == "MESH" and len(obj.data.vertices):
            obj.data.vertices[0].co = (float("nan"), 0.0, float("inf"))
        material = bpy.data.materials.new("fuzz")
        tree = material.node_tree
        shader = tree.nodes.new(node)
        tree.links.new(shader.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
        if obj.data is not None and hasattr(obj.data, "materials"):
            obj.data.materials.append(material)
        if instances:
            collection = bpy.data.collections.new("fuzz")
            collection.objects.link(obj)
            for i in range(instances):
                holder = bpy.data.objects.new("instance", None)
                holder.instance_type, holder.instance_collection = "COLLECTION", collection
                holder.location = (i * 2.0, 0.0, 0.0)
                bpy.context.collection.objects.link(holder)
    for kind, energy, size in light_rows:
        bpy.ops.object.light_add(type=kind, location=(0, 0, 4))
        light = bpy.context.object.data
        light.energy = energy
        if kind == "AREA":
            light.size = size
        elif kind != "SUN":
            light.shadow_soft_size = size
    bpy.ops.object.camera_add(location=(0, -10, 6), rotation=(1.0, 0, 0))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.render.resolution_percentage = 100


def _user_data(bpy) -> list:
    """What the export must not change: every mesh's vertices, every object's transform and modifiers."""
    meshes = []
    for mesh in bpy.data.meshes:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        meshes.append((mesh.name, co.tobytes()))
    objects_ = [(o.name, tuple(o.matrix_world.col[3]), tuple(m.name for m in o.modifiers)) for o in bpy.data.objects]
    return [sorted(meshes), sorted(objects_, key=lambda row: row[0]), len(bpy.data.materials)]


@settings(max_examples=FUZZ_EXAMPLES, derandomize=True, database=None, deadline=None, print_blob=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(shapes=objects, light_rows=lights, mode=st.sampled_from(["gi", "reference"]))
def test_a_random_blend_scene_exports_and_renders_finite_pixels_or_says_why(bpy_empty, device, shapes, light_rows,
                                                                           mode):
    bpy = bpy_empty
    bpy.ops.wm.read_homefile(use_empty=True)
    _build(bpy, shapes, light_rows)
    before = _user_data(bpy)
    config = RenderSettings(mode=mode, samples=1, global_photons=500, caustic_photons=100, photon_k=8,
                            cache_seeds=8, gather_rays=4, diffuse_bounces=1)
    try:
        result = Renderer(device).render(export_scene(bpy.context.evaluated_depsgraph_get()), config)
    except GpuGiError as err:
        assert str(err)
    else:
        image = result.passes["Combined"]
        assert np.isfinite(image).all() and image.min() >= 0.0
    assert _user_data(bpy) == before
