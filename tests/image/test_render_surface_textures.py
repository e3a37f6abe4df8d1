"""Textures on Roughness and Metallic, and a tangent-space normal map, in the image kernel."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, plane_scene

from gpu_core.device.constants import TEXTURE_LUMINANCE
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, LIGHT_SUN, Lights
from gpu_core.settings import RenderSettings

SIZE = 32
HEIGHT = 4.0
HALF = 2.0
ALBEDO = 0.8
PLANE = 40.0
# a glTF-style packed texture: occlusion, roughness, metallic in r, g, b
ORM = np.array([[[1.0, 0.3, 0.6, 1.0]]], np.float32)


def render(device, scene, samples=8):
    return Renderer(device).render(scene, RenderSettings(samples=samples)).passes["Combined"][..., :3]


def lit_plane(**material):
    """The plane under a point light beside the camera, with ``material``'s fields."""
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.5, 0.3, 3.0), power=(200.0,) * 3, radius=0.2)])
    scene = plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE))
    for key, value in material.items():
        getattr(scene.materials, key)[0] = value
    return scene


def with_uvs(scene):
    """The plane's UVs as its x and y over its size: the tangent is +x, the bitangent +y."""
    corners = scene.triangles[:2, :, :2]
    scene.uvs[:2] = (corners / PLANE + 0.5).astype(np.float32)
    return scene


def test_roughness_and_metallic_textures_render_as_the_values_they_hold(device):
    constant = render(device, lit_plane(metallic=0.6, roughness=0.3))
    textured = lit_plane(metallic=0.0, roughness=0.9, roughness_texture=0, roughness_channel=1,
                         metallic_texture=0, metallic_channel=2)
    textured.textures = [ORM]
    other = render(device, lit_plane(metallic=0.0, roughness=0.9))
    np.testing.assert_allclose(render(device, textured), constant, rtol=1e-5, atol=1e-7)
    assert np.abs(other - constant).max() > 0.05 * constant.max()  # the textures changed the image


def test_a_value_socket_reads_the_colours_luminance(device):
    constant = render(device, lit_plane(metallic=1.0, roughness=0.4))
    textured = lit_plane(metallic=1.0, roughness=0.0, roughness_texture=0, roughness_channel=TEXTURE_LUMINANCE)
    textured.textures = [np.array([[[0.4, 0.4, 0.4, 0.0]]], np.float32)]
    np.testing.assert_allclose(render(device, textured), constant, rtol=1e-4, atol=1e-7)


def test_a_textured_roughness_plans_caustics_and_glossy_paths_from_its_range():
    smooth = lit_plane(metallic=1.0, roughness=0.5, roughness_texture=0, roughness_channel=1)
    smooth.textures = [np.array([[[0, 0.05, 0, 1], [0, 0.6, 0, 1]]], np.float32)]
    assert smooth.has_specular() and smooth.has_glossy() and smooth.has_textures()
    rough = lit_plane(metallic=1.0, roughness=0.0, roughness_texture=0, roughness_channel=1)
    rough.textures = [np.array([[[0, 0.5, 0, 1]]], np.float32)]
    assert not rough.has_specular() and rough.has_glossy()
    mirror = lit_plane(metallic=0.0, roughness=0.0, metallic_texture=0, metallic_channel=0)
    mirror.textures = [np.array([[[1.0, 0, 0, 1]]], np.float32)]
    assert mirror.has_specular() and not mirror.has_glossy()


def sun_scene(azimuth, theta, **material):
    """The diffuse plane under a sun at zenith angle theta from azimuth (radians)."""
    toward = np.array([np.cos(azimuth) * np.sin(theta), np.sin(azimuth) * np.sin(theta), np.cos(theta)])
    lights = Lights.make([dict(kind=LIGHT_SUN, direction=tuple(-toward), power=(2.0,) * 3, sun_angle=np.radians(1))])
    scene = with_uvs(plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE), albedo=ALBEDO, plane_size=PLANE))
    for key, value in material.items():
        getattr(scene.materials, key)[0] = value
    return scene, toward


def normal_texel(normal):
    """The texel of a tangent-space normal (x along the tangent, y the bitangent, z the normal)."""
    return np.array([[[*(0.5 * np.asarray(normal) + 0.5), 1.0]]], np.float32)


def bump_shadowing(tilt, theta):
    """Cycles' diffuse bump shadowing: GGX G1 at the light's angle theta to
    the smooth normal, of alpha^2 = tan^2(tilt) / 8 for a map tilted by tilt."""
    alpha2 = min(np.tan(tilt) ** 2 / 8, 1.0)
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha2 * np.tan(theta) ** 2))


@pytest.mark.parametrize("azimuth", [0.0, np.pi / 2, 3 * np.pi / 4])
def test_normal_map_tilted_toward_the_sun_receives_it_head_on(device, azimuth):
    theta = np.radians(50)
    scene, toward = sun_scene(azimuth, theta, normal_texture=0)
    scene.textures = [normal_texel(toward)]
    flat, _ = sun_scene(azimuth, theta)
    full = ALBEDO / np.pi * 2.0
    # head on, less the shadowing of a normal tilted 50 degrees (0.944)
    np.testing.assert_allclose(render(device, scene), full * bump_shadowing(theta, theta), rtol=0.01)
    np.testing.assert_allclose(render(device, flat), full * np.cos(theta), rtol=0.01)


