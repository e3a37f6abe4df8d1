"""The viewport's sync, edit by edit, with the updates Blender's depsgraph
reports: what is exported again, what the renderer's plan then reuses, and
that the result is the scene (and the image) of a fresh export."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from blender_addon.export import export_scene
from blender_addon.export.sync import SceneSync, _shown_object, read_updates
from blender_addon.viewport import COARSE_PHOTON_SHARE, Job, ViewportSession
from gpu_core.renderer import Renderer
from gpu_core.settings import RenderSettings

GI = RenderSettings(mode="gi", samples=1, global_photons=5_000, caustic_photons=2_000, photon_k=16, cache_seeds=40,
                    gather_rays=16)
# cache points chosen afresh for every render (Reuse Across Views starts them from the last render's)
AFRESH = dataclasses.replace(GI, cache_reuse=False)


class Edits:
    """Captures depsgraph updates as the engine's view_update sees them."""

    def __init__(self, bpy):
        self.bpy, self.updates = bpy, []
        bpy.app.handlers.depsgraph_update_post.append(self._capture)

    def _capture(self, scene, depsgraph):
        self.updates.extend(read_updates(depsgraph))

    def apply(self, edit) -> list:
        """Run ``edit`` and evaluate: the updates it caused."""
        self.updates = []
        edit()
        self.bpy.context.view_layer.update()
        return self.updates

    def close(self):
        self.bpy.app.handlers.depsgraph_update_post.remove(self._capture)


@pytest.fixture
def room(bpy_empty):
    """A floor, a cube on it with its own material, a point light, a camera, a world."""
    bpy = bpy_empty
    bpy.ops.mesh.primitive_plane_add(size=6)
    floor = bpy.context.object
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5))
    cube = bpy.context.object
    material = bpy.data.materials.new("Red")
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.1, 0.1, 1)
    cube.data.materials.append(material)
    bpy.ops.object.light_add(type="POINT", location=(1, -1, 3))
    bpy.context.object.data.energy = 500
    bpy.ops.object.camera_add(location=(0, -6, 3), rotation=(1.1, 0, 0))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    scene.world = bpy.data.worlds.new("World")
    _background(bpy).default_value = (0.05, 0.05, 0.05, 1)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 24, 16, 100
    edits = Edits(bpy)
    yield bpy, edits, floor, cube, material
    edits.close()


def _camera(bpy):
    return export_scene(bpy.context.evaluated_depsgraph_get()).camera


def _synced(bpy, sync, updates=None):
    return sync.export(bpy.context.evaluated_depsgraph_get(), _camera(bpy), updates)


def _assert_same_scene(a, b):
    for name in ("triangles", "normals", "uvs", "material_ids", "world_color"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for table in ("materials", "lights"):
        for f in dataclasses.fields(getattr(a, table)):
            np.testing.assert_array_equal(getattr(getattr(a, table), f.name), getattr(getattr(b, table), f.name))


def _light_power(bpy):
    bpy.data.lights[0].energy *= 3


def _material_colour(bpy):
    bpy.data.materials["Red"].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.8, 0.1, 1)


def _move_cube(bpy):
    bpy.data.objects["Cube"].location.x += 0.5


def _edit_mesh(bpy):
    bpy.data.objects["Cube"].data.vertices[0].co.z += 0.3


def _background(bpy):
    return bpy.context.scene.world.node_tree.nodes["Background"].inputs["Color"]


def _world_colour(bpy):
    _background(bpy).default_value = (0.2, 0.1, 0.05, 1)


