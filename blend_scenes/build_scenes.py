"""Build the .blend scenes used by the demo, the tests and the benchmarks.

    python blend_scenes/build_scenes.py [--out DIR] [--only NAME ...]

Every scene uses only what the exporter supports (Principled BSDF, Diffuse,
Glossy, Glass and Emission shaders, Mix Shader, the world Background) so Cycles and GPU GI
render the same thing. Units are metres and watts; powers are chosen so each
scene is well exposed in Cycles with the AgX view (see check_exposure.py).
The render engine is GPU GI when the add-on is registered in this process,
Cycles otherwise; tests and the command line pick the engine at render time.
"""

from __future__ import annotations

import argparse
import math
import os

import bpy
import mathutils

HERE = os.path.dirname(os.path.abspath(__file__))
RESOLUTION = 256
CYCLES_SAMPLES = 64


# -- file and render settings -------------------------------------------------------


def reset(name: str):
    """An empty file (factory settings) with the shared render settings."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.name = name
    try:
        scene.render.engine = "GPUGI"
    except TypeError:  # the add-on is not registered in this process
        scene.render.engine = "CYCLES"
    scene.render.resolution_x = RESOLUTION
    scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    scene.cycles.samples = CYCLES_SAMPLES
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.world = bpy.data.worlds.new("World")
    set_world(scene, (0.0, 0.0, 0.0), 0.0)
    return scene


def set_world(scene, color, strength):
    """The world's Background colour and strength (the only world feature used)."""
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = strength


# -- materials ----------------------------------------------------------------------


def principled(name, color, metallic=0.0, roughness=0.5, transmission=0.0, ior=1.5, emission=None, strength=0.0,
               specular=0.5):
    """A Principled BSDF material with the inputs the exporter reads;
    ``specular`` is its Specular IOR Level (0: no dielectric reflection,
    a Lambertian surface)."""
    mat = bpy.data.materials.new(name)
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Specular IOR Level"].default_value = specular
    node.inputs["Base Color"].default_value = (*color, 1.0)
    node.inputs["Metallic"].default_value = metallic
    node.inputs["Roughness"].default_value = roughness
    node.inputs["Transmission Weight"].default_value = transmission
    node.inputs["IOR"].default_value = ior
    if emission is not None:
        node.inputs["Emission Color"].default_value = (*emission, 1.0)
        node.inputs["Emission Strength"].default_value = strength
    return mat


def shader(name, kind, **inputs):
    """A material made of one shader node (Diffuse, Glossy, Glass, Emission)."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def assign(obj, *mats):
    """Give ``obj`` exactly these material slots (face indices refer to them)."""
    obj.data.materials.clear()
    for mat in mats:
        obj.data.materials.append(mat)
    return obj


# -- objects ------------------------------------------------------------------------


def plane(size, location=(0, 0, 0), rotation=(0, 0, 0), mat=None, name=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    obj = bpy.context.object
    if name:
        obj.name = name
    return assign(obj, mat) if mat else obj


def cube(size, location, mat, rotation=(0, 0, 0), scale=(1, 1, 1), name=None):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location, rotation=rotation, scale=scale)
    obj = bpy.context.object
    if name:
        obj.name = name
    return assign(obj, mat)


def sphere(radius, location, mat, name, segments=48, rings=24):
    """A smooth-shaded UV sphere."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=segments, ring_count=rings)
    obj = bpy.context.object
    obj.name = name
    bpy.ops.object.shade_smooth()
    return assign(obj, mat)


def light(kind, location, energy, rotation=(0, 0, 0), color=(1, 1, 1), **props):
    """A light object of ``kind`` with energy in W (sun: W/m^2) and extra light properties."""
    data = bpy.data.lights.new(f"{kind.title()} Light", kind)
    data.energy = energy
    data.color = color
    for key, value in props.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(data.name, data)
    obj.location = location
    obj.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def camera(location, look_at, lens=35.0):
    """The scene camera at ``location`` looking at ``look_at`` (Z up)."""
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    obj = bpy.data.objects.new("Camera", data)
    obj.location = location
    direction = mathutils.Vector(look_at) - mathutils.Vector(location)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


# -- scenes -------------------------------------------------------------------------


