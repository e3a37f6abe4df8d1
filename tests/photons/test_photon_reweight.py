"""Photon maps reweighted for a change of light power or colour alone
(photons/reweight.py): the same maps a fresh trace gives for one light,
trees whose node sums match their photons, the emitted power restated,
and a fresh trace wherever the photons' paths would change."""

import dataclasses

import numpy as np
import pytest
from scenes_py import plane_scene, quad

from gpu_core.photons.emit import emitter_powers, maps_needed, reweight_scales
from gpu_core.photons.reweight import reweight_maps
from gpu_core.photons.trace import PhotonSettings, trace_maps
from gpu_core.plan import Held, plan
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, LIGHT_SPOT, Lights, validate
from gpu_core.scene.tables import scene_defines, scene_tables
from gpu_core.scene.upload import upload
from gpu_core.settings import RenderSettings

MIRROR = dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.0)


def lit_scene(powers, world=(0.0, 0.0, 0.0), spot_angle=1.0, position=(0, 0, 2)):
    """A floor with a mirror panel (so a caustic map is traced) under a
    point light and, with two powers, a spot; ``powers`` rgb each."""
    rows = [dict(kind=LIGHT_POINT, position=position, power=powers[0])]
    if len(powers) > 1:
        rows.append(dict(kind=LIGHT_SPOT, position=(-1, 0, 2), power=powers[1], spot_angle=spot_angle,
                         spot_blend=0.2))
    return plane_scene(Lights.make(rows), plane_size=6.0, world=world, extra_tris=[quad((1.2, 0, 0.6), 1.0, normal_axis=0, flip=True)],
                       extra_materials=[MIRROR])


def traced(device, scene):
    """The validated scene's maps, with the emitters and light table they were traced for."""
    scene = validate(scene)
    tables = scene_tables(scene)
    buffers = upload(device, scene, tables)
    emitters = emitter_powers(scene, tables)
    maps = maps_needed(emitters, scene.triangle_count, scene.has_specular(), 20_000, 5_000)
    settings = PhotonSettings(20_000, 5_000, seed=3, k_hint=20)
    return trace_maps(device, buffers, emitters, maps, settings, scene_defines(scene)), emitters, tables.lights


def reweighted(device, before, after):
    """The maps of ``before`` reweighted to the lights of ``after``."""
    maps, emitters, lights = traced(device, before)
    after = validate(after)
    tables = scene_tables(after)
    new = emitter_powers(after, tables)
    scales = reweight_scales(emitters, lights, new, tables.lights)
    assert scales is not None
    reweight_maps(device, maps, scales, emitters, new)
    return maps


def test_one_light_reweighted_gives_the_maps_a_fresh_trace_gives(device):
    # with one emitter every photon keeps its path: only its power changes
    maps = reweighted(device, lit_scene([(100, 100, 100)]), lit_scene([(300, 50, 0)]))
    fresh, _, _ = traced(device, lit_scene([(300, 50, 0)]))
    assert maps.caustic_map is not None and maps.caustic_map.point_count > 0
    for ours, theirs in ((maps.global_map, fresh.global_map), (maps.caustic_map, fresh.caustic_map)):
        np.testing.assert_allclose(ours.photons()["power"], theirs.photons()["power"], rtol=1e-5, atol=1e-12)
        a, b = ours.node_info(), theirs.node_info()
        for name in ("power", "irradiance"):
            np.testing.assert_allclose(a[name][:, :3], b[name][:, :3], rtol=2e-4, atol=1e-6 * b[name].max())
    for name in ("global", "caustic"):
        np.testing.assert_allclose(maps.stats["emitted_power"][name], fresh.stats["emitted_power"][name], rtol=1e-4,
                                   atol=1e-3)
    np.testing.assert_allclose(maps.stats["light_power"], fresh.stats["light_power"], rtol=1e-6)


def test_each_node_sums_its_photons_after_reweighting_two_lights(device):
    before = lit_scene([(100, 100, 100), (50, 50, 50)], world=(0.05, 0.05, 0.05))
    after = lit_scene([(100, 100, 100), (200, 20, 50)], world=(0.1, 0.05, 0.0))
    maps = reweighted(device, before, after)
    tree = maps.global_map
    power, info = tree.photons()["power"].astype(np.float64), tree.node_info()
    sums = np.array([power[f:f + c].sum(axis=0) for f, c in zip(info["first"], info["count"])])
    np.testing.assert_allclose(info["power"][:, :3], sums, rtol=1e-4, atol=1e-9 * sums.max())
    # the spot's photons carry its new colour, the point light's are as before
    fresh, _, _ = traced(device, after)
    np.testing.assert_allclose(power.sum(axis=0), fresh.global_map.photons()["power"].sum(axis=0), rtol=0.05)
    assert np.isfinite(info["irradiance"]).all()