@pytest.mark.parametrize("edit, parts, triangulated, transformed, materials", [
    (_light_power, {"lights"}, 0, 0, 0),
    (_material_colour, {"materials"}, 0, 0, 1),  # the edited material alone is read again
    (_move_cube, {"geometry"}, 0, 1, 0),
    (_edit_mesh, {"geometry"}, 1, 1, 0),
    (_world_colour, {"world"}, 0, 0, 0),
], ids=["light_power", "material_colour", "move_object", "edit_mesh", "world_colour"])
def test_an_edit_exports_only_what_it_changed_and_gives_the_fresh_export(room, edit, parts, triangulated,
                                                                         transformed, materials):
    bpy, edits, *_ = room
    sync = SceneSync()
    first, all_parts = _synced(bpy, sync)
    assert all_parts == {"geometry", "materials", "lights", "world"}
    updates = edits.apply(lambda: edit(bpy))
    scene, changed = _synced(bpy, sync, updates)
    assert changed == parts
    assert sync.stats.meshes_triangulated == triangulated and sync.stats.instances_transformed == transformed
    assert sync.stats.materials_exported == materials
    _assert_same_scene(scene, export_scene(bpy.context.evaluated_depsgraph_get()))
    if "geometry" not in parts:  # the arrays of the last sync are shared, not copied
        assert scene.triangles is first.triangles and scene.material_ids is first.material_ids


@pytest.mark.parametrize("edit, kept", [
    (_move_cube, ("normals", "uvs", "material_ids")),  # moved along x: its normals are the same
    (lambda bpy: setattr(bpy.data.objects["Cube"].rotation_euler, "z", 0.4), ("uvs", "material_ids")),
], ids=["translate", "rotate"])
def test_a_moved_object_leaves_the_arrays_it_did_not_change_shared_and_writes_its_rows_into_copies(room, edit, kept):
    bpy, edits, *_ = room
    sync = SceneSync()
    first, _ = _synced(bpy, sync)
    triangles = first.triangles.copy()
    scene, changed = _synced(bpy, sync, edits.apply(lambda: edit(bpy)))
    assert changed == {"geometry"}
    _assert_same_scene(scene, export_scene(bpy.context.evaluated_depsgraph_get()))
    for name in ("triangles", "normals", "uvs", "material_ids"):
        assert (getattr(scene, name) is getattr(first, name)) == (name in kept), name
    np.testing.assert_array_equal(first.triangles, triangles)  # the last scene is not written into


def test_a_sync_with_no_edit_changes_nothing_and_shares_every_table(room):
    bpy, edits, *_ = room
    sync = SceneSync()
    first, _ = _synced(bpy, sync)
    again, changed = _synced(bpy, sync, edits.apply(lambda: None))
    assert changed == set()
    assert again.triangles is first.triangles and again.materials is first.materials and again.lights is first.lights


class _Instance:
    """A depsgraph object instance whose ``object`` must not be read."""

    def __init__(self, is_instance, instance_object, parent):
        self.is_instance, self.instance_object, self.parent = is_instance, instance_object, parent

    @property
    def object(self):
        raise AssertionError("inst.object read")


def test_an_instance_of_an_object_is_read_through_the_object_it_instances():
    # bpy makes a Python object for an instance's temporary object that is
    # never freed (the viewport's memory grew with every edit of a scene of
    # collection instances): the sync reads the instanced object instead
    source, holder = object(), object()
    assert _shown_object(_Instance(True, source, holder)) is source


def test_geometry_made_by_geometry_nodes_and_plain_objects_are_read_through_the_instance():
    # geometry made in a node tree has no object of its own: instance_object is the instancer
    holder = object()
    with pytest.raises(AssertionError, match="inst.object read"):
        _shown_object(_Instance(True, holder, holder))
    with pytest.raises(AssertionError, match="inst.object read"):
        _shown_object(_Instance(False, None, None))


