"""Depsgraph export: meshes, instances, normals, UVs, materials, lights, world, camera."""

import math
import os
import time

import numpy as np
import pytest

from blender_addon.export import ExportError, export_scene
from blender_addon.export.inverse import affine_inverse, cofactors
from blender_addon.export.mesh import _times, _unit_rows
from blender_addon.final import LAST_RUN
from conftest import other_threads_cpu_ms, render_to_array
from gpu_core.scene import (AREA_ELLIPSE, AREA_RECTANGLE, CAMERA_ORTHO, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN,
                            TEXTURE_LUMINANCE, Materials)


def _camera(bpy, location=(0, 0, 10), lens=50.0):
    data = bpy.data.cameras.new("cam")
    data.lens = lens
    obj = bpy.data.objects.new("cam", data)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def _export(bpy):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return export_scene(depsgraph)


def _material(bpy, kind, **inputs):
    mat = bpy.data.materials.new(kind)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat, node


@pytest.fixture
def bpy(bpy_empty):
    _camera(bpy_empty)
    return bpy_empty


def test_modifiers_are_applied_and_user_mesh_is_unchanged(bpy):
    bpy.ops.mesh.primitive_cube_add(size=2)
    cube = bpy.context.object
    cube.modifiers.new("sub", "SUBSURF").levels = 1
    scene = _export(bpy)
    assert scene.triangle_count == 6 * 4 * 2
    assert len(cube.data.vertices) == 8 and len(cube.modifiers) == 1


def test_collection_instances_are_exported_with_their_matrices(bpy):
    coll = bpy.data.collections.new("src")
    bpy.ops.mesh.primitive_plane_add(size=1)
    plane = bpy.context.object
    for c in list(plane.users_collection):
        c.objects.unlink(plane)
    coll.objects.link(plane)
    for x in (5.0, -5.0):
        inst = bpy.data.objects.new(f"inst{x}", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = coll
        inst.location = (x, 0, 0)
        bpy.context.scene.collection.objects.link(inst)
    scene = _export(bpy)
    assert scene.triangle_count == 4
    centers = sorted(scene.triangles.reshape(-1, 3)[:, 0].reshape(2, -1).mean(axis=1))
    np.testing.assert_allclose(centers, [-5.0, 5.0], atol=0.5)


def test_geometry_nodes_instances_are_exported(bpy):
    bpy.ops.mesh.primitive_plane_add(size=4)  # four points to instance on
    plane = bpy.context.object
    group = bpy.data.node_groups.new("scatter", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    g_in, g_out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    on_points, cube = nodes.new("GeometryNodeInstanceOnPoints"), nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.5, 0.5, 0.5)
    links.new(g_in.outputs[0], on_points.inputs["Points"])
    links.new(cube.outputs["Mesh"], on_points.inputs["Instance"])
    links.new(on_points.outputs["Instances"], g_out.inputs[0])
    plane.modifiers.new("gn", "NODES").node_group = group
    scene = _export(bpy)
    assert scene.triangle_count == 4 * 12
    xs = np.unique(np.round(scene.triangles.reshape(-1, 3)[:, 0], 3))
    assert xs.min() == pytest.approx(-2.25) and xs.max() == pytest.approx(2.25)


def test_flat_smooth_and_custom_normals(bpy):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(-3, 0, 0))
    flat = bpy.context.object
    bpy.ops.object.shade_flat()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(3, 0, 0))
    bpy.ops.object.shade_smooth()
    bpy.ops.mesh.primitive_plane_add(size=1, location=(0, 5, 0), rotation=(0.5, 0, 0))
    custom = bpy.context.object
    custom.data.normals_split_custom_set_from_vertices([(1.0, 0.0, 0.0)] * len(custom.data.vertices))
    scene = _export(bpy)
    face_n = np.cross(scene.triangles[:, 1] - scene.triangles[:, 0], scene.triangles[:, 2] - scene.triangles[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    corner_vs_face = np.einsum("tcj,tj->tc", scene.normals, face_n).min(axis=1)
    centers = scene.triangles.mean(axis=1)
    on_flat, on_smooth, on_custom = centers[:, 0] < -1.5, centers[:, 0] > 1.5, centers[:, 1] > 4
    assert len(flat.data.polygons) > 0
    np.testing.assert_allclose(corner_vs_face[on_flat], 1.0, atol=1e-4)
    assert corner_vs_face[on_smooth].min() < 0.995  # flat faces give 1 within 1e-4
    np.testing.assert_allclose(scene.normals[on_custom].reshape(-1, 3), np.tile([1.0, 0, 0], (6, 1)), atol=1e-4)


def test_uvs_and_material_indices(bpy):
    bpy.ops.mesh.primitive_plane_add(size=2)
    plane = bpy.context.object
    red, _ = _material(bpy, "ShaderNodeBsdfDiffuse", Color=(1, 0, 0, 1))
    blue, _ = _material(bpy, "ShaderNodeBsdfDiffuse", Color=(0, 0, 1, 1))
    plane.data.materials.append(red)
    plane.data.materials.append(blue)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.quads_convert_to_tris()
    bpy.ops.object.mode_set(mode="OBJECT")
    plane.data.polygons[1].material_index = 1
    scene = _export(bpy)
    assert scene.uvs.min() == 0.0 and scene.uvs.max() == 1.0
    colors = scene.materials.base_color[scene.material_ids]
    assert sorted(map(tuple, colors)) == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]


def test_every_supported_shader_maps_to_a_material_row(bpy):
    rows = {}
    specs = [
        ("ShaderNodeBsdfPrincipled", {"Base Color": (0.2, 0.3, 0.4, 1), "Metallic": 0.25, "Roughness": 0.3,
                                      "Transmission Weight": 0.5, "IOR": 1.33, "Alpha": 0.7,
                                      "Emission Color": (1, 0.5, 0, 1), "Emission Strength": 2.0}),
        ("ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.5, 0.1, 1)}),
        ("ShaderNodeBsdfGlossy", {"Color": (0.9, 0.8, 0.7, 1), "Roughness": 0.0}),
        ("ShaderNodeBsdfGlass", {"Color": (1, 1, 1, 1), "IOR": 1.45}),
        ("ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": 7.0}),
    ]
    for i, (kind, inputs) in enumerate(specs):
        bpy.ops.mesh.primitive_plane_add(size=1, location=(2 * i, 0, 0))
        mat, _ = _material(bpy, kind, **inputs)
        bpy.context.object.data.materials.append(mat)
        rows[kind] = i + 1  # row 0 is the default material
    m = _export(bpy).materials
    names = m.names
    get = lambda kind: names.index(kind)  # noqa: E731
    p = get("ShaderNodeBsdfPrincipled")
    np.testing.assert_allclose(m.base_color[p], (0.2, 0.3, 0.4), atol=1e-6)
    assert (m.metallic[p], m.roughness[p], m.transmission[p], m.ior[p], m.alpha[p]) == pytest.approx((0.25, 0.3, 0.5, 1.33, 0.7))
    np.testing.assert_allclose(m.emission[p], (2.0, 1.0, 0.0))
    assert m.metallic[get("ShaderNodeBsdfGlossy")] == 1.0
    assert m.transmission[get("ShaderNodeBsdfGlass")] == 1.0 and m.ior[get("ShaderNodeBsdfGlass")] == pytest.approx(1.45)
    np.testing.assert_allclose(m.emission[get("ShaderNodeEmission")], (7.0, 7.0, 7.0))
    np.testing.assert_allclose(m.base_color[get("ShaderNodeBsdfDiffuse")], (0.5, 0.5, 0.1), atol=1e-6)


def test_unsupported_nodes_fall_back_with_a_warning(bpy):
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, _ = _material(bpy, "ShaderNodeBsdfToon")
    bpy.context.object.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=1, location=(3, 0, 0))
    mat2, node = _material(bpy, "ShaderNodeBsdfDiffuse")
    noise = mat2.node_tree.nodes.new("ShaderNodeTexNoise")
    mat2.node_tree.links.new(noise.outputs["Color"], node.inputs["Color"])
    bpy.context.object.data.materials.append(mat2)
    scene = _export(bpy)
    assert any("ShaderNodeBsdfToon" in w for w in scene.warnings)
    assert any("ShaderNodeTexNoise" in w for w in scene.warnings)
    assert scene.triangle_count == 4


