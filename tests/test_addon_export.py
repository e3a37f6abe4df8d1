"""Depsgraph export: meshes, instances, normals, UVs, materials, lights, world, camera."""

import math

import numpy as np
import pytest

from blender_addon.export import ExportError, export_scene
from gpu_core.scene import AREA_ELLIPSE, AREA_RECTANGLE, CAMERA_ORTHO, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN


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