def test_a_material_edit_keeps_the_images_pixels(room):
    bpy, edits, _floor, _cube, material = room
    image = bpy.data.images.new("Checker", 8, 8)
    image.generated_type = "COLOR_GRID"
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    material.node_tree.links.new(node.outputs["Color"], material.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    sync = SceneSync()
    first, _ = _synced(bpy, sync, None)
    scene, changed = _synced(bpy, sync, edits.apply(
        lambda: setattr(material.node_tree.nodes["Principled BSDF"].inputs["Roughness"], "default_value", 0.9)))
    assert changed == {"materials"} and scene.textures[0] is first.textures[0]


@pytest.mark.parametrize("edit, kdtree, photons", [
    (_light_power, "kdtree_reused", "global_photons_reweighted"),
    (_material_colour, "kdtree_reused", "global_photons"),
    (_move_cube, "kdtree", "global_photons"),
    (lambda bpy: None, "kdtree_reused", "global_photons_reused"),
], ids=["light_power", "material_colour", "move_object", "nothing"])
def test_the_renderer_reuses_what_an_edit_left_and_renders_the_fresh_image(room, device, edit, kdtree, photons):
    bpy, edits, *_ = room
    # reweighted maps hold other photons than a fresh trace (a photon's
    # direction depends on how many its light sends): enough photons and
    # gather rays that the image's photon noise stays within the bounds below
    settings = dataclasses.replace(AFRESH, global_photons=20_000, gather_rays=256) if photons.endswith("_reweighted") \
        else AFRESH
    sync, renderer = SceneSync(), Renderer(device)
    scene, changed = _synced(bpy, sync)
    renderer.render(scene, settings, edits=changed)
    scene, changed = _synced(bpy, sync, edits.apply(lambda: edit(bpy)))
    result = renderer.render(scene, settings, edits=changed)
    assert kdtree in result.stats["plan"] and photons in result.stats["plan"]
    fresh = Renderer(device).render(export_scene(bpy.context.evaluated_depsgraph_get()), settings)
    if photons.endswith("_reweighted"):
        # the light and the world share the photons as they did before the
        # edit, each reweighted: the fresh render's image within its noise,
        # its mean to 0.5% and its pixels no farther from it than those of a
        # fresh render of another seed
        ours, theirs = result.passes["Combined"][..., :3], fresh.passes["Combined"][..., :3]
        other = Renderer(device).render(export_scene(bpy.context.evaluated_depsgraph_get()),
                                        dataclasses.replace(settings, seed=settings.seed + 1)).passes["Combined"][..., :3]
        np.testing.assert_allclose(ours.mean(), theirs.mean(), rtol=5e-3)
        assert np.abs(ours - theirs).mean() <= np.abs(other - theirs).mean()
    else:
        np.testing.assert_array_equal(result.passes["Combined"], fresh.passes["Combined"])


def test_only_the_camera_moved_traces_no_photons_and_builds_no_kdtree(room, device):
    bpy, *_ = room
    sync, renderer = SceneSync(), Renderer(device)
    scene, changed = _synced(bpy, sync)
    renderer.render(scene, GI, edits=changed)
    camera = dataclasses.replace(scene.camera, matrix=scene.camera.matrix.copy())
    camera.matrix[0, 3] += 0.3
    result = renderer.render(dataclasses.replace(scene, camera=camera), GI, edits=set())
    stages = result.stats["plan"]
    assert "kdtree_reused" in stages and "global_photons_reused" in stages and "final_gather" in stages
    assert result.stats["gi"]["photons_reused"] and "kdtree" not in result.stats["ms"]


def test_bad_input_mid_session_shows_in_the_status_and_the_next_good_edit_renders(room, device):
    bpy, edits, *_ = room
    sync, renderer = SceneSync(), Renderer(device)
    session = ViewportSession(lambda: None, make_renderer=lambda spec: renderer)
    camera = _camera(bpy)

    def sync_and_render(updates):
        scene, changed = sync.export(bpy.context.evaluated_depsgraph_get(), camera, updates)
        session.update_scene(Job(scene, dataclasses.replace(GI, samples=2), None, edits=changed), ("view",))
        deadline = time.time() + 60
        while session.busy and time.time() < deadline:
            time.sleep(0.01)
        return session.status

    sync_and_render(None)
    nan = float("nan")
    status = sync_and_render(edits.apply(lambda: setattr(bpy.data.objects["Cube"].data.vertices[0], "co",
                                                          (nan, nan, nan))))
    assert "warning: dropped 4 triangle(s) with NaN/Inf coordinates" in status and session.error is None
    assert np.isfinite(session.latest()[0]).all()
    node = bpy.data.materials["Red"].node_tree.nodes.new("ShaderNodeBsdfToon")
    status = sync_and_render(edits.apply(lambda: bpy.data.materials["Red"].node_tree.links.new(
        node.outputs[0], bpy.data.materials["Red"].node_tree.nodes["Material Output"].inputs["Surface"])))
    assert "ShaderNodeBsdfToon" in status
    status = sync_and_render(edits.apply(lambda: setattr(bpy.data.lights[0], "energy", 1e12)))
    assert status.startswith("GPU GI | gi | sample 2/2") and np.isfinite(session.latest()[0]).all()
    session.stop()


def test_the_status_line_names_each_stage_while_it_runs(room, device, monkeypatch):
    import blender_addon.viewport as viewport

    monkeypatch.setattr(viewport, "STATUS_SECONDS", 0.0)
    bpy, *_ = room
    statuses = []
    session = ViewportSession(lambda: statuses.append(session.status), make_renderer=lambda spec: Renderer(device))
    scene, changed = _synced(bpy, SceneSync())
    session.update_scene(Job(scene, dataclasses.replace(GI, samples=2), None, edits=changed), ("view",))
    deadline = time.time() + 60
    while session.busy and time.time() < deadline:
        time.sleep(0.01)
    session.stop()
    for expected in ("preview: photons", "preview: shading points", "preview: gathering", "sample 1/2: rendered",
                     "sample 2/2: rendered"):
        assert any(expected in status for status in statuses), expected
    assert statuses[-1].startswith("GPU GI | gi | sample 2/2")


def test_a_material_edit_that_drops_an_unknown_node_drops_its_warning(room):
    bpy, edits, _floor, _cube, material = room
    tree = material.node_tree
    toon = tree.nodes.new("ShaderNodeBsdfToon")
    principled = tree.nodes["Principled BSDF"]
    tree.links.new(toon.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    sync = SceneSync()
    scene, _ = _synced(bpy, sync)
    assert any("ShaderNodeBsdfToon" in w for w in scene.warnings)
    scene, changed = _synced(bpy, sync, edits.apply(
        lambda: tree.links.new(principled.outputs[0], tree.nodes["Material Output"].inputs["Surface"])))
    assert changed == {"materials"} and sync.stats.materials_exported == 1
    assert not any("ShaderNodeBsdfToon" in w for w in scene.warnings)
    _assert_same_scene(scene, export_scene(bpy.context.evaluated_depsgraph_get()))


def test_an_edit_s_coarse_image_traces_a_share_of_the_photons_and_a_new_view_none(room, device):
    bpy, edits, *_ = room
    sync, renderer, stats = SceneSync(), Renderer(device), []

    class Recording:
        def render(self, *args, **kwargs):
            result = renderer.render(*args, **kwargs)
            stats.append(result.stats)
            return result

    session = ViewportSession(lambda: None, make_renderer=lambda spec: Recording())
    camera = _camera(bpy)

    def run(updates, view=1, cam=camera):
        scene, changed = sync.export(bpy.context.evaluated_depsgraph_get(), cam, updates)
        stats.clear()
        session.update_scene(Job(scene, GI, None, edits=changed), ("view", view))
        deadline = time.time() + 60
        while session.busy and time.time() < deadline:
            time.sleep(0.01)
        return [s["gi"] for s in stats]

    full = [GI.global_photons, GI.caustic_photons]
    coarse, first = run(None)
    share = [round(n * COARSE_PHOTON_SHARE) for n in full]
    assert COARSE_PHOTON_SHARE < 1 and coarse["photon_counts"] == share and first["photon_counts"] == full
    coarse, first = run(edits.apply(lambda: _material_colour(bpy)))
    assert coarse["photon_counts"] == share and not coarse["photons_reused"]
    assert first["photon_counts"] == full and not first["photons_reused"]
    # the maps of all the photons serve a new view's coarse image, and a light edit's (reweighted)
    turned = dataclasses.replace(camera, matrix=camera.matrix.copy())
    turned.matrix[0, 3] += 0.2
    coarse, first = run(set(), view=2, cam=turned)
    assert coarse["photon_counts"] == full and coarse["photons_reused"] and first["photons_reused"]
    coarse, first = run(edits.apply(lambda: _light_power(bpy)), view=2, cam=turned)
    assert coarse["photon_counts"] == full and coarse["photons_reweighted"] and first["photons_reused"]
    session.stop()