def test_image_texture_on_base_color_is_exported_linear(bpy):
    image = bpy.data.images.new("tex", 2, 1)
    image.pixels = [0.5, 0.5, 0.5, 1.0, 1.0, 0.0, 0.0, 1.0]
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    bpy.context.object.data.materials.append(mat)
    scene = _export(bpy)
    row = scene.materials.names.index("ShaderNodeBsdfPrincipled")
    assert scene.materials.texture_id[row] == 0
    pixels = scene.textures[0]
    assert pixels.shape == (1, 2, 4)
    # a byte image in sRGB: 0.5 is about 0.214 in linear
    assert pixels[0, 0, 0] == pytest.approx(0.214, abs=0.01)
    assert pixels[0, 1, 0] == pytest.approx(1.0)


def _image(bpy, name, pixels, colorspace="Non-Color"):
    image = bpy.data.images.new(name, len(pixels) // 4, 1)
    image.colorspace_settings.name = colorspace
    image.pixels = pixels
    return image


def test_textures_on_roughness_metallic_and_a_normal_map_are_exported(bpy):
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    orm = nodes.new("ShaderNodeTexImage")
    orm.image = _image(bpy, "orm", [1.0, 0.3, 0.6, 1.0])
    separate = nodes.new("ShaderNodeSeparateColor")
    links.new(orm.outputs["Color"], separate.inputs["Color"])
    links.new(separate.outputs["Green"], node.inputs["Roughness"])
    links.new(separate.outputs["Blue"], node.inputs["Metallic"])
    normal_map = nodes.new("ShaderNodeNormalMap")
    normal_map.inputs["Strength"].default_value = 0.7
    bumps = nodes.new("ShaderNodeTexImage")
    bumps.image = _image(bpy, "bumps", [0.5, 0.5, 1.0, 1.0])
    links.new(bumps.outputs["Color"], normal_map.inputs["Color"])
    links.new(normal_map.outputs["Normal"], node.inputs["Normal"])
    bpy.context.object.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=1, location=(3, 0, 0))
    glossy, glossy_node = _material(bpy, "ShaderNodeBsdfGlossy")
    rough = glossy.node_tree.nodes.new("ShaderNodeTexImage")
    rough.image = _image(bpy, "rough", [0.2, 0.2, 0.2, 0.9])
    glossy.node_tree.links.new(rough.outputs["Alpha"], glossy_node.inputs["Roughness"])
    bpy.context.object.data.materials.append(glossy)
    scene = _export(bpy)
    m = scene.materials
    row = m.names.index("ShaderNodeBsdfPrincipled")
    orm_id, normal_id = m.roughness_texture[row], m.normal_texture[row]
    assert orm_id >= 0 and m.metallic_texture[row] == orm_id and (m.roughness_channel[row], m.metallic_channel[row]) == (1, 2)
    # Non-Color: as stored, to a step of a byte image
    assert scene.textures[orm_id][0, 0, :3] == pytest.approx([1.0, 0.3, 0.6], abs=1 / 255)
    assert normal_id >= 0 and normal_id != orm_id and m.normal_strength[row] == pytest.approx(0.7)
    assert m.texture_id[row] == -1
    row = m.names.index("ShaderNodeBsdfGlossy")
    assert m.roughness_channel[row] == 3 and scene.textures[m.roughness_texture[row]][0, 0, 3] == pytest.approx(0.9, abs=1 / 255)
    assert not any("Roughness" in w or "Metallic" in w or "Normal" in w for w in scene.warnings)


