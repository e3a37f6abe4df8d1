"""Build the .blend scenes used by the demo, the tests and the benchmarks.

    python blend_scenes/build_scenes.py [--out DIR] [--only NAME ...]

Every scene uses only what the exporter supports (Principled BSDF, Diffuse,
Glossy, Glass and Emission shaders, the world Background) so Cycles and GPU GI
render the same thing. Units are metres and watts.
"""

from __future__ import annotations

import argparse
import math
import os

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))


# -- building blocks ---------------------------------------------------------------


def reset(name: str):
    """An empty file with sane render settings."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.name = name
    scene.render.resolution_x = 256
    scene.render.resolution_y = 256
    scene.render.resolution_percentage = 100
    scene.cycles.samples = 64
    scene.world = bpy.data.worlds.new("World")
    set_world(scene, (0.0, 0.0, 0.0), 0.0)
    return scene


def set_world(scene, color, strength):
    world = scene.world
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*color, 1.0)
    background.inputs["Strength"].default_value = strength


def principled(name, color, metallic=0.0, roughness=0.5, transmission=0.0, ior=1.5, emission=None, strength=0.0):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
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
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def assign(obj, mat):
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    return obj


def plane(size, location=(0, 0, 0), rotation=(0, 0, 0), mat=None, name=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    obj = bpy.context.object
    if name:
        obj.name = name
    return assign(obj, mat) if mat else obj


def cube(size, location, mat, rotation=(0, 0, 0), scale=(1, 1, 1)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location, rotation=rotation, scale=scale)
    return assign(bpy.context.object, mat)


def sphere(radius, location, mat, segments=48, rings=24):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=segments, ring_count=rings)
    obj = bpy.context.object
    bpy.ops.object.shade_smooth()
    return assign(obj, mat)


def light(kind, location, energy, rotation=(0, 0, 0), color=(1, 1, 1), **props):
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
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    obj = bpy.data.objects.new("Camera", data)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    direction = [t - l for t, l in zip(look_at, location)]
    import mathutils

    obj.rotation_euler = mathutils.Vector(direction).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = obj
    return obj


# -- scenes ----------------------------------------------------------------------


def cornell_box():
    """The classic box, 2 m wide: red and green walls, area light, mirror box, glass sphere."""
    reset("cornell_box")
    white = principled("White", (0.73, 0.73, 0.73), roughness=1.0)
    red = principled("Red", (0.63, 0.065, 0.05), roughness=1.0)
    green = principled("Green", (0.14, 0.45, 0.091), roughness=1.0)
    plane(2, (0, 0, 0), mat=white, name="Floor")
    plane(2, (0, 0, 2), (math.pi, 0, 0), white, "Ceiling")
    plane(2, (0, 1, 1), (math.pi / 2, 0, 0), white, "Back")
    plane(2, (-1, 0, 1), (0, math.pi / 2, 0), red, "Left")
    plane(2, (1, 0, 1), (0, -math.pi / 2, 0), green, "Right")
    mirror = principled("Mirror", (0.9, 0.9, 0.9), metallic=1.0, roughness=0.0)
    cube(0.6, (-0.35, 0.35, 0.6), mirror, rotation=(0, 0, math.radians(18)), scale=(1, 1, 2)).name = "Mirror Box"
    glass = principled("Glass", (1, 1, 1), roughness=0.0, transmission=1.0, ior=1.5)
    sphere(0.3, (0.4, -0.2, 0.3), glass).name = "Glass Sphere"
    light("AREA", (0, 0, 1.98), 60.0, color=(1.0, 0.85, 0.7), size=0.5)
    camera((0, -3.4, 1.0), (0, 0, 1.0), lens=38)


def box_torus():
    """The seed's closed box with a specular torus (~600 triangles) and one light."""
    reset("box_torus")
    walls = principled("Walls", (0.7, 0.7, 0.7), roughness=1.0)
    floor = principled("Floor", (0.6, 0.5, 0.35), roughness=1.0)
    box = cube(2, (0, 0, 1), walls)
    box.name = "Box"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    plane(1.98, (0, 0, 0.001), mat=floor, name="Floor")
    bpy.ops.mesh.primitive_torus_add(major_radius=0.45, minor_radius=0.17, major_segments=24, minor_segments=12,
                                     location=(0, 0.1, 0.5), rotation=(math.radians(60), 0, math.radians(20)))
    torus = bpy.context.object
    torus.name = "Torus"
    bpy.ops.object.shade_smooth()
    assign(torus, principled("Gold", (1.0, 0.77, 0.34), metallic=1.0, roughness=0.0))
    light("POINT", (0.3, -0.4, 1.8), 120.0, shadow_soft_size=0.05)
    camera((0, -0.95, 1.2), (0, 0.2, 0.55), lens=18)


