"""The GI mode: shading points, final gathering, and whole images against
the reference path tracer (the same kernels' ground truth), at the extremes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scenes_py import box_scene, camera_looking_down, on_device, plane_scene, quad

from gpu_core.device.layout import float4_rows
from gpu_core.gi import cut, gather, shading_points
from gpu_core.gi.cache import neighbours
from gpu_core.photons.trace import trace_photon_maps
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_AREA, Lights
from gpu_core.settings import RenderSettings

# small and quick: a few thousand photons and cache points at 24 x 24 pixels
GI = RenderSettings(mode="gi", samples=4, global_photons=60_000, caustic_photons=60_000, photon_k=40,
                    cache_seeds=150, gather_rays=64, cut_delta=0.25)


def rgb(result):
    return result.passes["Combined"][..., :3].astype(np.float64)


# -- stage kernels against oracles ----------------------------------------------


def constant_cut(device, irradiance):
    """A cut giving ``irradiance`` at every surface of a box: one node per
    wall direction, each spanning the whole box."""
    normals = np.concatenate([np.eye(3), -np.eye(3)])
    return cut.Cut.from_nodes(device, np.zeros((6, 3)), normals, np.full(6, 100.0), np.full((6, 3), irradiance))


def test_gather_in_a_closed_box_returns_albedo_times_the_irradiance_it_is_given(device):
    scene, up = on_device(device, box_scene(albedo=0.5))
    points = shading_points.trace(device, up, (0, 0, 24, 24), 8)
    rng = np.random.default_rng(0)
    # points on the edges where two walls meet too: they step back off both walls
    on_edge = np.nonzero((np.abs(points.positions) > 0.999).sum(axis=1) >= 2)[0]
    assert len(on_edge) >= 10
    pick = np.concatenate([on_edge[:20], rng.choice(len(points.positions), 20, replace=False)])
    result = gather.gather(device, up, device.to_device(float4_rows(points.positions[pick])),
                           device.to_device(float4_rows(points.normals[pick])), len(pick), 6,
                           constant_cut(device, 2.0))
    assert result.stats["hit_fraction"] == 1.0  # nothing escapes a closed box
    np.testing.assert_allclose(result.irradiance, 0.5 * 2.0, rtol=1e-5)
    assert (result.translational_gradient == 0.0).all()  # the same light everywhere
    # every hit lies inside the 2 m box, at most its diagonal away
    assert np.all((result.harmonic_distance > 0) & (result.harmonic_distance < 2 * np.sqrt(3)))


def test_gather_gradient_matches_finite_differences_of_the_gathered_irradiance(device):
    # in the closed box, the wall at x = +1 lit ten times brighter (red; green five, blue alike)
    scene, up = on_device(device, box_scene(albedo=0.5))
    normals = np.concatenate([np.eye(3), -np.eye(3)])
    lit = np.ones((6, 3))
    lit[3] = (10.0, 5.0, 1.0)
    the_cut = cut.Cut.from_nodes(device, np.zeros((6, 3)), normals, np.full(6, 100.0), lit)
    up_normal = np.array([0.0, 0.0, 1.0])

    def at(p, seeds=range(8)):
        """Irradiance and gradient at p (normal +z), means over seeds of 32 x 32 rays."""
        point, normal = device.to_device(float4_rows([p])), device.to_device(float4_rows([up_normal]))
        runs = [gather.gather(device, up, point, normal, 1, 32, the_cut, seed=seed) for seed in seeds]
        return (np.mean([r.irradiance[0] for r in runs], axis=0),
                np.mean([r.translational_gradient[0] for r in runs], axis=0))
    p, h = np.array([0.3, 0.2, -0.5]), 0.02
    _, gradient = at(p)
    fd = np.stack([(at(p + h * axis)[0] - at(p - h * axis)[0]) / (2 * h) for axis in np.eye(3)[:2]], axis=1)
    assert (gradient[:, 2] == 0.0).all()  # it lies in the tangent plane
    assert (gradient[2] == 0.0).all() and np.abs(fd[2]).max() < 1e-3  # blue is the same everywhere
    for channel in range(2):  # red and green: towards the bright wall, as the differences say
        g, d = gradient[channel, :2], fd[channel]
        assert g[0] > 0.0
        assert abs(np.linalg.norm(g) / np.linalg.norm(d) - 1.0) < 0.15
        assert np.dot(g, d) / (np.linalg.norm(g) * np.linalg.norm(d)) > np.cos(np.radians(6.0))


def test_gather_is_the_same_in_batches_of_any_size(device, monkeypatch):
    # each batch sorts its rays' cut lookups along a Morton curve: the order
    # of the lookups changes with the batch, a ray's light must not
    scene, up = on_device(device, box_scene(albedo=0.5, mirror=True))
    maps = trace_photon_maps(device, scene, 20_000, 20_000)
    the_cut = cut.with_caustics(cut.select(device, maps.global_map, 20), maps.caustic_map, 16)
    assert the_cut.count > 50
    points = shading_points.trace(device, up, (0, 0, 24, 24), 8)
    pick = np.random.default_rng(1).choice(len(points.positions), 30, replace=False)
    positions = device.to_device(float4_rows(points.positions[pick]))
    normals = device.to_device(float4_rows(points.normals[pick]))

    def gathered():
        result = gather.gather(device, up, positions, normals, len(pick), 8, the_cut)
        return result.irradiance, result.harmonic_distance, result.translational_gradient
    whole = gathered()
    monkeypatch.setattr(gather, "_RAYS_PER_LAUNCH", 3 * 64)  # 3 samples a batch: 10 sorts
    for one, other in zip(whole, gathered()):
        np.testing.assert_array_equal(one, other)
    assert whole[0].min() > 0.0


def test_shading_points_look_through_mirrors_to_the_surfaces_they_show(device):
    scene, up = on_device(device, box_scene(albedo=0.5, mirror=True))
    points = shading_points.trace(device, up, (0, 0, 24, 24), 8, subpixels=2)
    # every camera ray ends on a diffuse surface: the floor, walls, or their mirror image
    assert len(points.positions) == 24 * 24 * 4
    p = points.positions
    on_mirror = (np.abs(p[:, 2] + 0.98) < 1e-3) & (np.abs(p[:, 0] - 0.6) < 0.4) & (np.abs(p[:, 1]) < 0.4)
    assert not on_mirror.any()
    # the rays that met the mirror went on up: points on the ceiling and upper walls
    assert (p[:, 2] > 0.0).sum() > 20


# -- whole images ----------------------------------------------------------------


def test_gi_image_matches_the_reference_path_tracer_in_a_closed_box(device):
    scene = box_scene(albedo=0.5)
    gi = rgb(Renderer(device).render(scene, GI))
    reference = rgb(Renderer(device).render(scene, RenderSettings(samples=256, diffuse_bounces=32)))
    assert np.isfinite(gi).all()
    assert abs(gi.mean() / reference.mean() - 1.0) < 0.05
    assert np.sqrt(((gi - reference) ** 2).mean()) / reference.mean() < 0.12


def test_light_seen_through_a_mirror_reaches_the_image(device):
    scene = box_scene(albedo=0.5, mirror=True)
    gi = rgb(Renderer(device).render(scene, GI))
    reference = rgb(Renderer(device).render(scene, RenderSettings(samples=256, diffuse_bounces=32)))
    assert abs(gi.mean() / reference.mean() - 1.0) < 0.06


def test_caustic_k_sets_the_photons_of_each_estimate_of_the_caustics_seen_directly(device):
    """An area light facing up under a mirror ceiling: the floor sees it only
    through the mirror, all of it the caustic map's. Its mirror image, a
    light facing down as far above, lights a bare floor directly; times the
    mirror's reflectance that is the same irradiance. Fewer photons per
    estimate: the same light, noisier."""
    height, light_z, reflectance = 1.5, 1.0, 0.8
    camera = camera_looking_down(height=0.9, half_width=0.5, size=16)
    area = dict(kind=LIGHT_AREA, power=(150.0,) * 3, axis_u=(1.0, 0, 0), axis_v=(0, 1.0, 0))
    up = Lights.make([dict(area, position=(0, 0, light_z), direction=(0, 0, 1.0))])
    mirror = dict(base_color=(reflectance,) * 3, metallic=1.0, roughness=0.0)
    scene = plane_scene(up, camera, extra_tris=[quad((0, 0, height), 40.0, flip=True)], extra_materials=[mirror])
    image = Lights.make([dict(area, position=(0, 0, 2 * height - light_z), direction=(0, 0, -1.0))])
    direct = Renderer(device).render(plane_scene(image, camera), RenderSettings(samples=16)).passes["Combined"]
    expected = reflectance * direct[..., :3].mean()
    settings = dataclasses.replace(GI, global_photons=20_000, cache_seeds=80, gather_rays=16, light_passes=True)
    few, many = (Renderer(device).render(scene, dataclasses.replace(settings, caustic_k=k)).passes for k in (4, 64))
    for passes in (few, many):
        assert passes["Caustics"].mean() == pytest.approx(expected, rel=0.1)
    spread = [passes["Caustics"].std() / passes["Caustics"].mean() for passes in (few, many)]
    assert spread[0] > 2.0 * spread[1]


def test_cache_iterations_cap_the_k_means_and_a_change_chooses_the_cache_points_again(device):
    renderer, scene = Renderer(device), box_scene(albedo=0.5)
    one = renderer.render(scene, dataclasses.replace(GI, cache_iterations=1)).stats["gi"]
    assert one["selection"]["iterations"] == 1
    three = renderer.render(scene, dataclasses.replace(GI, cache_iterations=3)).stats["gi"]
    assert not three["cache_reused"] and 1 < three["selection"]["iterations"] <= 3


def test_plan_names_the_gi_stages_and_skips_the_caustic_map_without_mirrors(device):
    result = Renderer(device).render(box_scene(), GI)
    plan = result.stats["plan"]
    assert result.stats["mode"] == "gi"
    assert {"global_photons", "sample_points", "illumination_cut", "final_gather", "interpolation"} <= set(plan)
    assert "caustic_photons" not in plan and "path_traced_indirect" not in plan
    assert result.stats["gi"]["photons"]["maps"]["caustic"].startswith("skipped")
    with_mirror = Renderer(device).render(box_scene(mirror=True), GI)
    assert {"caustic_photons", "caustics"} <= set(with_mirror.stats["plan"])


def test_photons_and_kdtree_are_not_rebuilt_when_only_the_camera_moves(device):
    renderer = Renderer(device)
    scene = box_scene()
    first = renderer.render(scene, GI)
    camera = dataclasses.replace(scene.camera, matrix=scene.camera.matrix.copy())
    camera.matrix[0, 3] += 0.1
    moved = renderer.render(dataclasses.replace(scene, camera=camera), GI)
    assert "global_photons" in first.stats["plan"] and "kdtree" in first.stats["plan"]
    assert "global_photons_reused" in moved.stats["plan"] and moved.stats["gi"]["photons_reused"]
    assert "kdtree_reused" in moved.stats["plan"]
    brighter = renderer.render(box_scene(power=200.0), GI)
    assert "global_photons_reweighted" in brighter.stats["plan"]  # a light power edit reweights the photons
    assert "kdtree_reused" in brighter.stats["plan"]  # the same triangles keep their tree


# -- extremes ----------------------------------------------------------------------


def test_no_lights_give_a_black_finite_image(device):
    image = rgb(Renderer(device).render(box_scene(light=False), GI))
    assert np.isfinite(image).all() and image.max() == 0.0


@pytest.mark.parametrize("power", [1e-6, 1e8])
def test_dim_and_blinding_lights_scale_the_image_linearly(device, power):
    base = rgb(Renderer(device).render(box_scene(power=1.0), GI))
    scaled = rgb(Renderer(device).render(box_scene(power=power), GI))
    assert np.isfinite(scaled).all()
    np.testing.assert_allclose(scaled.mean() / power, base.mean(), rtol=1e-3)


def test_albedo_one_walls_stay_finite_and_bounded(device):
    image = rgb(Renderer(device).render(box_scene(albedo=1.0), GI))
    direct = rgb(Renderer(device).render(box_scene(albedo=1.0), RenderSettings(samples=4)))
    assert np.isfinite(image).all()
    # light keeps bouncing up to the photon bounce limit: brighter than direct, not unbounded
    assert direct.mean() < image.mean() < 20 * direct.mean()


@pytest.mark.parametrize("knobs", [dict(cache_seeds=1), dict(cache_seeds=24 * 24), dict(gather_rays=1)],
                         ids=["one_seed", "one_seed_per_pixel", "one_gather_ray"])
def test_extreme_cache_settings_leave_no_holes(device, knobs):
    image = rgb(Renderer(device).render(box_scene(), dataclasses.replace(GI, **knobs)))
    indirect_free = rgb(Renderer(device).render(box_scene(), RenderSettings(samples=4)))
    assert np.isfinite(image).all()
    # every pixel gets some indirect light on top of its direct light
    assert np.all(image.sum(axis=2) > indirect_free.sum(axis=2))


@pytest.mark.parametrize("size, offset", [(1e-3, 0.0), (1e4, 0.0), (2.0, 1e5)],
                         ids=["millimetre", "ten_km", "far_from_origin"])
def test_scaled_and_moved_scenes_give_the_unit_scene_image(device, size, offset):
    unit = rgb(Renderer(device).render(box_scene(), GI))
    # irradiance falls with distance squared: power scaled with size^2 keeps the image
    other = box_scene(size=size, power=100.0 * (size / 2.0) ** 2, offset=(offset, -offset, offset))
    image = rgb(Renderer(device).render(other, GI))
    assert np.isfinite(image).all()
    assert abs(image.mean() / unit.mean() - 1.0) < 0.03
    assert np.sqrt(((image - unit) ** 2).mean()) / unit.mean() < 0.1


def test_a_lone_bright_cache_sample_is_brought_down_and_light_no_neighbour_saw_is_shared(device):
    rng = np.random.default_rng(3)
    m = 400
    positions = np.zeros((m, 3), np.float32)
    positions[:, :2] = rng.uniform(-1, 1, (m, 2))
    positions[7, :2] = (-0.8, -0.8)
    positions[11, :2] = (-0.6, 0.6)
    normals = np.tile(np.float32([0.0, 0.0, 1.0]), (m, 1))
    d = np.linalg.norm(positions[:, None, :2] - positions[None, :, :2], axis=2)
    nearest = np.argsort(d, axis=1)[:, 1:neighbours.NEIGHBOURS + 1]
    sideways = nearest[11][0]
    normals[sideways] = (1.0, 0.0, 0.0)  # a neighbour on a wall facing elsewhere: no share
    irradiance = np.ones((m, 3), np.float32)
    irradiance[7] = 100.0  # one sample saw a focused caustic
    bright = np.linalg.norm(positions[:, :2] - [0.5, 0.5], axis=1) < 0.35
    irradiance[bright] = 50.0  # a lit patch many samples see
    dark = np.linalg.norm(positions[:, :2] - [-0.6, 0.6], axis=1) < 0.35
    irradiance[dark] = 0.0  # a region no light reaches but through sample 11's rays
    irradiance[11] = 9.0
    checked = neighbours.check(device, device.to_device(float4_rows(positions)), device.to_device(float4_rows(normals)),
                               device.to_device(float4_rows(irradiance)), device.to_device(np.ones(m, np.float32)), m)
    out = device.read(checked.irradiance, (m, 4), np.float32)[:, :3]
    # the host's reading: an outlier down to OUTLIER_RATIO x its neighbours' median; where that
    # median is 0, its light split evenly over itself and the samples that list it and face its way
    facing = (normals @ normals.T > neighbours.SHARE_COS)[np.arange(m)[:, None], nearest]
    limit = neighbours.OUTLIER_RATIO * np.median(irradiance[nearest, 0], axis=1)
    lone = (limit == 0.0) & (irradiance[:, 0] > 0.0)
    kept = np.where(lone, 0.0, np.minimum(irradiance[:, 0], limit))
    receivers = np.bincount(nearest[facing], minlength=m)
    share = np.where(lone, irradiance[:, 0], 0.0) / (1 + receivers)
    expected = kept + share + (share[nearest] * facing).sum(axis=1)
    np.testing.assert_allclose(out[:, 0], expected, rtol=1e-5)
    assert abs(out[7, 0] - 4.0) < 1e-5 and checked.outliers_clamped >= 2
    # sample 11's light is shared, the sideways sample left out, and no shared light is lost
    assert out[sideways, 0] == 0.0 and out[11, 0] == np.float32(9.0 / (1 + receivers[11])) and receivers[11] >= 4
    dropped = np.where(lone, 0.0, irradiance[:, 0] - kept)
    np.testing.assert_allclose(out[:, 0].sum(), (irradiance[:, 0] - dropped).sum(), rtol=1e-5)
    # the patch stays lit where its samples' neighbours are in it too; samples away from the
    # outlier and the dark region are untouched
    inner = bright & bright[nearest].all(axis=1)
    assert inner.sum() > 10 and np.all(out[inner] == 50.0)
    away = ~bright & (np.linalg.norm(positions[:, :2] - [-0.6, 0.6], axis=1) > 0.7) & (np.arange(m) != 7)
    assert np.all(out[away & ~np.isin(np.arange(m), nearest[7])] == 1.0) and away.sum() > 150


def _clamped_radii(device, positions, radii):
    """neighbours.check's R_j of samples at ``positions`` with distances ``radii``."""
    m = len(positions)
    up = device.to_device(float4_rows(np.tile(np.float32([0.0, 0.0, 1.0]), (m, 1))))
    checked = neighbours.check(device, device.to_device(float4_rows(positions)), up,
                               device.to_device(float4_rows(np.ones((m, 3), np.float32))),
                               device.to_device(np.asarray(radii, np.float32)), m)
    return device.read(checked.radii, m, np.float32), checked.radii_clamped


