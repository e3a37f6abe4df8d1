"""Mixes of surfaces (Mix and Add Shader): a chain of material rows, one
picked per shading event by its chance and scaled by its weight over it,
renders as the weighted sum of its surfaces, in shadows too."""

import dataclasses

import numpy as np
import pytest
from scenes_py import box_scene, camera_looking_down, make_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, LIGHT_SUN, MATERIAL_TRANSPARENT, TEXTURE_LUMINANCE, Lights, Materials
from gpu_core.scene.tables import scene_defines
from gpu_core.settings import RenderSettings

SIZE = 32
RED = dict(base_color=(0.9, 0.2, 0.2))
BLUE = dict(base_color=(0.2, 0.3, 0.9))
METAL = dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.3)
DIRECT = dict(diffuse_bounces=0)


def plane(rows, lights=None, half_width=1.0):
    """A 4 m plane of material row 0 (the other rows its mix), under a
    point light beside the camera, seen from above."""
    lights = lights or Lights.make([dict(kind=LIGHT_POINT, position=(0.5, 0.3, 3.0), power=(300.0,) * 3,
                                         radius=0.1)])
    scene = make_scene(quad((0, 0, 0), 4.0), [0, 0], Materials.make(rows), lights,
                       camera_looking_down(4.0, half_width, SIZE))
    # u runs along x over the plane, v along y
    scene.uvs[:] = (scene.triangles[:, :, :2] / 4.0 + 0.5).astype(np.float32)
    return scene


def mix(first, second, chance_first, scale=1.0):
    """The rows of a mix: ``first`` picked with ``chance_first``, else ``second``."""
    return [dict(first, mix_next=1, mix_stop=chance_first, mix_scale=scale), dict(second, mix_scale=scale)]


def render(device, scene, samples=16, **settings):
    result = Renderer(device).render(scene, RenderSettings(samples=samples, **settings))
    return result.passes["Combined"][..., :3].astype(np.float64), result.stats


