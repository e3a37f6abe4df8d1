"""Light and denoising passes: they add up to Combined, each light path lands
in the pass Cycles would give it, and the Caustics pass matches a mirror-image
oracle."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad

from gpu_core.renderer import DENOISING_PASSES, LIGHT_PASSES, Renderer
from gpu_core.scene import LIGHT_AREA, LIGHT_POINT, Lights, Materials
from gpu_core.settings import RenderSettings

SUMMED = LIGHT_PASSES[:-1]  # all but Caustics, which repeats a part of the others


def mixed_scene():
    """Every kind of path in one view: a small diffuse floor (the world shows
    around it), a mirror that sees a diffuse ceiling and the world, a glass
    square half over the floor, an emitter, a point light and a world colour."""
    mats = Materials.make([
        dict(base_color=(0.8, 0.8, 0.8)),  # floor and ceiling
        dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.0),  # mirror
        dict(base_color=(1.0, 1.0, 1.0), transmission=1.0, ior=1.5, roughness=0.0),  # glass
        dict(base_color=(0.0, 0.0, 0.0), emission=(2.0, 1.0, 0.5)),  # emitter
    ])
    parts = [
        (quad((0, 0, 0), 1.6), 0),
        (quad((-1.5, 0.5, 6.0), 2.0, flip=True), 0),
        (quad((-0.5, 0.5, 0.5), 0.6), 1),
        (quad((0.6, 0.6, 0.5), 0.6), 2),
        (quad((-0.5, -0.5, 0.3), 0.4), 3),
    ]
    tris = np.concatenate([t for t, _ in parts])
    ids = np.concatenate([[m] * len(t) for t, m in parts]).astype(np.int32)
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.3, -0.3, 3.0), power=(80.0,) * 3)])
    return make_scene(tris, ids, mats, lights, camera_looking_down(height=4.0, size=32), world=(0.2, 0.3, 0.4))


def render(device, scene, **settings):
    return Renderer(device).render(scene, RenderSettings(light_passes=True, **settings)).passes


@pytest.mark.parametrize("clamp", [0.0, 0.5])
def test_light_passes_add_up_to_combined(device, clamp):
    passes = render(device, mixed_scene(), samples=16, diffuse_bounces=2, clamp=clamp)
    total = sum(passes[name].astype(np.float64) for name in SUMMED)
    combined = passes["Combined"][..., :3]
    assert combined.mean() > 0.05
    np.testing.assert_allclose(total, combined, rtol=1e-5, atol=1e-6)
    # every kind of path of this scene reached its pass
    for name in SUMMED:
        assert passes[name].mean() > 1e-4, name
    assert all(np.isfinite(passes[name]).all() for name in LIGHT_PASSES)


@pytest.mark.parametrize("clamp", [0.0, 0.5])
def test_combined_is_the_same_with_and_without_the_light_passes(device, clamp):
    # without the passes the kernel sums a path's light once instead of per
    # pass (IMAGE_LIGHT_PASSES): the same paths, so the same image but for
    # the order of float additions
    settings = dict(samples=16, diffuse_bounces=2, clamp=clamp)
    with_passes = render(device, mixed_scene(), **settings)["Combined"]
    without = Renderer(device).render(mixed_scene(), RenderSettings(**settings)).passes["Combined"]
    assert without.mean() > 0.05
    np.testing.assert_allclose(without, with_passes, rtol=1e-5, atol=1e-6)


def test_direct_light_on_a_diffuse_plane_is_all_diffuse_direct(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(100.0,) * 3)])
    passes = render(device, plane_scene(lights, camera_looking_down(size=16)), samples=4)
    np.testing.assert_array_equal(passes["Diffuse Direct"], passes["Combined"][..., :3])
    for name in LIGHT_PASSES[1:]:
        assert not passes[name].any(), name


def test_caustics_pass_matches_the_mirror_image_of_the_light(device):
    """An area light facing up under a mirror ceiling: the floor sees it only
    through the mirror (L S D paths, all Caustics). Its mirror image, a light
    facing down as far above the mirror, lights a floor without mirror
    directly; times the mirror's reflectance that is the same irradiance."""
    height, light_z, reflectance = 1.5, 1.0, 0.8
    camera = camera_looking_down(height=0.9, half_width=0.5, size=16)
    area = dict(kind=LIGHT_AREA, power=(150.0,) * 3, axis_u=(1.0, 0, 0), axis_v=(0, 1.0, 0))
    up = Lights.make([dict(area, position=(0, 0, light_z), direction=(0, 0, 1.0))])
    mirror = quad((0, 0, height), 40.0, flip=True)
    caustic = render(device, plane_scene(up, camera, extra_tris=[mirror],
                                         extra_materials=[dict(base_color=(reflectance,) * 3, metallic=1.0, roughness=0.0)]),
                     samples=256, diffuse_bounces=1)
    image = Lights.make([dict(area, position=(0, 0, 2 * height - light_z), direction=(0, 0, -1.0))])
    direct = render(device, plane_scene(image, camera), samples=16)

    assert not caustic["Diffuse Direct"].any()  # the light faces away from the floor
    np.testing.assert_array_equal(caustic["Caustics"], caustic["Diffuse Indirect"])
    expected = reflectance * direct["Combined"][..., :3].mean()
    assert expected > 0.05
    assert caustic["Caustics"].mean() == pytest.approx(expected, rel=0.05)