def caustics():
    """A glass sphere over a diffuse floor under a spot light: a bright caustic."""
    reset("caustics")
    plane(6, mat=principled("Floor", (0.8, 0.8, 0.8), roughness=1.0), name="Floor")
    plane(6, (0, 2, 1.5), (math.pi / 2, 0, 0), principled("Wall", (0.5, 0.6, 0.8), roughness=1.0), "Wall")
    sphere(0.5, (0, 0, 0.9), shader("Glass", "ShaderNodeBsdfGlass", IOR=1.5, Roughness=0.0)).name = "Glass Sphere"
    light("SPOT", (0.0, -0.3, 3.5), 800.0, rotation=(math.radians(-5), 0, 0), spot_size=math.radians(40),
          spot_blend=0.2, shadow_soft_size=0.02)
    set_world(bpy.context.scene, (0.05, 0.05, 0.06), 1.0)
    camera((0, -4.0, 2.6), (0, 0, 0.6), lens=40)


def light_scene(name, add_light):
    """A diffuse plane with a small occluder under one light."""
    reset(name)
    plane(8, mat=shader("Floor", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8, 1)), name="Floor")
    cube(0.5, (0.4, 0.3, 0.5), principled("Block", (0.8, 0.3, 0.2), roughness=1.0)).name = "Block"
    add_light()
    camera((0, -5.5, 4.0), (0, 0, 0.3), lens=40)


def light_point():
    light_scene("light_point", lambda: light("POINT", (-0.5, -0.3, 2.5), 400.0, shadow_soft_size=0.1))


def light_spot():
    light_scene("light_spot", lambda: light("SPOT", (-0.5, -0.8, 3.0), 800.0, rotation=(0.3, -0.2, 0),
                                           spot_size=math.radians(50), spot_blend=0.25, shadow_soft_size=0.1))


def light_sun():
    light_scene("light_sun", lambda: light("SUN", (0, 0, 5), 3.0, rotation=(0.5, 0.3, 0), angle=math.radians(3)))


def light_area():
    light_scene("light_area", lambda: light("AREA", (-0.5, -0.3, 2.5), 300.0, rotation=(0.2, -0.2, 0),
                                           shape="RECTANGLE", size=1.0, size_y=0.6))


def light_world():
    def sky():
        set_world(bpy.context.scene, (0.6, 0.7, 0.9), 1.0)

    light_scene("light_world", sky)


def light_emission():
    def panel():
        mat = shader("Emitter", "ShaderNodeEmission", Color=(1.0, 0.9, 0.8, 1), Strength=30.0)
        plane(0.8, (-0.6, -0.2, 1.8), (math.pi, 0, 0), mat, "Emitter")

    light_scene("light_emission", panel)


def large_scene():
    """Over 100k triangles: a subdivided Suzanne instanced through a collection."""
    reset("large_scene")
    plane(30, mat=principled("Ground", (0.5, 0.5, 0.5), roughness=1.0), name="Ground")
    source = bpy.data.collections.new("Suzanne Source")
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(0, 0, 0))
    monkey = bpy.context.object
    bpy.ops.object.shade_smooth()
    modifier = monkey.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = 2
    assign(monkey, principled("Suzanne", (0.8, 0.55, 0.3), roughness=0.6))
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
    light("SUN", (0, 0, 10), 4.0, rotation=(0.6, 0.2, 0.5), angle=math.radians(2))
    set_world(bpy.context.scene, (0.4, 0.5, 0.7), 0.5)
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
}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("--out", default=HERE, help="folder for the .blend files")
    parser.add_argument("--only", nargs="*", default=None, help="scene names to build")
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    for name in args.only or SCENES:
        SCENES[name]()
        path = os.path.join(args.out, f"{name}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
        print(f"{path}  {os.path.getsize(path) / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
