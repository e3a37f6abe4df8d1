"""Photon tracing: emitted power in watts, energy over bounces, irradiance
by density estimation against analytic values, caustic map planning,
extreme light powers."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad, sphere

from gpu_core.photons import trace as photon_trace
from gpu_core.photons import trace_photon_maps
from gpu_core.renderer import Renderer
from gpu_core.settings import RenderSettings
from gpu_core.scene import LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Lights, Materials

UP = np.array([0.0, 0.0, 1.0])


def closed_box(albedo, lights, size=2.0):
    """A cube seen from inside: six faces facing inwards, one material."""
    h = size / 2
    faces = [quad((0, 0, -h), size), quad((0, 0, h), size, flip=True),
             quad((0, -h, 0), size, normal_axis=1), quad((0, h, 0), size, normal_axis=1, flip=True),
             quad((-h, 0, 0), size, normal_axis=0), quad((h, 0, 0), size, normal_axis=0, flip=True)]
    tris = np.concatenate(faces)
    mats = Materials.make([dict(base_color=(albedo,) * 3)])
    return make_scene(tris, np.zeros(len(tris), np.int32), mats, lights, plane_scene(lights).camera)


def irradiance(maps, points, k=100):
    """Global-map irradiance at points on the plane z = 0 facing +Z."""
    return maps.global_map.irradiance(points - maps.center, np.tile(UP, (len(points), 1)), k=k)[:, 0]


def test_emitted_power_equals_the_lights_power(device):
    lights = Lights.make([
        dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(100, 50, 25)),
        dict(kind=LIGHT_AREA, position=(1, 0, 3), power=(40, 40, 40), axis_u=(0.5, 0, 0), axis_v=(0, 0.5, 0)),
        dict(kind=LIGHT_SUN, direction=(0.3, 0, -1), power=(2, 2, 2)),
        dict(kind=LIGHT_SPOT, position=(-1, 0, 2), power=(30, 30, 30), spot_angle=1.0, spot_blend=0.0),
    ])
    emitter = quad((0, 0, 4), 1.0, flip=True)
    scene = plane_scene(lights, plane_size=10.0, world=(0.1, 0.1, 0.1), extra_tris=[emitter],
                        extra_materials=[dict(base_color=(0, 0, 0), emission=(3, 3, 3))])
    maps = trace_photon_maps(device, scene, global_photons=20000, caustic_photons=0, seed=1)
    lo, hi = scene.bounds()
    r = 0.5 * np.linalg.norm(hi - lo)
    want = (np.array([100, 50, 25]) + 40 + 2 * np.pi * r**2 + 30 * 0.5 * (1 - np.cos(0.5))
            + 2 * np.pi * 1.0 * 3 + 4 * np.pi**2 * r**2 * 0.1)
    np.testing.assert_allclose(maps.stats["light_power"], want, rtol=1e-6)
    np.testing.assert_allclose(maps.stats["emitted_power"]["global"], want, rtol=1e-4)
    assert maps.stats["emitters"] == 6
    assert maps.stats["emitted"]["global"] == pytest.approx(20000, abs=6)


def test_spot_photons_carry_the_power_inside_the_falloff(device):
    lights = Lights.make([dict(kind=LIGHT_SPOT, position=(0, 0, 2), power=(30, 30, 30), spot_angle=1.2, spot_blend=0.5)])
    maps = trace_photon_maps(device, plane_scene(lights), global_photons=20000, seed=1)
    # smoothstep over the outer half of the cone (in cos): it averages 1/2 there
    width = 1 - np.cos(0.6)
    want = 30 / 2 * (width / 2 + width / 2 * 0.5)
    np.testing.assert_allclose(maps.stats["light_power"], want, rtol=1e-6)
    np.testing.assert_allclose(maps.stats["emitted_power"]["global"], want, rtol=0.01)


@pytest.mark.parametrize("albedo", [0.3, 0.7])
def test_closed_box_stores_power_over_one_minus_albedo(device, albedo):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.1, -0.2, 0.3), power=(10, 10, 10))])
    maps = trace_photon_maps(device, closed_box(albedo, lights), global_photons=20000, seed=3, max_bounces=60)
    stored = maps.global_map.node_info()[0]["power"][:3]
    np.testing.assert_allclose(stored, 10 / (1 - albedo), rtol=0.03)
    assert maps.stats["mean_path_length"]["global"] == pytest.approx(1 / (1 - albedo), rel=0.03)
    assert maps.stats["stored"]["global"] == maps.global_map.point_count


def test_a_bright_closed_box_is_traced_once_into_buffers_sized_by_a_sample(device, monkeypatch):
    # albedo 0.8: five stores per photon, more than the fixed guess of three would hold
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.1, -0.2, 0.3), power=(10, 10, 10))])
    scene = closed_box(0.8, lights)
    sized = trace_photon_maps(device, scene, global_photons=20000, seed=3, max_bounces=60)
    assert sized.stats["stored"]["global"] > photon_trace.STORE_GUESS * 20000
    assert sized.stats["passes"]["global"] == 1
    # a sample that falls short: traced again with room for all, the same map
    monkeypatch.setattr(photon_trace, "SAMPLE_MARGIN", 0.5)
    short = trace_photon_maps(device, scene, global_photons=20000, seed=3, max_bounces=60)
    assert short.stats["passes"]["global"] == 2
    np.testing.assert_array_equal(short.global_map.positions(), sized.global_map.positions())
    np.testing.assert_array_equal(short.global_map.photons()["power"], sized.global_map.photons()["power"])


def test_photons_in_a_row_leave_in_neighbouring_directions_covering_all_evenly(device):
    # a point light inside a closed box, one store per photon (no bounce):
    # the stored photons in photon order, each with the direction it left in
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 0), power=(10, 10, 10))])
    n = 26000  # not a multiple of the 128 x 128 cells: 1.6 photons a cell
    maps = trace_photon_maps(device, closed_box(0.5, lights), global_photons=n, seed=4, max_bounces=0)
    tree = maps.global_map
    assert tree.point_count == n
    left = np.empty((n, 3))
    left[tree.leaf_order()] = -tree.photons()["direction"]
    # next to each other in photon order, next to each other in direction
    # (independent directions would give a mean cosine of 0)
    assert np.mean(np.sum(left[1:] * left[:-1], axis=1)) > 0.9
    # and every direction as likely: z and the azimuth in eight equal bins
    z = np.histogram(left[:, 2], bins=8, range=(-1, 1))[0]
    azimuth = np.histogram(np.arctan2(left[:, 1], left[:, 0]), bins=8, range=(-np.pi, np.pi))[0]
    np.testing.assert_allclose(z, n / 8, rtol=0.04)
    np.testing.assert_allclose(azimuth, n / 8, rtol=0.04)


def test_bounce_limit_ends_paths(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 0), power=(10, 10, 10))])
    maps = trace_photon_maps(device, closed_box(1.0, lights), global_photons=2000, max_bounces=3)
    # albedo 1: every photon is stored at each of its 4 hits (more than the
    # first guess of the buffer holds: the pass runs again with room for all)
    assert maps.stats["stored"]["global"] == 4 * 2000
    assert maps.stats["dropped"]["global"] == 0
    np.testing.assert_allclose(maps.global_map.node_info()[0]["power"][:3], 40, rtol=1e-4)


def test_irradiance_under_a_point_light(device):
    h, power = 2.0, 100.0
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, h), power=(power,) * 3)])
    maps = trace_photon_maps(device, plane_scene(lights), global_photons=200000, seed=5)
    xy = np.random.default_rng(0).uniform(-1.5, 1.5, (300, 2))
    points = np.c_[xy, np.zeros(len(xy))]
    d = np.sqrt((xy**2).sum(1) + h * h)
    want = power / (4 * np.pi) * h / d**3  # intensity x cos / distance^2
    ratio = irradiance(maps, points) / want
    assert abs(ratio.mean() - 1) < 0.05
    assert np.all(np.abs(ratio - 1) < 0.5)


def test_irradiance_under_an_area_light(device):
    h, power, size = 1.0, 50.0, 1.0
    lights = Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, h), power=(power,) * 3,
                               axis_u=(size, 0, 0), axis_v=(0, size, 0))])
    maps = trace_photon_maps(device, plane_scene(lights), global_photons=200000, seed=6)
    xy = np.random.default_rng(1).uniform(-1.0, 1.0, (300, 2))
    points = np.c_[xy, np.zeros(len(xy))]
    # analytic: radiance P / (pi A) integrated with cos cos' / d^2 over the light (midpoint rule)
    g = (np.arange(200) + 0.5) / 200 * size - size / 2
    lx, ly = np.meshgrid(g, g)
    dx = lx.ravel()[None, :] - xy[:, :1]
    dy = ly.ravel()[None, :] - xy[:, 1:]
    d2 = dx**2 + dy**2 + h * h
    want = power / (np.pi * size**2) * (h * h / d2**2).sum(1) * (size / 200) ** 2
    ratio = irradiance(maps, points) / want
    assert abs(ratio.mean() - 1) < 0.05
    assert np.all(np.abs(ratio - 1) < 0.5)


SPOT_AND_SUN = dict(lights=[dict(kind=LIGHT_SPOT, position=(0.2, 0, 2), power=(100,) * 3, spot_angle=1.2),
                            dict(kind=LIGHT_SUN, direction=(0.3, 0, -1), power=(3,) * 3)])
# an emissive square out of the camera's view, facing down, and a grey world
MESH_AND_WORLD = dict(lights=[], world=(0.2, 0.2, 0.2), extra_tris=[quad((1.5, 0, 1), 0.5, flip=True)],
                      extra_materials=[dict(base_color=(0, 0, 0), emission=(5, 5, 5))])


@pytest.mark.parametrize("setup", [SPOT_AND_SUN, MESH_AND_WORLD], ids=["spot+sun", "mesh+world"])
def test_radiance_estimate_matches_the_renderers_direct_light(device, setup):
    """albedo / pi x photon irradiance equals what render.cl computes with
    shadow rays, pixel by pixel."""
    size, half = 12, 0.8
    setup = dict(setup, lights=Lights.make(setup["lights"]))
    scene = plane_scene(camera=camera_looking_down(4.0, half, size, ortho=True), albedo=0.8, plane_size=4.0, **setup)
    image = Renderer(device).render(scene, RenderSettings(samples=64)).passes["Combined"][..., 0]
    maps = trace_photon_maps(device, scene, global_photons=200000, seed=4)
    c = (np.arange(size) + 0.5) / size * 2 * half - half
    x, y = np.meshgrid(c, c)  # image rows count y from the bottom
    points = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    radiance = 0.8 / np.pi * irradiance(maps, points).reshape(size, size)
    assert abs(radiance.mean() / image.mean() - 1) < 0.05
    assert np.all(np.abs(radiance / image - 1) < 0.5)  # k = 100: about 10% noise per pixel


def test_no_specular_surface_skips_the_caustic_map(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(10, 10, 10))])
    maps = trace_photon_maps(device, plane_scene(lights), global_photons=1000, caustic_photons=1000)
    assert maps.caustic_map is None
    assert maps.stats["maps"]["caustic"].startswith("skipped: no specular")
    assert maps.stats["maps"]["global"] == "built"
    assert "caustic" not in maps.stats["emitted"] and "trace_caustic" not in maps.stats["ms"]


def test_glass_sphere_focuses_a_caustic(device):
    lights = Lights.make([dict(kind=LIGHT_SPOT, position=(0, 0, 4), power=(100, 100, 100), spot_angle=0.4)])
    glass = sphere((0, 0, 1.0), 0.5)
    scene = plane_scene(lights, extra_tris=[glass], extra_materials=[dict(base_color=(1, 1, 1), transmission=1.0, ior=1.5, roughness=0.0)])
    maps = trace_photon_maps(device, scene, global_photons=2000, caustic_photons=20000, seed=2)
    assert maps.stats["maps"]["caustic"].startswith("built")
    tree = maps.caustic_map
    assert tree.point_count > 1000
    pts = tree.positions() + maps.center
    assert np.all(np.abs(pts[:, 2]) < 1e-4)  # stored on the diffuse plane only
    photons = tree.photons()
    assert np.all(photons["normal"][:, 2] > 0.999) and np.all(photons["direction"][:, 2] > 0)
    assert np.all(photons["power"] > 0)
    # the sphere focuses: the photons crowd near its axis more than the bare cone would
    r = np.hypot(pts[:, 0], pts[:, 1])
    assert np.median(r) < 0.5 * 4 * np.tan(0.2)


def test_a_mirror_casts_its_share_of_the_light_as_a_caustic(device):
    """A point light over a small mirror under a diffuse ceiling: the caustic
    map holds the reflected light, P x reflectance x solid angle / 4 pi."""
    power, reflectance = 100.0, 0.9
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(power,) * 3)])
    mirror, ceiling = quad((0, 0, 0.5), 0.5), quad((0, 0, 3), 4.0, flip=True)
    scene = plane_scene(lights, extra_tris=[mirror, ceiling],
                        extra_materials=[dict(base_color=(reflectance,) * 3, metallic=1.0, roughness=0.0), dict()])
    maps = trace_photon_maps(device, scene, global_photons=1000, caustic_photons=100000, seed=3)
    tree = maps.caustic_map
    assert np.all(np.abs(tree.positions()[:, 2] + maps.center[2] - 3) < 1e-4)
    assert np.all(tree.photons()["normal"][:, 2] < -0.999)
    # solid angle of a centred a x a square at distance d: 4 asin(a^2 / (a^2 + 4 d^2))
    solid = 4 * np.arcsin(0.25 / (0.25 + 4 * 1.5**2))
    np.testing.assert_allclose(tree.node_info()[0]["power"][:3], power * reflectance * solid / (4 * np.pi), rtol=0.1)


def test_zero_lights_give_empty_finite_maps(device):
    maps = trace_photon_maps(device, plane_scene(Lights.make([])), global_photons=1000)
    assert maps.global_map is None and maps.caustic_map is None
    assert maps.stats["maps"]["global"] == "skipped: no light emits power"


def test_the_seed_fixes_the_photons(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.1, -0.2, 0.3), power=(10, 10, 10))])
    scene = closed_box(0.5, lights)

    def photons(seed):
        tree = trace_photon_maps(device, scene, global_photons=2000, seed=seed).global_map
        return np.sort(tree.positions(), axis=0)  # slots come from an atomic counter, in any order

    first = photons(1)
    np.testing.assert_array_equal(photons(1), first)
    other = photons(2)
    assert other.shape != first.shape or not np.array_equal(other, first)


def test_photons_that_hit_nothing_leave_an_empty_map(device):
    lights = Lights.make([dict(kind=LIGHT_SPOT, position=(0, 0, 1), direction=(0, 0, 1), power=(10, 10, 10))])
    maps = trace_photon_maps(device, plane_scene(lights), global_photons=500)
    assert maps.stats["maps"]["global"] == "built" and maps.stats["stored"]["global"] == 0
    assert maps.stats["mean_path_length"]["global"] == 0
    idx, d2 = maps.global_map.knn(np.zeros((3, 3), np.float32), 5)
    assert np.all(idx == -1) and np.all(np.isinf(d2))
    assert np.all(maps.global_map.irradiance(np.zeros((3, 3)), np.tile(UP, (3, 1)), k=5) == 0)


def test_extreme_light_powers_scale_linearly(device):
    def estimate(power):
        lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(power,) * 3)])
        maps = trace_photon_maps(device, plane_scene(lights), global_photons=5000, seed=9)
        return irradiance(maps, np.array([[0.0, 0.0, 0.0], [0.5, 0.2, 0.0]]), k=50)

    unit = estimate(1.0)
    for power in (1e8, 1e-6):
        e = estimate(power)
        assert np.all(np.isfinite(e)) and np.all(e > 0)
        np.testing.assert_allclose(e / power, unit, rtol=1e-3)