def test_caustics_pass_is_empty_without_specular_surfaces(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(50.0,) * 3)])
    ceiling = quad((0, 0, 2.0), 40.0, flip=True)
    passes = render(device, plane_scene(lights, camera_looking_down(height=1.5, size=16), extra_tris=[ceiling],
                                        extra_materials=[dict(base_color=(0.8,) * 3)]), samples=4, diffuse_bounces=3)
    assert passes["Diffuse Indirect"].mean() > 0.01
    assert not passes["Caustics"].any()


def test_denoising_albedo_and_normal_follow_mirrors_to_the_first_diffuse_surface(device):
    """Left half: the floor seen directly (albedo 0.8). Right half: a mirror of
    reflectance 0.5 facing up, which sees the world (albedo 0.5 x 1)."""
    mirror = quad((1.0, 0, 0.5), 2.0)
    scene = plane_scene(Lights.make([]), camera_looking_down(height=4.0, ortho=True, size=16), world=(0.3,) * 3,
                        extra_tris=[mirror], extra_materials=[dict(base_color=(0.5,) * 3, metallic=1.0, roughness=0.0)])
    passes = Renderer(device).render(scene, RenderSettings(samples=4, denoising_passes=True)).passes
    albedo, normal = passes["Denoising Albedo"], passes["Denoising Normal"]
    left, right = np.s_[:, 1:7], np.s_[:, 9:15]
    np.testing.assert_allclose(albedo[left], 0.8, rtol=1e-5)
    np.testing.assert_allclose(albedo[right], 0.5, rtol=1e-5)
    # camera space: the floor faces the camera (+Z); seen only through the mirror, no normal
    np.testing.assert_allclose(normal[left], np.broadcast_to([0.0, 0.0, 1.0], normal[left].shape), atol=1e-5)
    assert not normal[right].any()
    np.testing.assert_array_equal(passes["Denoising Depth"], passes["Depth"])


def test_passes_are_only_computed_when_asked_for(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(100.0,) * 3)])
    scene = plane_scene(lights, camera_looking_down(size=8))
    plain = Renderer(device).render(scene, RenderSettings(samples=2)).passes
    assert set(plain) == {"Combined", "Depth", "Normal"}
    both = Renderer(device).render(scene, RenderSettings(samples=2, light_passes=True, denoising_passes=True))
    assert set(both.passes) == {"Combined", "Depth", "Normal", *LIGHT_PASSES, *DENOISING_PASSES}
    # asking for passes does not change the image
    np.testing.assert_array_equal(both.passes["Combined"], plain["Combined"])


def test_plan_lists_the_passes_asked_for(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(100.0,) * 3)])
    scene = plane_scene(lights, camera_looking_down(size=8))
    plain = Renderer(device).render(scene, RenderSettings(samples=1)).stats["plan"]
    both = Renderer(device).render(scene, RenderSettings(samples=1, light_passes=True, denoising_passes=True))
    assert not {"light_passes", "denoising_passes"} & set(plain)
    assert both.stats["plan"] == plain + ["light_passes", "denoising_passes"]


def test_without_geometry_passes_only_combined_and_the_asked_denoising_passes_come_back(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(100.0,) * 3)])
    scene = plane_scene(lights, camera_looking_down(size=8))
    full = Renderer(device).render(scene, RenderSettings(samples=2, denoising_passes=True)).passes
    lean = Renderer(device).render(scene, RenderSettings(samples=2, geometry_passes=False)).passes
    assert set(lean) == {"Combined"}
    np.testing.assert_array_equal(lean["Combined"], full["Combined"])
    guided = Renderer(device).render(scene, RenderSettings(samples=2, geometry_passes=False,
                                                           denoising_passes=True)).passes
    assert set(guided) == {"Combined", *DENOISING_PASSES}
    np.testing.assert_array_equal(guided["Denoising Depth"], full["Depth"])