def test_corner_tangents_given_with_the_scene_orient_the_normal_map(device):
    # the map tilts the normal along its tangent; corner tangents along +y
    # (as MikkTSpace gives them) turn it toward a sun from +y, where the
    # plane's UVs alone (u along x) would turn it sideways
    theta = np.radians(50)
    scene, _ = sun_scene(np.pi / 2, theta, normal_texture=0)
    scene.textures = [normal_texel((np.sin(theta), 0.0, np.cos(theta)))]
    scene.tangents = np.tile(np.array([0.0, 1.0, 0.0, 1.0], np.float32), (len(scene.triangles), 3, 1))
    assert scene.has_tangents()
    full = ALBEDO / np.pi * 2.0 * bump_shadowing(theta, theta)
    result = Renderer(device).render(scene, RenderSettings(samples=8))
    assert "corner_tangents" in result.stats["plan"]
    np.testing.assert_allclose(result.passes["Combined"][..., :3], full, rtol=0.01)
    scene.tangents[:] = 0.0  # no tangent given: the triangle's UV direction
    np.testing.assert_allclose(render(device, scene).mean(), full * np.cos(theta) ** 2, rtol=0.01)


def test_normal_map_tilted_away_from_the_sun_receives_it_more_obliquely(device):
    theta, tilt = np.radians(20), np.radians(30)
    scene, _ = sun_scene(0.0, theta, normal_texture=0)
    scene.textures = [normal_texel((-np.sin(tilt), 0.0, np.cos(tilt)))]
    expected = ALBEDO / np.pi * 2.0 * np.cos(theta + tilt) * bump_shadowing(tilt, theta)
    np.testing.assert_allclose(render(device, scene), expected, rtol=0.01)


def test_light_below_the_smooth_surface_does_not_reach_a_normal_mapped_one(device):
    # smooth normals tilted 30 degrees toward -x, the map turning them 60 degrees back toward +x,
    # a sun from +x 70 degrees from the zenith: above the facet and the mapped normal, below the
    # smooth surface, where Cycles lets no light through
    scene, _ = sun_scene(0.0, np.radians(70), normal_texture=0)
    scene.normals[:] = (-np.sin(np.radians(30)), 0.0, np.cos(np.radians(30)))
    scene.textures = [normal_texel((np.sin(np.radians(60)), 0.0, np.cos(np.radians(60))))]
    assert render(device, scene).max() == 0.0
    scene.materials.normal_texture[0] = -1  # the smooth normal alone: the light is behind it too
    assert render(device, scene).max() == 0.0
    scene.normals[:] = (0.0, 0.0, 1.0)  # flat: lit
    assert render(device, scene).min() > 0.0


@pytest.mark.parametrize("strength, texel", [(0.0, (0.6, 0.0, 0.8)), (1.0, (0.0, 0.0, 1.0))])
def test_flat_normal_map_or_zero_strength_keeps_the_smooth_normal(device, strength, texel):
    theta = np.radians(40)
    scene, _ = sun_scene(0.3, theta, normal_texture=0, normal_strength=strength)
    scene.textures = [normal_texel(texel)]
    flat, _ = sun_scene(0.3, theta)
    np.testing.assert_allclose(render(device, scene), render(device, flat), rtol=1e-4)


def test_normal_maps_at_the_extremes_stay_finite(device):
    """Texels pointing into the surface, zero texels, huge strength, degenerate UVs."""
    for texel, strength, uvs in (((0.0, 0.0, -1.0), 1.0, True), ((-1.0, -1.0, -1.0), 50.0, True),
                                 ((1.0, 0.0, 0.0), 1.0, False)):
        scene, _ = sun_scene(0.0, np.radians(30), normal_texture=0, normal_strength=strength)
        scene.textures = [np.array([[[*(0.5 * np.asarray(texel) + 0.5), 1.0]]], np.float32)]
        if not uvs:
            scene.uvs[:] = 0.25
        img = render(device, scene, samples=2)
        assert np.isfinite(img).all() and (img >= 0).all()


@pytest.mark.parametrize("closest", [False, True], ids=["linear", "closest"])
def test_a_closest_texture_reads_the_texel_a_point_falls_in(device, closest):
    # two texels, 0.2 and 0.8 grey; the view spans u 0.45..0.55 around their edge at 0.5
    dark, bright = (render(device, with_uvs(lit_plane(base_color=(grey,) * 3))) for grey in (0.2, 0.8))
    scene = with_uvs(lit_plane(base_color=(1.0, 1.0, 1.0), texture_id=0))
    scene.textures = [np.array([[[0.2, 0.2, 0.2, 1.0], [0.8, 0.8, 0.8, 1.0]]], np.float32)]
    scene.texture_closest = [closest]
    image = render(device, scene)
    left, right = slice(0, SIZE // 2 - 1), slice(SIZE // 2 + 1, SIZE)
    if closest:
        np.testing.assert_allclose(image[:, left], dark[:, left], rtol=1e-4, atol=1e-7)
        np.testing.assert_allclose(image[:, right], bright[:, right], rtol=1e-4, atol=1e-7)
    else:
        # bilinear between the texel centres at u = 0.25 and 0.75: greys of 0.44-0.56 here
        assert (image[:, left] > 1.8 * dark[:, left]).all() and (image[:, right] < 0.75 * bright[:, right]).all()