def _normal_mapped(bpy):
    """A Principled material with a flat normal map on its Normal input."""
    mat, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    normal_map = mat.node_tree.nodes.new("ShaderNodeNormalMap")
    bumps = mat.node_tree.nodes.new("ShaderNodeTexImage")
    bumps.image = _image(bpy, "flat", [0.5, 0.5, 1.0, 1.0])
    mat.node_tree.links.new(bumps.outputs["Color"], normal_map.inputs["Color"])
    mat.node_tree.links.new(normal_map.outputs["Normal"], node.inputs["Normal"])
    return mat


def test_meshes_under_a_normal_map_carry_mikktspace_corner_tangents(bpy):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(0, 0, 0))
    sphere = bpy.context.object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_normal_mapped(bpy))
    sphere.scale = (1.0, 1.0, -1.0)  # mirrored: the bitangents' signs turn with it
    bpy.ops.mesh.primitive_plane_add(size=1, location=(4, 0, 0))  # no normal map: no tangents of its own
    scene = _export(bpy)
    on_sphere = np.linalg.norm(scene.triangles.mean(axis=1), axis=1) < 2
    assert scene.tangents.shape == (len(scene.triangles), 3, 4) and scene.has_tangents()
    t, sign = scene.tangents[on_sphere, :, :3], scene.tangents[on_sphere, :, 3]
    np.testing.assert_allclose(np.linalg.norm(t, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(np.abs(np.einsum("tcj,tcj->tc", t, scene.normals[on_sphere])), 0.0, atol=2e-3)
    # Blender's own MikkTSpace tangents at each triangle's corners, mirrored
    # by the object's scale (the corner order reversed with the winding)
    mesh = sphere.data
    mesh.calc_tangents(uvmap=mesh.uv_layers.active.name)
    mesh.calc_loop_triangles()
    loops = np.array([tri.loops[:] for tri in mesh.loop_triangles])[:, ::-1]
    want_t = np.array([loop.tangent[:] for loop in mesh.loops])[loops] * [1.0, 1.0, -1.0]
    want_sign = -np.array([loop.bitangent_sign for loop in mesh.loops])[loops]
    np.testing.assert_allclose(t, want_t / np.linalg.norm(want_t, axis=-1, keepdims=True), atol=1e-5)
    np.testing.assert_array_equal(sign, want_sign)
    np.testing.assert_array_equal(scene.tangents[~on_sphere], 0.0)


def test_anisotropic_shaders_export_their_stretch_and_the_tangent_they_follow(bpy):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(0, 0, 0))
    radial, node = _material(bpy, "ShaderNodeBsdfPrincipled", Anisotropic=0.7)
    node.inputs["Anisotropic Rotation"].default_value = 0.25
    bpy.context.object.data.materials.append(radial)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(5, 0, 0))
    along_uv, glossy = _material(bpy, "ShaderNodeBsdfGlossy", Anisotropy=-0.4)
    tangent = along_uv.node_tree.nodes.new("ShaderNodeTangent")
    tangent.direction_type = "UV_MAP"
    along_uv.node_tree.links.new(tangent.outputs["Tangent"], glossy.inputs["Tangent"])
    bpy.context.object.data.materials.append(along_uv)
    scene = _export(bpy)
    m = scene.materials
    row = m.names.index("ShaderNodeBsdfPrincipled")
    assert m.anisotropy[row] == pytest.approx(0.7) and m.anisotropic_rotation[row] == pytest.approx(0.25)
    assert m.anisotropy[m.names.index("ShaderNodeBsdfGlossy")] == pytest.approx(-0.4)
    assert scene.has_tangents() and not any("anisotropy" in w for w in scene.warnings)
    centres = scene.triangles.mean(axis=1)
    first = centres[:, 0] < 2.5
    # radial about the object's Z: horizontal, square to the corner's own direction from the axis
    t, corners = scene.tangents[first, :, :3], scene.triangles[first]
    np.testing.assert_allclose(np.linalg.norm(t, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(t[..., 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(np.einsum("tcj,tcj->tc", t[..., :2], corners[..., :2]), 0.0, atol=1e-5)
    # the UV map's: MikkTSpace's, sign in w
    assert set(np.unique(scene.tangents[~first, :, 3])) <= {-1.0, 1.0}


def test_a_material_edit_that_adds_a_normal_map_gives_the_mesh_its_tangents(bpy):
    from blender_addon.export.sync import SceneSync, read_updates

    bpy.ops.mesh.primitive_plane_add(size=1)
    plain, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    bpy.context.object.data.materials.append(plain)
    sync, camera = SceneSync(), _export(bpy).camera
    first, _ = sync.export(bpy.context.evaluated_depsgraph_get(), camera)
    assert len(first.tangents) == 0
    updates = []
    handler = lambda scene, depsgraph: updates.extend(read_updates(depsgraph))  # noqa: E731
    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        mapped = _normal_mapped(bpy)
        bpy.context.object.data.materials[0] = mapped
        bpy.context.evaluated_depsgraph_get().update()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    second, changed = sync.export(bpy.context.evaluated_depsgraph_get(), camera, updates)
    assert "geometry" in changed and second.tangents.shape == (2, 3, 4)
    np.testing.assert_allclose(np.abs(second.tangents[..., 0]), 1.0, atol=1e-5)  # the plane's U runs along x


def test_rough_diffuse_is_exported_and_thin_film_named_in_the_warnings(bpy):
    bpy.ops.mesh.primitive_plane_add(size=1)
    principled, _ = _material(bpy, "ShaderNodeBsdfPrincipled", **{"Diffuse Roughness": 0.5,
                                                                    "Thin Film Thickness": 300.0})
    bpy.context.object.data.materials.append(principled)
    bpy.ops.mesh.primitive_plane_add(size=1, location=(2, 0, 0))
    diffuse, _ = _material(bpy, "ShaderNodeBsdfDiffuse", Roughness=0.3)
    bpy.context.object.data.materials.append(diffuse)
    scene = _export(bpy)
    m = scene.materials
    assert m.diffuse_roughness[m.names.index("ShaderNodeBsdfPrincipled")] == pytest.approx(0.5)
    assert m.diffuse_roughness[m.names.index("ShaderNodeBsdfDiffuse")] == pytest.approx(0.3)
    assert any("thin film" in w for w in scene.warnings)
    assert not any("Roughness" in w for w in scene.warnings)


@pytest.mark.parametrize("kind", ["ShaderNodeBsdfPrincipled", "ShaderNodeBsdfGlossy", "ShaderNodeBsdfGlass"])
def test_the_ggx_distribution_exports_single_scattering(bpy, kind):
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, node = _material(bpy, kind)
    bpy.context.object.data.materials.append(mat)
    m = _export(bpy).materials
    assert m.single_scatter[m.names.index(kind)] == 0  # Multiscatter GGX, the default
    node.distribution = "GGX"
    scene = _export(bpy)
    m = scene.materials
    assert m.single_scatter[m.names.index(kind)] == 1 and not any("distribution" in w for w in scene.warnings)


@pytest.mark.parametrize("kind, distribution", [("ShaderNodeBsdfGlossy", "BECKMANN"),
                                                 ("ShaderNodeBsdfGlossy", "ASHIKHMIN_SHIRLEY"),
                                                 ("ShaderNodeBsdfGlass", "BECKMANN")])
def test_other_distributions_are_named_in_the_warnings(bpy, kind, distribution):
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, node = _material(bpy, kind)
    bpy.context.object.data.materials.append(mat)
    node.distribution = distribution
    warned = [w for w in _export(bpy).warnings if "distribution" in w]
    assert len(warned) == 1 and node.name in warned[0] and "Multiscatter GGX" in warned[0]


def test_a_bump_node_on_normal_is_named_in_the_warnings(bpy):
    bpy.ops.mesh.primitive_plane_add(size=1)
    mat, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    bump = mat.node_tree.nodes.new("ShaderNodeBump")
    mat.node_tree.links.new(bump.outputs["Normal"], node.inputs["Normal"])
    bpy.context.object.data.materials.append(mat)
    scene = _export(bpy)
    assert any("ShaderNodeBump" in w for w in scene.warnings)
    assert scene.materials.normal_texture[0] == -1


def _light(bpy, kind, location=(0, 0, 3), rotation=(0, 0, 0), **props):
    data = bpy.data.lights.new(kind, kind)
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(kind, data)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def test_every_light_type_exports_its_parameters(bpy):
    _light(bpy, "POINT", energy=100, color=(1, 0.5, 0.25), shadow_soft_size=0.3)
    _light(bpy, "SPOT", rotation=(math.pi / 2, 0, 0), energy=50, spot_size=1.0, spot_blend=0.4)
    _light(bpy, "SUN", energy=3, angle=0.1)
    _light(bpy, "AREA", energy=20, shape="RECTANGLE", size=2.0, size_y=0.5)
    _light(bpy, "AREA", energy=20, shape="DISK", size=1.5)
    lights = _export(bpy).lights
    kinds = list(lights.kind)
    point, spot, sun = kinds.index(LIGHT_POINT), kinds.index(LIGHT_SPOT), kinds.index(LIGHT_SUN)
    np.testing.assert_allclose(lights.power[point], (100, 50, 25))
    assert lights.radius[point] == pytest.approx(0.3)
    assert lights.spot_angle[spot] == pytest.approx(1.0) and lights.spot_blend[spot] == pytest.approx(0.4)
    np.testing.assert_allclose(lights.direction[spot], (0, 1, 0), atol=1e-6)  # -Z rotated 90 degrees about X
    assert lights.sun_angle[sun] == pytest.approx(0.1)
    np.testing.assert_allclose(lights.direction[sun], (0, 0, -1), atol=1e-6)
    areas = [i for i, k in enumerate(kinds) if k == LIGHT_AREA]
    rect = next(i for i in areas if lights.shape[i] == AREA_RECTANGLE)
    disk = next(i for i in areas if lights.shape[i] == AREA_ELLIPSE)
    np.testing.assert_allclose(lights.axis_u[rect], (2, 0, 0), atol=1e-6)
    np.testing.assert_allclose(lights.axis_v[rect], (0, 0.5, 0), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(lights.axis_v[disk]), 1.5, atol=1e-6)


def test_world_background_colour_times_strength(bpy):
    world = bpy.data.worlds.new("w")
    bpy.context.scene.world = world
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.2, 0.4, 0.6, 1)
    bg.inputs["Strength"].default_value = 2.5
    np.testing.assert_allclose(_export(bpy).world_color, (0.5, 1.0, 1.5), rtol=1e-6)


def test_perspective_camera_window_with_sensor_fit_and_shift(bpy):
    scene = bpy.context.scene
    cam = scene.camera.data
    cam.lens, cam.sensor_width, cam.sensor_fit = 50.0, 36.0, "AUTO"
    cam.shift_x = 0.1
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 32, 100
    window = _export(bpy).camera.window
    half = 18.0 / 50.0
    np.testing.assert_allclose(window, (-half + 2 * half * 0.1, half + 2 * half * 0.1, -half / 2, half / 2), atol=1e-5)
    cam.sensor_fit, cam.sensor_height = "VERTICAL", 24.0
    window = _export(bpy).camera.window
    np.testing.assert_allclose(window[2:], (-12.0 / 50.0, 12.0 / 50.0), atol=1e-5)


def test_orthographic_camera_clipping_percentage_and_border(bpy):
    scene = bpy.context.scene
    cam = scene.camera.data
    cam.type, cam.ortho_scale, cam.clip_start, cam.clip_end = "ORTHO", 4.0, 0.5, 50.0
    render = scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = 100, 50, 50
    render.use_border, render.border_min_x, render.border_max_x = True, 0.2, 0.6
    render.border_min_y, render.border_max_y = 0.0, 1.0
    camera = _export(bpy).camera
    assert camera.kind == CAMERA_ORTHO
    assert (camera.width, camera.height) == (50, 25)
    np.testing.assert_allclose(camera.window, (-2, 2, -1, 1), atol=1e-6)
    assert (camera.clip_start, camera.clip_end) == (0.5, 50.0)
    assert camera.border == (10, 0, 30, 25)


def test_missing_camera_is_a_clear_export_error(bpy_empty):
    with pytest.raises(ExportError, match="no active camera"):
        export_scene(bpy_empty.context.evaluated_depsgraph_get())


def test_panoramic_camera_is_a_clear_export_error(bpy):
    bpy.context.scene.camera.data.type = "PANO"
    with pytest.raises(ExportError, match="panoramic"):
        _export(bpy)


def _face_normals(tris):
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_unit_rows_and_row_products_agree_with_numpys_row_by_row_forms():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(200, 3, 3))
    v[7, 1] = 0.0  # a zero vector stays zero
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="raise", divide="raise"):
        unit = _unit_rows(v)
    np.testing.assert_array_equal(unit, np.where(length > 0, v / np.where(length > 0, length, 1.0), 0.0))
    assert not unit[7, 1].any()
    matrix = rng.normal(size=(3, 3))
    np.testing.assert_allclose(_times(v, matrix), v @ matrix, rtol=1e-13, atol=1e-15)
    assert _times(v[0], matrix).shape == (3, 3)


def test_cofactors_and_affine_inverse_agree_with_numpys_inverse():
    rng = np.random.default_rng(5)
    for m in [rng.normal(size=(3, 3)) for _ in range(50)] + [np.diag([2.0, -3.0, 0.5]), np.eye(3) * 1e-6]:
        cof, det = cofactors(m)
        assert det == pytest.approx(np.linalg.det(m), rel=1e-12)
        np.testing.assert_allclose(cof / det, np.linalg.inv(m).T, rtol=1e-9, atol=1e-12)
        affine = np.eye(4)
        affine[:3, :3], affine[:3, 3] = m, rng.normal(size=3) * 100.0
        np.testing.assert_allclose(affine_inverse(affine) @ affine, np.eye(4), atol=1e-9)
    singular = np.eye(4)
    singular[2, :3] = singular[0, :3]
    with pytest.raises(np.linalg.LinAlgError):
        affine_inverse(singular)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="threads' CPU times are read from /proc")