def test_samples_whose_rays_met_nothing_take_the_largest_finite_radius(device):
    rng = np.random.default_rng(5)
    lit = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    far = (rng.uniform(-0.1, 0.1, (30, 3)) + [40.0, 0.0, 0.0]).astype(np.float32)  # no finite R within reach
    radii = np.concatenate([rng.uniform(0.1, 0.5, 300), np.full(30, np.inf)]).astype(np.float32)
    positions = np.concatenate([lit, far])
    out, _ = _clamped_radii(device, positions, radii)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[300:], out[:300].max())
    # with no finite distance at all there is nothing to bound them by
    out, _ = _clamped_radii(device, far, np.full(30, np.inf, np.float32))
    assert np.isinf(out).all()


def test_neighbour_clamping_matches_rounds_of_the_bound_over_each_samples_nearest(device):
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(11)
    positions = rng.uniform(-1, 1, (600, 3)).astype(np.float32)
    radii = rng.uniform(0.05, 3.0, 600).astype(np.float32)
    radii[rng.choice(600, 30, replace=False)] = np.inf  # samples whose rays hit nothing
    radii[rng.choice(600, 20, replace=False)] = 1e-3  # samples in crevices
    out, count = _clamped_radii(device, positions, radii)
    # the oracle: the same rounds over cKDTree's neighbours, in float32
    dist, idx = cKDTree(positions.astype(np.float64)).query(positions.astype(np.float64), neighbours.NEIGHBOURS + 1)
    dist, idx = dist[:, 1:].astype(np.float32), idx[:, 1:]
    expect = radii.copy()
    for _ in range(neighbours.RADIUS_ROUNDS):
        expect = np.minimum(expect, (expect[idx] + dist).min(axis=1))
    np.testing.assert_allclose(out, expect, rtol=1e-5)
    assert np.all(out <= radii) and np.isfinite(out).all()
    assert count == int((out < radii).sum()) and count > 100