def cornell_box():
    """The classic box, 2 m wide and open at the front: red and green side walls,
    an area light under the ceiling, a mirror sphere and a glass sphere."""
    reset("cornell_box")
    white = principled("White", (0.73, 0.73, 0.73), roughness=1.0, specular=0.0)
    red = principled("Red", (0.63, 0.065, 0.05), roughness=1.0, specular=0.0)
    green = principled("Green", (0.14, 0.45, 0.091), roughness=1.0, specular=0.0)
    plane(2, (0, 0, 0), mat=white, name="Floor")
    plane(2, (0, 0, 2), (math.pi, 0, 0), white, "Ceiling")
    plane(2, (0, 1, 1), (math.pi / 2, 0, 0), white, "Back")
    plane(2, (-1, 0, 1), (0, math.pi / 2, 0), red, "Left")
    plane(2, (1, 0, 1), (0, -math.pi / 2, 0), green, "Right")
    mirror = principled("Mirror", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.0)
    sphere(0.35, (-0.42, 0.35, 0.35), mirror, "Mirror Sphere")
    glass = principled("Glass", (1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5)
    sphere(0.35, (0.4, -0.3, 0.35), glass, "Glass Sphere")
    light("AREA", (0, 0, 1.98), 60.0, color=(1.0, 0.85, 0.7), size=0.5)
    camera((0, -3.4, 1.0), (0, 0, 1.0), lens=38)


def box_torus():
    """The seed's closed box (floor faces with their own material) around a
    gold mirror torus of 576 triangles, lit by one point light."""
    reset("box_torus")
    walls = principled("Walls", (0.7, 0.7, 0.7), roughness=1.0, specular=0.0)
    floor = principled("Floor", (0.6, 0.5, 0.35), roughness=1.0, specular=0.0)
    box = cube(2, (0, 0, 1), walls, name="Box")
    assign(box, walls, floor)
    # normals point into the box; the bottom face takes the second material
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    for polygon in box.data.polygons:
        polygon.material_index = 1 if polygon.center.z < -0.99 else 0
    bpy.ops.mesh.primitive_torus_add(major_radius=0.45, minor_radius=0.17, major_segments=24, minor_segments=12,
                                     location=(0, 0.1, 0.5), rotation=(math.radians(60), 0, math.radians(20)))
    torus = bpy.context.object
    torus.name = "Torus"
    bpy.ops.object.shade_smooth()
    assign(torus, principled("Gold", (1.0, 0.77, 0.34), metallic=1.0, roughness=0.0))
    light("POINT", (0.3, -0.4, 1.8), 20.0, shadow_soft_size=0.05)
    camera((0, -0.95, 1.2), (0, 0.2, 0.55), lens=18)


def caustics():
    """A glass sphere (Glass BSDF) 0.4 m over a diffuse floor under a narrow
    spot light: the sphere focuses the light into a bright caustic."""
    reset("caustics")
    plane(6, mat=principled("Floor", (0.8, 0.8, 0.8), roughness=1.0), name="Floor")
    plane(6, (0, 2, 1.5), (math.pi / 2, 0, 0), principled("Wall", (0.5, 0.6, 0.8), roughness=1.0), "Wall")
    sphere(0.5, (0, 0, 0.9), shader("Glass", "ShaderNodeBsdfGlass", IOR=1.5, Roughness=0.0), "Glass Sphere")
    light("SPOT", (0.0, -0.3, 3.5), 800.0, rotation=(math.radians(-5), 0, 0), spot_size=math.radians(40),
          spot_blend=0.2, shadow_soft_size=0.02)
    set_world(bpy.context.scene, (0.05, 0.05, 0.06), 1.0)
    camera((0, -4.0, 2.6), (0, 0, 0.6), lens=40)


def light_scene(name, add_light):
    """An 8 m diffuse plane (Diffuse BSDF) with a small block floating 0.25 m
    above it, lit by whatever ``add_light`` adds."""
    reset(name)
    plane(8, mat=shader("Floor", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8, 1)), name="Floor")
    cube(0.5, (0.4, 0.3, 0.5), principled("Block", (0.8, 0.3, 0.2), roughness=1.0), name="Block")
    add_light()
    camera((0, -5.5, 4.0), (0, 0, 0.3), lens=40)


def light_point():
    light_scene("light_point", lambda: light("POINT", (-0.5, -0.3, 2.5), 400.0, shadow_soft_size=0.1))


def light_spot():
    light_scene("light_spot", lambda: light("SPOT", (-0.5, -0.8, 3.0), 1000.0, rotation=(0.3, -0.2, 0),
                                           spot_size=math.radians(90), spot_blend=0.25, shadow_soft_size=0.1))


def light_sun():
    light_scene("light_sun", lambda: light("SUN", (0, 0, 5), 3.0, rotation=(0.5, 0.3, 0), angle=math.radians(3)))


def light_area():
    light_scene("light_area", lambda: light("AREA", (-0.5, -0.3, 2.5), 300.0, rotation=(0.2, -0.2, 0),
                                           shape="RECTANGLE", size=1.0, size_y=0.6))


def light_world():
    light_scene("light_world", lambda: set_world(bpy.context.scene, (0.6, 0.7, 0.9), 0.7))


def light_emission():
    def panel():
        mat = shader("Emitter", "ShaderNodeEmission", Color=(1.0, 0.9, 0.8, 1), Strength=30.0)
        plane(0.8, (-0.6, -0.2, 1.8), (math.pi, 0, 0), mat, "Emitter")

    light_scene("light_emission", panel)