def test_exporting_a_transformed_mesh_leaves_numpys_blas_threads_idle(bpy):
    # numpy's OpenBLAS solves even a 3 x 3 inverse, and multiplies tall
    # products, on its worker threads, which then spin for about 0.1 s and
    # take a core from the render's first kernels: the export calls neither
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128)  # 65k triangles: a tall product
    obj = bpy.context.object
    obj.rotation_euler, obj.scale = (0.3, 0.2, 0.1), (1.0, 2.0, 3.0)
    _export(bpy)
    time.sleep(0.3)
    before = other_threads_cpu_ms()
    _export(bpy)
    time.sleep(0.3)  # a woken worker spins through this
    assert other_threads_cpu_ms() - before < 40


def test_non_uniform_and_mirroring_scales_keep_normals_on_the_winding_side(bpy):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1, location=(0, 0, 0))
    sphere = bpy.context.object
    bpy.ops.object.shade_flat()
    for scale in ((1.0, 2.0, 0.5), (-1.0, 1.5, 1.0)):
        sphere.scale = scale
        scene = _export(bpy)
        # flat shading: corner normals stay perpendicular to the transformed faces
        # (inverse transpose) and on the side the winding points to (mirroring flips it)
        dots = np.einsum("tcj,tj->tc", scene.normals, _face_normals(scene.triangles))
        np.testing.assert_allclose(dots, 1.0, atol=1e-4)
        outward = np.einsum("tj,tj->t", _face_normals(scene.triangles), scene.triangles.mean(axis=1))
        assert (outward > 0).all(), scale


