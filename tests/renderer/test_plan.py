"""The plan: decided before anything runs, edit by edit (what is uploaded,
rebuilt, traced again or reused), with the device memory GI takes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.errors import BudgetError
from gpu_core.gi import gather
from gpu_core.plan import Held, plan
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, PARTS, Lights, Materials, validate
from gpu_core.settings import RenderSettings, preset

GI = RenderSettings(mode="gi", samples=2, global_photons=20_000, caustic_photons=20_000, photon_k=20,
                    cache_seeds=60, gather_rays=16)


def room(power=100.0, albedo=0.5, mirror=False, shift=0.0):
    """A closed box with a point light; optionally a mirror panel; ``shift`` moves one wall."""
    faces = [quad((0, 0, -1), 2), quad((0, 0, 1), 2, flip=True), quad((0, -1, 0), 2, normal_axis=1),
             quad((0, 1, 0), 2, normal_axis=1, flip=True), quad((-1 + shift, 0, 0), 2, normal_axis=0),
             quad((1, 0, 0), 2, normal_axis=0, flip=True)]
    tris = np.concatenate(faces)
    ids = [0] * len(tris)
    mats = [dict(base_color=(albedo,) * 3)]
    if mirror:
        tris = np.concatenate([tris, quad((0.5, 0, -0.98), 0.6)])
        ids += [1, 1]
        mats.append(dict(base_color=(0.9,) * 3, metallic=1.0, roughness=0.0))
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 0.5), power=(power,) * 3)])
    camera = camera_looking_down(height=0.9, half_width=1.0, size=16)
    camera.clip_start, camera.clip_end = 1e-3, 20.0
    return make_scene(tris, np.array(ids, np.int32), Materials.make(mats), lights, camera)


def held_after(scene, settings):
    """What a renderer holds after rendering ``scene``, as the plan sees it."""
    first = plan(validate(scene), settings)
    return Held(digests=first.digests, generations=first.generations, tables=first.tables,
                photon_key=first.photon_key, photon_emitters=first.emitters, photon_lights=first.tables.lights)


def moved_camera(scene):
    camera = dataclasses.replace(scene.camera, matrix=scene.camera.matrix.copy())
    camera.matrix[0, 3] += 0.1
    return dataclasses.replace(scene, camera=camera)


@pytest.mark.parametrize("edit, uploads, kdtree, photons", [
    (moved_camera, {"camera"}, "kdtree_reused", "global_photons_reused"),
    (lambda s: room(albedo=0.7), {"materials"}, "kdtree_reused", "global_photons"),
    (lambda s: room(power=200.0), {"lights"}, "kdtree_reused", "global_photons_reweighted"),
    (lambda s: room(shift=0.1), None, "kdtree", "global_photons"),
], ids=["camera", "material_colour", "light_power", "geometry"])
def test_each_edit_uploads_rebuilds_and_traces_only_what_it_touches(edit, uploads, kdtree, photons):
    held = held_after(room(), GI)
    edited = plan(validate(edit(room())), GI, held)
    assert kdtree in edited.stages and photons in edited.stages
    if uploads is not None:
        assert edited.changed == uploads
    assert edited.traces_photons == (photons == "global_photons")
    assert edited.reweights_photons == (photons == "global_photons_reweighted")


def test_draft_and_preview_build_the_same_programs_so_switching_between_them_compiles_nothing(device):
    # their photon k (20, 32) and caustic k (12, 16) fall in the same kNN capacity buckets; Final's 50 does not
    scene = validate(room(mirror=True))
    wanted = {name: plan(scene, preset(name, mode="gi").validated(), None, None, device).programs
              for name in ("draft", "preview", "final")}
    assert sorted(map(repr, wanted["draft"])) == sorted(map(repr, wanted["preview"]))
    assert sorted(map(repr, wanted["final"])) != sorted(map(repr, wanted["preview"]))


def test_settings_photon_tracing_does_not_read_keep_the_photon_maps():
    held = held_after(room(), GI)
    more_rays = plan(validate(room()), dataclasses.replace(GI, gather_rays=64, cache_seeds=90), held)
    assert more_rays.changed == set() and "global_photons_reused" in more_rays.stages
    more_photons = plan(validate(room()), dataclasses.replace(GI, global_photons=30_000), held)
    assert "global_photons" in more_photons.stages and more_photons.traces_photons


def test_edits_named_by_the_caller_skip_the_hashing():
    held = held_after(room(), GI)
    named = plan(validate(room(power=200.0)), GI, held, edits={"lights"})
    assert named.changed == {"lights"} and named.digests["lights"] is None
    assert named.digests["geometry"] == held.digests["geometry"]
    assert "kdtree_reused" in named.stages and named.reweights_photons


def test_with_edits_named_the_camera_is_still_compared():
    held = held_after(room(), GI)
    assert plan(validate(moved_camera(room())), GI, held, edits=set()).changed == {"camera"}
    assert plan(validate(room()), GI, held, edits=set()).changed == set()


def test_a_part_named_as_edited_is_hashed_again_by_a_later_render_that_names_none():
    held = held_after(room(), GI)
    named = plan(validate(room(power=200.0)), GI, held, edits={"lights"})
    later = Held(digests=named.digests, generations=named.generations, tables=named.tables)
    assert plan(validate(room(power=200.0)), GI, later).changed == {"lights"}


def test_a_first_render_hashes_nothing_and_a_later_one_only_parts_with_new_arrays():
    def hashed(*plans):
        return {part for p in plans for part, digest in p.digests.items() if digest._value is not None}

    scene = validate(room())
    first = plan(scene, GI)  # a fresh renderer: nothing held to compare with
    assert first.changed == set(PARTS) and not hashed(first)
    held = Held(digests=first.digests, generations=first.generations, tables=first.tables)
    same = plan(scene, GI, held)  # the very same arrays: only the camera's are made afresh
    assert same.changed == set() and hashed(first, same) == {"camera"}
    brighter = plan(dataclasses.replace(scene, lights=room(power=200.0).lights), GI, held)
    assert brighter.changed == {"lights"} and hashed(first, brighter) == {"camera", "lights"}
    again = dataclasses.replace(scene, lights=room().lights)  # new arrays, the same values
    assert plan(again, GI, held).changed == set()


def test_the_gi_cache_is_reused_only_for_the_same_view_scene_and_cache_settings():
    first = plan(validate(room()), GI)
    held = Held(digests=first.digests, generations=first.generations, tables=first.tables,
                photon_key=first.photon_key, cache_key=first.cache_key)
    more_samples = plan(validate(room()), dataclasses.replace(GI, samples=8, clamp=3.0), held)
    assert more_samples.cache_reused and "final_gather_reused" in more_samples.stages
    assert "final_gather" not in more_samples.stages
    for changed in (plan(validate(moved_camera(room())), GI, held), plan(validate(room(albedo=0.7)), GI, held),
                    plan(validate(room()), dataclasses.replace(GI, gather_rays=64), held),
                    plan(validate(room(power=50.0)), GI, held)):
        assert not changed.cache_reused and "final_gather" in changed.stages


def test_the_caustic_map_is_planned_only_with_a_specular_surface():
    plain = plan(validate(room()), GI)
    assert plain.photon_maps["caustic"].startswith("skipped") and "caustics" not in plain.stages
    with_mirror = plan(validate(room(mirror=True)), GI)
    assert with_mirror.photon_maps["caustic"].startswith("built") and "caustics" in with_mirror.stages


def test_the_render_runs_what_the_plan_says(device):
    renderer = Renderer(device)
    scene = room(mirror=True)
    first = renderer.render(scene, GI)
    again = renderer.render(moved_camera(scene), GI)
    assert first.stats["gi"]["photons"]["maps"] == plan(validate(scene), GI).photon_maps
    assert "global_photons_reused" in again.stats["plan"] and "caustic_photons_reused" in again.stats["plan"]
    assert "photons" in again.stats["ms"] and again.stats["gi"]["photons_reused"]


def test_gi_memory_counts_in_the_budget_before_any_kernel_runs():
    scene = validate(room())
    reference, gi = plan(scene, RenderSettings()), plan(scene, dataclasses.replace(GI, global_photons=2_000_000))
    assert gi.device_bytes > reference.device_bytes + 2_000_000 * 3 * 64
    device = type("Small", (), dict(name="small device", global_mem_bytes=gi.device_bytes - 1,
                                    max_alloc_bytes=gi.largest_buffer))()
    reference.check_budget(device)
    with pytest.raises(BudgetError, match="small device"):
        gi.check_budget(device)


def test_the_gathers_batch_of_rays_counts_in_the_budget():
    scene = validate(room())
    few, many = (plan(scene, dataclasses.replace(GI, cache_seeds=4000, gather_rays=rays)) for rays in (16, 1024))
    grown = gather.batch_bytes(4000, 32) - gather.batch_bytes(4000, 4)
    assert grown > 16 * 2**20  # a batch of 2^18 rays against one of 16,000
    assert many.device_bytes - few.device_bytes == grown


def test_cache_records_are_kept_for_a_new_view_of_the_same_lit_scene_only():
    first = plan(validate(room()), GI)
    held = Held(digests=first.digests, generations=first.generations, tables=first.tables,
                photon_key=first.photon_key, cache_key=first.cache_key, records_keys=(first.records_key,))
    turned = plan(validate(moved_camera(room())), GI, held)
    assert turned.records_reused and "cache_records_reused" in turned.stages and "final_gather" in turned.stages
    assert not plan(validate(room(power=50.0)), GI, held).records_reused
    assert not plan(validate(moved_camera(room())), dataclasses.replace(GI, cache_reuse=False), held).records_reused
    assert not plan(validate(room()), GI, held).records_reused  # the same view reuses the whole cache instead


def test_a_view_with_fewer_cache_points_reads_the_records_of_more_but_not_the_reverse():
    full = plan(validate(room()), GI)
    held = Held(digests=full.digests, generations=full.generations, tables=full.tables,
                photon_key=full.photon_key, cache_key=full.cache_key, records_keys=(full.records_key,))
    coarse = dataclasses.replace(GI, cache_seeds=GI.cache_seeds // 16)
    turned = plan(validate(moved_camera(room())), coarse, held)
    assert turned.records_reused and turned.records_source == full.records_key != turned.records_key
    assert "cache_records_reused" in turned.stages
    # the full pass does not read the sparser records of a coarse one
    held.records_keys = (turned.records_key,)
    assert not plan(validate(moved_camera(room())), GI, held).records_reused
    assert not plan(validate(moved_camera(room())), dataclasses.replace(coarse, gather_rays=GI.gather_rays // 2),
                    Held(**{**held.__dict__, "records_keys": (full.records_key,)})).records_reused


def test_a_photon_share_traces_fewer_photons_only_where_the_maps_held_cannot_serve():
    held = held_after(room(), GI)
    quick = dataclasses.replace(GI, photon_share=0.25)
    material = plan(validate(room(albedo=0.7)), quick, held)
    assert material.traces_photons and material.photon_counts == (5_000, 5_000)
    camera = plan(validate(moved_camera(room())), quick, held)
    assert camera.photons_reused and camera.photon_counts == (20_000, 20_000)
    light = plan(validate(room(power=200.0)), quick, held)
    assert light.reweights_photons and light.photon_counts == (20_000, 20_000)
    # maps of the share held: a later quick render of the same lit scene uses them
    shared = dataclasses.replace(held, photon_key=material.photon_key, generations=material.generations,
                                 digests=material.digests, tables=material.tables)
    again = plan(validate(room(albedo=0.7)), quick, shared)
    assert again.photons_reused and again.photon_counts == (5_000, 5_000)
    assert plan(validate(room(albedo=0.7)), GI, shared).traces_photons


def test_the_triangles_bounds_are_kept_while_the_geometry_is():
    from gpu_core.scene.tables import scene_tables

    scene = validate(room())
    first = scene_tables(scene)
    np.testing.assert_array_equal(first.triangle_bounds, [[-1, -1, -1], [1, 1, 1]])
    kept = scene_tables(validate(moved_camera(room())), first, {"camera"})
    assert kept.triangle_bounds is first.triangle_bounds
    shifted = scene_tables(validate(room(shift=-0.5)), first, {"geometry"})
    np.testing.assert_array_equal(shifted.triangle_bounds[0], [-1.5, -1, -1])
    # the frame stays while the bounds' centre moves a little (0.25 of a 1.9 half-diagonal)...
    assert shifted.center is first.center
    lo, hi = np.array([-1.5, -1, -1]), np.array([1.0, 1, 1])  # the bounding sphere still holds the scene
    assert shifted.radius >= np.linalg.norm(np.maximum(hi - shifted.center, shifted.center - lo)) > first.radius
    # ... and follows them further (1.5 of 2.9)
    far_wall = scene_tables(validate(room(shift=-3.0)), first, {"geometry"})
    np.testing.assert_array_equal(far_wall.center, [-1.5, 0, 0])
    # a light moved out of the box widens the bounds without reading the triangles again
    far = room()
    far.lights.position[0] = (0.0, 0.0, 5.0)
    lit = scene_tables(validate(far), first, {"lights"})
    assert lit.triangle_bounds is first.triangle_bounds and lit.center[2] == 2.0


def test_a_move_of_few_triangles_is_overlaid_on_the_tree_held():
    held = dataclasses.replace(held_after(room(), GI), tree_base=validate(room()).triangles.copy())
    moved_wall = plan(validate(room(shift=0.1)), GI, held)
    assert "kdtree_overlay" in moved_wall.stages and "kdtree" not in moved_wall.stages
    assert len(moved_wall.tree_rows) == 2 and "2 of 12 triangles moved" in moved_wall.reuse["kdtree"]
    assert moved_wall.traces_photons  # the light paths still change


def test_a_move_of_many_triangles_or_of_the_frame_builds_the_whole_tree():
    held = dataclasses.replace(held_after(room(), GI), tree_base=validate(room()).triangles.copy())
    # the frame moves with the scene's bounds: every triangle is uploaded again
    assert "kdtree" in plan(validate(room(shift=-3.0)), GI, held).stages
    # past the overlay's share (a quarter of the triangles): a wall's two and the mirror's two of 14
    base = validate(room(mirror=True)).triangles.copy()
    moved = room(mirror=True, shift=0.1)
    moved.triangles[-2:, :, 2] += 0.01
    shared = dataclasses.replace(held_after(room(mirror=True), GI), tree_base=base)
    many = plan(validate(moved), GI, shared)
    assert "kdtree" in many.stages and (many.tables.center == shared.tables.center).all()
    moved.triangles[-2:, :, 2] -= 0.01  # the wall alone: 2 of 14
    assert "kdtree_overlay" in plan(validate(moved), GI, shared).stages


def test_an_overlaid_tree_renders_what_a_tree_built_afresh_renders(device):
    afresh = dataclasses.replace(GI, cache_reuse=False)  # cache points chosen afresh, as the fresh render's
    renderer = Renderer(device)
    renderer.render(room(mirror=True), afresh)
    overlaid = renderer.render(room(mirror=True, shift=0.1), afresh)
    fresh = Renderer(device).render(room(mirror=True, shift=0.1), afresh)
    assert "kdtree_overlay" in overlaid.stats["plan"] and "kdtree" in fresh.stats["plan"]
    assert overlaid.stats["kdtree"]["overlay_triangles"] == 2
    np.testing.assert_allclose(overlaid.passes["Combined"], fresh.passes["Combined"], rtol=1e-5, atol=1e-6)
    # moved back: the base tree alone again
    back = renderer.render(room(mirror=True), afresh)
    assert "kdtree_overlay" in back.stats["plan"] and "overlay_triangles" not in back.stats["kdtree"]