def test_a_small_distance_bounds_the_samples_around_it_and_no_distance_grows(device):
    # a row of samples 0.1 apart, all open (R = 5) but one in a crevice (R = 0.01)
    positions = np.zeros((40, 3), np.float32)
    positions[:, 0] = 0.1 * np.arange(40)
    radii = np.full(40, 5.0, np.float32)
    radii[20] = 0.01
    out, count = _clamped_radii(device, positions, radii)
    hops = np.abs(np.arange(40) - 20)
    # within RADIUS_ROUNDS neighbours of it: its R plus the way there; further out: untouched or bounded
    near = hops <= neighbours.RADIUS_ROUNDS
    np.testing.assert_allclose(out[near], 0.01 + 0.1 * hops[near], rtol=1e-5)
    assert np.all(out <= radii) and out[20] == np.float32(0.01)
    assert count == 39 - int(np.sum(out == 5.0))


def test_neighbour_checks_leave_too_few_samples_as_they_are(device):
    positions = np.zeros((neighbours.NEIGHBOURS, 3), np.float32)
    positions[:, 0] = np.arange(neighbours.NEIGHBOURS)
    radii = np.array([1e-3] + [10.0] * (neighbours.NEIGHBOURS - 1), np.float32)
    out, count = _clamped_radii(device, positions, radii)
    assert count == 0 and np.array_equal(out, radii)