def blocks(image, n=4):
    """Means of n x n pixel blocks: the pick's noise averaged out."""
    h, w, c = image.shape
    return image.reshape(h // n, n, w // n, n, c).mean(axis=(1, 3))


def test_a_mix_of_a_diffuse_and_a_metal_surface_renders_as_their_weighted_sum(device):
    red, _ = render(device, plane([RED]), **DIRECT)
    metal, _ = render(device, plane([METAL]), samples=512, **DIRECT)
    mixed, stats = render(device, plane(mix(RED, METAL, 0.7)), samples=512, **DIRECT)
    expected = 0.7 * red + 0.3 * metal
    assert "mixed_surfaces" in stats["plan"]
    np.testing.assert_allclose(mixed.mean(axis=(0, 1)), expected.mean(axis=(0, 1)), rtol=0.02)
    # each 4 x 4 block within 6% (the pick's noise under the highlight, 30 times the diffuse light: 3%)
    error = (np.abs(blocks(mixed) - blocks(expected)) / blocks(expected)).max()
    assert error < 0.06, error
    # the highlight of the metal shows, at its weight
    assert np.abs(metal - red).max() > 0.5 * red.max()


def test_an_add_of_two_surfaces_sums_them(device):
    dim, bright = dict(base_color=(0.3,) * 3), dict(base_color=(0.4,) * 3)
    added, _ = render(device, plane(mix(dim, bright, 0.5, scale=2.0)), samples=256, **DIRECT)
    together, _ = render(device, plane([dict(base_color=(0.7,) * 3)]), **DIRECT)
    np.testing.assert_allclose(added.mean(), together.mean(), rtol=0.01)
    np.testing.assert_allclose(blocks(added), blocks(together), rtol=0.03)


def test_a_surface_of_weight_below_one_is_that_much_darker(device):
    weighted, stats = render(device, plane([dict(RED, mix_scale=0.25)]))
    darker, _ = render(device, plane([dict(base_color=(0.225, 0.05, 0.05))]))
    # no chain, nothing picked: the same random numbers, the same image
    assert "mixed_surfaces" not in stats["plan"]
    np.testing.assert_allclose(weighted, darker, rtol=1e-5, atol=1e-7)


def test_a_fac_texture_picks_the_surface_its_texels_hold(device):
    # u < 0.5 holds 0 (the first surface), u > 0.5 holds 1 (the second)
    stripes = np.zeros((1, 16, 4), np.float32)
    stripes[0, 8:] = 1.0
    scene = plane([dict(RED, mix_next=1, mix_stop=0.5, mix_texture=0, mix_channel=0), BLUE], half_width=2.0)
    scene.textures = [stripes]
    masked, _ = render(device, scene, **DIRECT)
    red, _ = render(device, plane([RED], half_width=2.0), **DIRECT)
    blue, _ = render(device, plane([BLUE], half_width=2.0), **DIRECT)
    # away from the texel edges, which bilinear filtering blends
    x = (np.arange(SIZE) + 0.5) / SIZE * 4.0 - 2.0
    left, right = (x > -1.7) & (x < -0.3), (x > 0.3) & (x < 1.7)
    np.testing.assert_allclose(masked[:, left], red[:, left], rtol=0.02, atol=1e-6)
    np.testing.assert_allclose(masked[:, right], blue[:, right], rtol=0.02, atol=1e-6)


@pytest.mark.parametrize("textured", [False, True], ids=["fac_value", "fac_texture"])
def test_a_transparent_surface_in_a_mix_lets_its_share_of_light_through_shadows(device, textured):
    # a sun 45 degrees from -x; a panel 3 m up (x -6.75..-3) shades the view left of x = 0
    sun = Lights.make([dict(kind=LIGHT_SUN, direction=(0.7071, 0.0, -0.7071), power=(3.0,) * 3,
                            sun_angle=np.radians(0.5))])
    transparent = dict(base_color=(0.0, 0.0, 0.0), alpha=0.0)
    panel = dict(base_color=(0.5,) * 3, mix_next=2, mix_stop=0.6)
    if textured:
        panel.update(mix_stop=0.0, mix_texture=0, mix_channel=TEXTURE_LUMINANCE)
    tris = np.concatenate([quad((0, 0, 0), 40.0), quad((-4.875, 0, 3.0), 3.75)])
    mats = Materials.make([dict(base_color=(0.8,) * 3), panel, transparent])
    scene = make_scene(tris, [0, 0, 1, 1], mats, sun, camera_looking_down(4.0, 1.0, SIZE, ortho=True))
    scene.textures = [np.full((1, 1, 4), 0.4, np.float32)]  # 1 - 0.4: the panel's chance
    image, stats = render(device, scene, **DIRECT)
    assert "alpha_shadows" in stats["plan"] and "mixed_surfaces" in stats["plan"]
    x = (np.arange(SIZE) + 0.5) / SIZE * 2.0 - 1.0
    shaded, lit = image[:, x < -0.2].mean(), image[:, x > 0.2].mean()
    assert shaded / lit == pytest.approx(0.4, abs=0.01)


def test_a_tinted_transparent_sheet_tints_the_light_through_it_and_the_view(device):
    # a white floor under a sun straight down, a Transparent shader sheet of
    # colour c above its middle: the light reaches the floor through the
    # sheet and the camera sees it through the sheet again, c^2 of the open floor
    tint = np.array([0.9, 0.5, 0.2])
    sun = Lights.make([dict(kind=LIGHT_SUN, direction=(0, 0, -1), power=(2.0,) * 3)])
    tris = np.concatenate([quad((0, 0, 0), 4.0), quad((0, 0, 1.0), 1.0)])
    mats = Materials.make([dict(base_color=(0.8, 0.8, 0.8)),
                           dict(shader=MATERIAL_TRANSPARENT, base_color=tuple(tint))])
    scene = make_scene(tris, [0, 0, 1, 1], mats, sun, camera_looking_down(4.0, 1.0, SIZE))
    image, stats = render(device, scene, **DIRECT)
    assert "alpha_shadows" in stats["plan"] and np.isfinite(image).all()
    c = SIZE // 2
    through, open_floor = image[c - 2:c + 2, c - 2:c + 2].mean(axis=(0, 1)), image[:3, :3].mean(axis=(0, 1))
    np.testing.assert_allclose(through / open_floor, tint ** 2, rtol=0.02)


def test_mixes_are_planned_only_where_a_triangle_uses_one(device):
    glossy_leaf = plane(mix(RED, METAL, 0.5))
    assert glossy_leaf.has_mix() and glossy_leaf.has_glossy()
    assert scene_defines(glossy_leaf) == {"SCENE_HAS_MIX": 1}
    # the same rows, the chain unused: the triangles use the metal row alone
    unused = dataclasses.replace(glossy_leaf, material_ids=np.array([1, 1], np.int32))
    assert not unused.has_mix() and scene_defines(unused) == {}
    # a leaf with alpha plans see-through shadows
    assert plane(mix(RED, dict(alpha=0.0), 0.5)).has_alpha()
    assert not plane([RED]).has_alpha()


@pytest.mark.parametrize("chain", [
    dict(mix_next=0, mix_stop=0.5),  # itself
    dict(mix_next=7, mix_stop=0.5),  # past the table
    dict(mix_next=1, mix_stop=np.nan, mix_scale=np.inf),
    dict(mix_next=1, mix_stop=-3.0, mix_scale=-1.0),
    dict(mix_next=1, mix_stop=0.5, mix_scale=1e30),
], ids=["self", "out_of_range", "nan_inf", "negative", "huge_scale"])
def test_broken_mix_chains_render_finite(device, chain):
    rows = [dict(RED, **chain), dict(BLUE, mix_next=0)]  # a chain back to the start is cut too
    image, _ = render(device, plane(rows), samples=4)
    assert np.isfinite(image).all() and (image >= 0).all()


def test_a_mix_in_gi_mode_matches_the_blend_it_stands_for(device):
    gi = RenderSettings(mode="gi", samples=4, global_photons=60_000, caustic_photons=60_000, photon_k=40,
                        cache_seeds=150, gather_rays=64, cut_delta=0.25)
    mixed = box_scene(albedo=0.5)
    mixed.materials = Materials.make(mix(dict(base_color=(0.3,) * 3), dict(base_color=(0.7,) * 3), 0.5))
    blended = Renderer(device).render(box_scene(albedo=0.5), gi).passes["Combined"][..., :3]
    result = Renderer(device).render(mixed, gi)
    image = result.passes["Combined"][..., :3]
    assert "mixed_surfaces" in result.stats["plan"] and np.isfinite(image).all()
    assert image.mean() / blended.mean() == pytest.approx(1.0, abs=0.04)