def user_content():
    """What a user's scene is mostly made of: default-like Principled BSDFs
    (roughness 0.5, the specular layer on), a glossy floor, rough metals, a
    plastic, a Mix Shader of a Diffuse and a Glossy BSDF, lit by an area
    light, a sun and the world, in an open corner of a room."""
    reset("user_content")
    floor = principled("Glossy Floor", (0.45, 0.4, 0.35), roughness=0.25)
    wall = principled("Wall", (0.8, 0.78, 0.72))
    plane(6, mat=floor, name="Floor")
    plane(6, (0, 2, 3), (math.pi / 2, 0, 0), wall, "Back Wall")
    plane(6, (-2, 0, 3), (0, math.pi / 2, 0), wall, "Left Wall")
    sphere(0.45, (-0.9, 0.6, 0.45), principled("Brushed Steel", (0.8, 0.8, 0.8), metallic=1.0, roughness=0.3),
           "Steel Sphere")
    sphere(0.4, (0.2, 0.9, 0.4), principled("Rough Copper", (0.95, 0.64, 0.54), metallic=1.0, roughness=0.55),
           "Copper Sphere")
    sphere(0.35, (0.9, 0.1, 0.35), principled("Red Plastic", (0.7, 0.1, 0.08), roughness=0.35), "Plastic Sphere")
    mixed = bpy.data.materials.new("Lacquer")
    tree = mixed.node_tree
    tree.nodes.clear()
    out, mix = tree.nodes.new("ShaderNodeOutputMaterial"), tree.nodes.new("ShaderNodeMixShader")
    diffuse, glossy = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (0.1, 0.25, 0.6, 1.0)
    glossy.inputs["Roughness"].default_value = 0.15
    mix.inputs["Fac"].default_value = 0.3
    tree.links.new(diffuse.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    cube(0.5, (-0.1, -0.5, 0.25), mixed, rotation=(0, 0, math.radians(30)), name="Lacquer Cube")
    light("AREA", (0.8, -0.6, 2.6), 45.0, rotation=(math.radians(20), math.radians(15), 0), shape="RECTANGLE",
          size=1.2, size_y=0.6)
    light("SUN", (0, 0, 5), 0.6, rotation=(math.radians(50), 0, math.radians(40)), angle=math.radians(5))
    set_world(bpy.context.scene, (0.5, 0.6, 0.8), 0.15)
    camera((1.2, -1.8, 0.9), (-0.3, 0.45, 0.4), lens=26)


def large_scene():
    """Over 100k triangles kept small on disk: a Suzanne with an unapplied
    Subdivision Surface modifier, instanced nine times through a collection."""
    reset("large_scene")
    plane(30, mat=principled("Ground", (0.5, 0.5, 0.5), roughness=1.0), name="Ground")
    source = bpy.data.collections.new("Suzanne Source")
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0))
    monkey = bpy.context.object
    bpy.ops.object.shade_smooth()
    modifier = monkey.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = 2
    assign(monkey, principled("Suzanne", (0.8, 0.55, 0.3), roughness=0.6))
    # the source lives only in its (unlinked) collection; the scene sees the instances
    for coll in list(monkey.users_collection):
        coll.objects.unlink(monkey)
    source.objects.link(monkey)
    for i in range(3):
        for j in range(3):
            inst = bpy.data.objects.new(f"Suzanne {i}{j}", None)
            inst.instance_type = "COLLECTION"
            inst.instance_collection = source
            inst.location = (2.2 * (i - 1), 2.2 * (j - 1), 0.8)
            inst.rotation_euler = (0, 0, 0.4 * (i + j))
            bpy.context.scene.collection.objects.link(inst)
    light("SUN", (0, 0, 10), 2.5, rotation=(0.6, 0.2, 0.5), angle=math.radians(2))
    set_world(bpy.context.scene, (0.4, 0.5, 0.7), 0.4)
    camera((0, -8.5, 6.0), (0, 0, 0.4), lens=35)


SCENES = {
    "cornell_box": cornell_box,
    "box_torus": box_torus,
    "caustics": caustics,
    "light_point": light_point,
    "light_spot": light_spot,
    "light_sun": light_sun,
    "light_area": light_area,
    "light_world": light_world,
    "light_emission": light_emission,
    "large_scene": large_scene,
    "user_content": user_content,
}


# -- command line -------------------------------------------------------------------


def evaluated_triangles() -> int:
    """Triangles of every mesh instance after modifiers, as a renderer sees them."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return sum(len(inst.object.data.loop_triangles) for inst in depsgraph.object_instances
               if inst.object.type == "MESH")


def relative_paths_only():
    """Point the render output and the file browsers at the .blend's own
    folder, so the saved file holds no absolute folder of this computer."""
    bpy.context.scene.render.filepath = "//"
    for screen in bpy.data.screens:
        for area in screen.areas:
            for space in area.spaces:
                if space.type == "FILE_BROWSER" and space.params is not None:
                    space.params.directory = b"//"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("--out", default=HERE, help="folder for the .blend files")
    parser.add_argument("--only", nargs="*", default=None, choices=sorted(SCENES), metavar="NAME",
                        help="scene names to build (default: all)")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups beside the scenes
    for name in args.only or SCENES:
        SCENES[name]()
        triangles = evaluated_triangles()
        relative_paths_only()
        path = os.path.join(args.out, f"{name}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
        print(f"{name + '.blend':22s} {os.path.getsize(path) / 1024:6.0f} KiB {triangles:8d} triangles")


if __name__ == "__main__":
    main()
