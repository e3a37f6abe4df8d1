"""Path-traced diffuse bounces: energy in a closed box follows the geometric series."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights, Materials
from gpu_core.settings import RenderSettings


def closed_box(albedo, emission, size=2.0):
    """A cube seen from inside: six faces facing inwards, all one material."""
    h = size / 2
    faces = [quad((0, 0, -h), size), quad((0, 0, h), size, flip=True),
             quad((0, -h, 0), size, normal_axis=1), quad((0, h, 0), size, normal_axis=1, flip=True),
             quad((-h, 0, 0), size, normal_axis=0), quad((h, 0, 0), size, normal_axis=0, flip=True)]
    tris = np.concatenate(faces)
    mats = Materials.make([dict(base_color=(albedo,) * 3, emission=(emission,) * 3)])
    return make_scene(tris, np.zeros(len(tris), np.int32), mats, Lights.make([]),
                      camera_looking_down(height=0.5, half_width=0.25, size=16))


@pytest.mark.parametrize("albedo", [0.0, 0.5, 0.8])
def test_furnace_box_radiance_is_emission_over_one_minus_albedo(device, albedo):
    scene = closed_box(albedo, 1.0)
    img = Renderer(device).render(scene, RenderSettings(samples=512, diffuse_bounces=64)).passes["Combined"]
    expected = 1.0 / (1.0 - albedo)
    assert np.isfinite(img).all()
    assert abs(img[..., :3].mean() / expected - 1) < 0.02


def test_albedo_one_closed_box_stays_bounded_and_finite(device):
    scene = closed_box(1.0, 1.0)
    img = Renderer(device).render(scene, RenderSettings(samples=256, diffuse_bounces=16)).passes["Combined"]
    assert np.isfinite(img).all()
    # the emitter seen directly, then one unit of direct light at each of the 17 hits: 18, not infinity
    assert abs(img[..., :3].mean() / 18.0 - 1) < 0.03


def test_zero_diffuse_bounces_is_direct_light_only(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(50,) * 3)])
    wall = quad((0, 0, 2.0), 40.0, flip=True)
    scene = plane_scene(lights, camera_looking_down(height=1.5, size=16), extra_tris=[wall], extra_materials=[dict(base_color=(0.8,) * 3)])
    direct = Renderer(device).render(scene, RenderSettings(samples=16)).passes["Combined"]
    full = Renderer(device).render(scene, RenderSettings(samples=16, diffuse_bounces=4)).passes["Combined"]
    # the ceiling bounces light back: indirect makes the floor brighter, never darker
    assert full[..., :3].mean() > direct[..., :3].mean() * 1.05