def test_uvs_come_from_the_uv_map_marked_for_rendering(bpy):
    bpy.ops.mesh.primitive_plane_add(size=2)
    mesh = bpy.context.object.data
    second = mesh.uv_layers.new(name="second")
    coords = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers[0].uv.foreach_get("vector", coords)
    second.uv.foreach_set("vector", coords * 0.25 + 0.5)
    mesh.uv_layers.active = mesh.uv_layers[0]
    second.active_render = True
    uvs = _export(bpy).uvs
    assert uvs.min() == pytest.approx(0.5) and uvs.max() == pytest.approx(0.75)


def _combine(bpy, name, kind, first, second, fac=None):
    """A material of an Add or Mix Shader of two shader nodes (kind, inputs)
    or, for a tuple of three, a nested combination."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")

    def build(kind, first, second, fac):
        node = tree.nodes.new(kind)
        shaders = [s for s in node.inputs if s.type == "SHADER"]
        for socket, spec in zip(shaders, (first, second)):
            if len(spec) == 4:
                source = build(*spec)
            else:
                source = tree.nodes.new(spec[0])
                for key, value in spec[1].items():
                    source.inputs[key].default_value = value
            tree.links.new(source.outputs[0], socket)
        if fac is not None:
            node.inputs["Fac"].default_value = fac
        return node

    tree.links.new(build(kind, first, second, fac).outputs[0], out.inputs["Surface"])
    return mat


def _plane_with(bpy, mat, x):
    bpy.ops.mesh.primitive_plane_add(size=1, location=(x, 0, 0))
    bpy.context.object.data.materials.append(mat)


def _chain(materials, row):
    """The rows of the mix starting at ``row``: (row, chance of picking it, scale)."""
    rows, left = [], 1.0
    while row >= 0:
        stop = float(materials.mix_stop[row]) if materials.mix_next[row] >= 0 else 1.0
        rows.append((row, left * stop, float(materials.mix_scale[row])))
        left *= 1.0 - stop
        row = int(materials.mix_next[row])
    return rows


DIFFUSE_RED = ("ShaderNodeBsdfDiffuse", {"Color": (1, 0, 0, 1)})
EMISSION = ("ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": 4.0})
GLOSSY = ("ShaderNodeBsdfGlossy", {"Color": (1, 1, 1, 1)})


def test_add_and_mix_shaders_sum_emission_and_weigh_the_surface(bpy):
    _plane_with(bpy, _combine(bpy, "add", "ShaderNodeAddShader", EMISSION, DIFFUSE_RED), 0)
    _plane_with(bpy, _combine(bpy, "mix_emit", "ShaderNodeMixShader", DIFFUSE_RED, EMISSION, fac=0.25), 2)
    scene = _export(bpy)
    m = scene.materials
    add, mix_emit = (m.names.index(n) for n in ("add", "mix_emit"))
    np.testing.assert_allclose(m.base_color[add], (1, 0, 0))
    np.testing.assert_allclose(m.emission[add], (4, 4, 4))
    assert _chain(m, add) == [(add, 1.0, 1.0)]
    # one surface at weight 0.75: no pick, its BSDF scaled
    np.testing.assert_allclose(m.base_color[mix_emit], (1, 0, 0))
    np.testing.assert_allclose(m.emission[mix_emit], (1, 1, 1))
    assert _chain(m, mix_emit) == [(mix_emit, 1.0, 0.75)]
    assert not scene.warnings


def test_a_mix_of_surfaces_becomes_a_chain_of_rows_picked_by_weight(bpy):
    _plane_with(bpy, _combine(bpy, "mix_two", "ShaderNodeMixShader", DIFFUSE_RED, GLOSSY, fac=0.8), 0)
    # Mix(Add(diffuse, glossy), transparent): weights 0.4, 0.4, 0.6 of a total 1.4
    nested = ("ShaderNodeAddShader", DIFFUSE_RED, GLOSSY, None)
    transparent = ("ShaderNodeBsdfTransparent", {})
    _plane_with(bpy, _combine(bpy, "nested", "ShaderNodeMixShader", nested, transparent, fac=0.6), 2)
    scene = _export(bpy)
    m = scene.materials
    two, nested_row = m.names.index("mix_two"), m.names.index("nested")
    (first, p0, s0), (second, p1, s1) = _chain(m, two)
    assert first == two and m.metallic[first] == 0.0 and m.metallic[second] == 1.0
    assert (p0, p1, s0, s1) == pytest.approx((0.2, 0.8, 1.0, 1.0))
    rows = _chain(m, nested_row)
    assert [p for _, p, _ in rows] == pytest.approx([0.4 / 1.4, 0.4 / 1.4, 0.6 / 1.4])
    assert [s for _, _, s in rows] == pytest.approx([1.4] * 3)
    assert [float(m.alpha[r]) for r, _, _ in rows] == [1.0, 1.0, 0.0]
    # the triangles use the first row; the others are reached through it
    assert set(scene.material_ids.tolist()) == {two, nested_row}
    assert scene.has_mix() and scene.has_alpha() and not scene.warnings


def test_an_image_on_a_mix_fac_picks_between_two_surfaces(bpy):
    mat = _combine(bpy, "masked", "ShaderNodeMixShader", DIFFUSE_RED, GLOSSY, fac=0.3)
    tree = mat.node_tree
    mask = bpy.data.images.new("mask", 2, 1)
    mask.colorspace_settings.name = "Non-Color"
    mask.pixels = [0, 0, 0, 1, 1, 1, 1, 1]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = mask
    tree.links.new(tex.outputs["Color"], tree.nodes["Mix Shader"].inputs["Fac"])
    _plane_with(bpy, mat, 0)
    scene = _export(bpy)
    m = scene.materials
    row = m.names.index("masked")
    assert m.mix_texture[row] == 0 and m.mix_channel[row] == TEXTURE_LUMINANCE
    assert m.mix_next[row] > row and m.metallic[m.mix_next[row]] == 1.0
    np.testing.assert_allclose(scene.textures[0][0, :, 0], [0, 1])
    assert scene.has_textures() and not scene.warnings


def test_a_material_edit_that_grows_its_mix_keeps_its_row(bpy):
    from blender_addon.export.materials import MaterialTable

    mat = _combine(bpy, "growing", "ShaderNodeMixShader", DIFFUSE_RED, GLOSSY, fac=0.5)
    table = MaterialTable()
    row = table.index(mat)
    tree = mat.node_tree
    add = tree.nodes.new("ShaderNodeAddShader")
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    tree.links.new(tree.nodes["Glossy BSDF"].outputs[0], add.inputs[0])
    tree.links.new(glass.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], tree.nodes["Mix Shader"].inputs[2])
    table.forget(mat.name_full)
    assert table.index(mat) == row
    m = Materials.make(table.rows)
    chain = _chain(m, row)
    assert len(chain) == 3 and all(a < b for (a, _, _), (b, _, _) in zip(chain, chain[1:]))
    assert sum(p for _, p, _ in chain) == pytest.approx(1.0)


def test_non_color_and_float_images_stay_linear(bpy):
    values = [0.5, 0.25, 0.125, 1.0]
    non_color = bpy.data.images.new("data", 1, 1)
    non_color.colorspace_settings.name = "Non-Color"
    non_color.pixels = values
    floating = bpy.data.images.new("hdr", 1, 1, float_buffer=True)
    floating.pixels = values
    for x, image in ((0, non_color), (2, floating)):
        bpy.ops.mesh.primitive_plane_add(size=1, location=(x, 0, 0))
        mat, node = _material(bpy, "ShaderNodeBsdfDiffuse")
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = image
        mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Color"])
        bpy.context.object.data.materials.append(mat)
    scene = _export(bpy)
    assert len(scene.textures) == 2
    for pixels in scene.textures:
        np.testing.assert_allclose(pixels[0, 0], values, atol=1.0 / 255)


def test_an_image_keeps_each_nodes_interpolation(bpy):
    image = bpy.data.images.new("pixel_art", 2, 2)
    for x, (interpolation, extension) in enumerate((("Closest", "REPEAT"), ("Linear", "REPEAT"),
                                                     ("Cubic", "EXTEND"))):
        bpy.ops.mesh.primitive_plane_add(size=1, location=(2 * x, 0, 0))
        mat, node = _material(bpy, "ShaderNodeBsdfDiffuse")
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image, tex.interpolation, tex.extension = image, interpolation, extension
        mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Color"])
        bpy.context.object.data.materials.append(mat)
    scene = _export(bpy)
    # one texture per filter: Closest on its own, Linear shared with the Cubic node (drawn Linear)
    assert sorted(scene.texture_closest) == [False, True] and len(scene.textures) == 2
    assert any("Cubic interpolation" in w and "used Linear" in w for w in scene.warnings)
    assert any("extend extension" in w and "used Repeat" in w for w in scene.warnings)


def test_light_power_follows_exposure_temperature_and_normalize(bpy):
    point = _light(bpy, "POINT", energy=10, exposure=2.0, color=(1, 1, 1))
    warm = _light(bpy, "POINT", energy=10, use_temperature=True, temperature=3000.0, color=(1, 1, 1))
    area = _light(bpy, "AREA", energy=10, shape="RECTANGLE", size=2.0, size_y=0.5, normalize=False)
    area.scale = (2.0, 1.0, 1.0)
    disk = _light(bpy, "AREA", energy=10, shape="DISK", size=2.0, normalize=False)
    sphere = _light(bpy, "POINT", energy=10, shadow_soft_size=0.5, normalize=False)
    lights = _export(bpy).lights
    power = dict(zip(lights.names, lights.power))
    np.testing.assert_allclose(power[point.data.name], (40, 40, 40), rtol=1e-6)
    np.testing.assert_allclose(power[warm.data.name], 10 * np.array(warm.data.temperature_color[:3]), rtol=1e-6)
    assert power[warm.data.name][0] > power[warm.data.name][2]  # 3000 K is reddish
    # without Normalize the strength is per unit area: the power grows with the (scaled) area
    np.testing.assert_allclose(power[area.data.name], 10 * (2.0 * 2.0) * 0.5, rtol=1e-6)
    np.testing.assert_allclose(power[disk.data.name], 10 * math.pi / 4 * 4.0, rtol=1e-6)
    np.testing.assert_allclose(power[sphere.data.name], 10 * 4 * math.pi * 0.25, rtol=1e-6)


def test_portal_lights_are_skipped_and_unsupported_light_settings_warn(bpy):
    portal = _light(bpy, "AREA", energy=10)
    portal.data.cycles.is_portal = True
    spread = _light(bpy, "AREA", energy=10, spread=0.5)
    _light(bpy, "POINT", energy=10, use_shadow=False)
    scene = _export(bpy)
    assert portal.data.name not in scene.lights.names
    assert len(scene.lights) == 2
    assert any(spread.data.name in w and "spread" in w for w in scene.warnings)
    assert any("shadows" in w for w in scene.warnings)


def test_unsupported_objects_and_world_nodes_warn_but_export(bpy):
    cloud = bpy.data.objects.new("cloud", bpy.data.pointclouds.new("cloud"))
    bpy.context.scene.collection.objects.link(cloud)
    world = bpy.data.worlds.new("sky")
    bpy.context.scene.world = world
    sky = world.node_tree.nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    bpy.ops.mesh.primitive_plane_add(size=1)
    scene = _export(bpy)
    assert scene.triangle_count == 2
    assert any("POINTCLOUD" in w for w in scene.warnings)
    assert any("ShaderNodeTexSky" in w for w in scene.warnings)
    assert np.isfinite(scene.world_color).all()


def test_instancer_hidden_in_renders_is_not_exported(bpy, tmp_path):
    bpy.ops.mesh.primitive_plane_add(size=2)
    parent = bpy.context.object
    bpy.ops.mesh.primitive_cube_add(size=0.2)
    cube = bpy.context.object
    cube.parent = parent
    parent.instance_type = "VERTS"
    parent.show_instancer_for_render = parent.show_instancer_for_viewport = False
    # the viewport shows the child itself too; renders hide it (Blender's rule)
    assert _export(bpy).triangle_count == 4 * 12 + 12
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.gpugi.samples = 1
    render_to_array(bpy, scene, "GPUGI", str(tmp_path / "verts.exr"))
    assert LAST_RUN["stats"]["triangles"] == 4 * 12  # a cube on each of the plane's 4 vertices


def _window_from_projection_matrix(projection, ortho):
    """Unproject the NDC corners with the inverse projection (independent of the exporter)."""
    inv = np.linalg.inv(np.asarray(projection, np.float64))
    corners = []
    for x, y in ((-1, -1), (1, 1)):
        p = inv @ np.array([x, y, 0.5, 1.0])
        p = p[:3] / p[3]
        corners.append(p[:2] if ortho else p[:2] / -p[2])
    (x0, y0), (x1, y1) = corners
    return (x0, x1, y0, y1)


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
@pytest.mark.parametrize("fit,size,shift", [("AUTO", (64, 32), (0.1, 0.0)), ("VERTICAL", (40, 60), (-0.2, 0.15)),
                                            ("HORIZONTAL", (30, 50), (0.0, -0.3))])
def test_camera_window_matches_blenders_projection_matrix(bpy, kind, fit, size, shift):
    scene = bpy.context.scene
    cam_obj = scene.camera
    cam = cam_obj.data
    cam.type, cam.sensor_fit, cam.lens, cam.ortho_scale = kind, fit, 35.0, 3.0
    cam.shift_x, cam.shift_y = shift
    render = scene.render
    render.resolution_x, render.resolution_y, render.resolution_percentage = *size, 100
    depsgraph = bpy.context.evaluated_depsgraph_get()
    projection = cam_obj.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=size[0], y=size[1])
    camera = export_scene(depsgraph).camera
    expected = _window_from_projection_matrix(projection, kind == "ORTHO")
    np.testing.assert_allclose(camera.window, expected, rtol=1e-5, atol=1e-6)
    # the window keeps the image's aspect
    x0, x1, y0, y1 = camera.window
    assert (x1 - x0) / (y1 - y0) == pytest.approx(size[0] / size[1], rel=1e-5)


def _user_data_snapshot(bpy):
    """Names in every bpy.data collection, mesh coordinates and material values."""
    snap = {}
    for attr in dir(bpy.data):
        collection = getattr(bpy.data, attr, None)
        if isinstance(collection, bpy.types.bpy_prop_collection) and attr != "window_managers":
            snap[attr] = sorted(item.name for item in collection)
    for mesh in bpy.data.meshes:
        coords = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", coords)
        snap["mesh:" + mesh.name] = (coords.tobytes(), len(mesh.loop_triangles), len(mesh.uv_layers))
    for mat in bpy.data.materials:
        snap["mat:" + mat.name] = [
            tuple(s.default_value) if hasattr(s.default_value, "__len__") else s.default_value
            for n in mat.node_tree.nodes for s in n.inputs if hasattr(s, "default_value")
        ]
    for obj in bpy.data.objects:
        snap["obj:" + obj.name] = (tuple(map(tuple, obj.matrix_world)), len(obj.modifiers), obj.hide_render)
    return snap


def test_exporter_leaves_the_users_data_unchanged(bpy):
    bpy.ops.mesh.primitive_cube_add(size=2)
    cube = bpy.context.object
    cube.modifiers.new("sub", "SUBSURF").levels = 1
    image = bpy.data.images.new("tex", 2, 2)
    mat, node = _material(bpy, "ShaderNodeBsdfPrincipled")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    cube.data.materials.append(mat)
    _light(bpy, "AREA", energy=10)
    bpy.context.scene.world = bpy.data.worlds.new("w")
    bpy.context.view_layer.update()  # evaluate first: matrix_world is then up to date
    before = _user_data_snapshot(bpy)
    for _ in range(2):
        _export(bpy)
    assert _user_data_snapshot(bpy) == before


def test_ray_visibility_and_holdout_settings_warn(bpy):
    bpy.ops.mesh.primitive_plane_add(size=1)
    hidden = bpy.context.object
    hidden.visible_shadow = False
    bpy.ops.mesh.primitive_plane_add(size=1, location=(2, 0, 0))
    bpy.context.object.is_holdout = True
    bpy.ops.mesh.primitive_plane_add(size=1, location=(4, 0, 0))
    scene = _export(bpy)
    assert scene.triangle_count == 6
    assert any(hidden.name in w and "shadow" in w for w in scene.warnings)
    assert sum("holdout" in w for w in scene.warnings) == 1