@pytest.mark.parametrize("change", ["moved", "turned_on_a_channel", "cone", "added_light"])
def test_a_change_of_the_photons_paths_is_not_reweighted(change):
    before = validate(lit_scene([(100, 100, 0), (50, 50, 50)]))
    after = validate({
        "moved": lit_scene([(100, 100, 0), (50, 50, 50)], position=(0.1, 0, 2)),
        "turned_on_a_channel": lit_scene([(100, 100, 10), (50, 50, 50)]),
        "cone": lit_scene([(100, 100, 0), (50, 50, 50)], spot_angle=1.2),
        "added_light": lit_scene([(100, 100, 0), (50, 50, 50)], world=(0.1, 0.1, 0.1)),
    }[change])
    t0, t1 = scene_tables(before), scene_tables(after)
    assert reweight_scales(emitter_powers(before, t0), t0.lights, emitter_powers(after, t1), t1.lights) is None


def test_a_light_made_enormously_brighter_is_traced_again_not_scaled_out_of_range():
    before = validate(lit_scene([(1e-20, 1e-20, 1e-20)]))
    after = validate(lit_scene([(1e20, 1e20, 1e20)]))
    t0, t1 = scene_tables(before), scene_tables(after)
    assert reweight_scales(emitter_powers(before, t0), t0.lights, emitter_powers(after, t1), t1.lights) is None


def test_a_light_turned_dark_in_a_channel_is_reweighted_to_zero_there():
    before = validate(lit_scene([(100, 100, 100), (50, 50, 50)]))
    after = validate(lit_scene([(100, 0, 100), (50, 50, 50)]))
    t0, t1 = scene_tables(before), scene_tables(after)
    scales = reweight_scales(emitter_powers(before, t0), t0.lights, emitter_powers(after, t1), t1.lights)
    np.testing.assert_allclose(scales[:, :3], [[1, 0, 1], [1, 1, 1]])


GI = RenderSettings(mode="gi", samples=2, global_photons=20_000, caustic_photons=5_000, photon_k=20, cache_seeds=60,
                    gather_rays=16)


def test_a_light_power_edit_reweights_and_renders_the_fresh_image(device):
    renderer = Renderer(device)
    renderer.render(lit_scene([(100, 100, 100)]), GI)
    edited = lit_scene([(250, 150, 100)])
    result = renderer.render(edited, GI, edits={"lights"})
    stages = result.stats["plan"]
    assert "global_photons_reweighted" in stages and "caustic_photons_reweighted" in stages
    assert result.stats["gi"]["photons_reweighted"] and "final_gather" in stages
    fresh = Renderer(device).render(edited, GI)
    ours, theirs = result.passes["Combined"][..., :3], fresh.passes["Combined"][..., :3]
    assert np.isfinite(ours).all()
    np.testing.assert_allclose(ours, theirs, rtol=2e-3, atol=2e-3 * theirs.max())
    # a move of the light traces again
    moved = renderer.render(lit_scene([(250, 150, 100)], position=(0.2, 0, 2)), GI, edits={"lights"})
    assert "global_photons" in moved.stats["plan"] and not moved.stats["gi"]["photons_reweighted"]


def test_the_plan_reweights_only_from_maps_held_for_the_same_surfaces():
    first = plan(validate(lit_scene([(100, 100, 100)])), GI)
    held = Held(digests=first.digests, generations=first.generations, tables=first.tables,
                photon_key=first.photon_key, photon_emitters=first.emitters, photon_lights=first.tables.lights)
    brighter = plan(validate(lit_scene([(200, 200, 200)])), GI, held, edits={"lights"})
    assert brighter.reweights_photons and not brighter.traces_photons
    assert "reweighted" in brighter.reuse["photons"]
    more_photons = plan(validate(lit_scene([(200, 200, 200)])), dataclasses.replace(GI, global_photons=30_000), held,
                        edits={"lights"})
    assert more_photons.traces_photons and not more_photons.reweights_photons
    unknown = dataclasses.replace(held, photon_emitters=None)
    assert plan(validate(lit_scene([(200, 200, 200)])), GI, unknown, edits={"lights"}).traces_photons
