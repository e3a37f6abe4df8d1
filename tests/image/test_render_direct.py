"""The image kernel against analytic answers: every light type, mirror, glass, passes."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Lights, Materials
from gpu_core.settings import RenderSettings

SIZE = 32
HEIGHT = 4.0
HALF = 2.0
ALBEDO = 0.8


def render(device, scene, samples=16, **kw):
    return Renderer(device).render(scene, RenderSettings(samples=samples, **kw))


def pixel_points(size=SIZE, height=HEIGHT, half=HALF, ortho=False):
    """World (x, y) on z = 0 at each pixel centre of camera_looking_down."""
    c = (np.arange(size) + 0.5) / size * 2 - 1
    if ortho:
        xs = c * half
    else:
        xs = c * (half / height) * height
    x, y = np.meshgrid(xs, xs)  # rows are y (from the bottom), columns x
    return x, y


def point_oracle(position, power, x, y):
    """Radiance of the diffuse plane at (x, y, 0) under an isotropic point light."""
    d = np.stack([position[0] - x, position[1] - y, np.full_like(x, position[2])], -1)
    d2 = (d**2).sum(-1)
    cos = d[..., 2] / np.sqrt(d2)
    return ALBEDO / np.pi * power / (4 * np.pi * d2) * cos


def test_point_light_matches_inverse_square_law(device):
    pos, power = (0.3, -0.2, 1.5), 100.0
    scene = plane_scene(Lights.make([dict(kind=LIGHT_POINT, position=pos, power=(power,) * 3)]),
                        camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene).passes["Combined"]
    x, y = pixel_points()
    expected = point_oracle(pos, power, x, y)
    np.testing.assert_allclose(img[..., 0], expected, rtol=0.03)
    assert abs(img[..., :3].mean() / expected.mean() - 1) < 0.01
    np.testing.assert_array_equal(img[..., 3], 1.0)


def test_orthographic_camera_sees_the_same_law(device):
    pos, power = (0.0, 0.0, 1.0), 50.0
    scene = plane_scene(Lights.make([dict(kind=LIGHT_POINT, position=pos, power=(power,) * 3)]),
                        camera_looking_down(HEIGHT, HALF, SIZE, ortho=True))
    img = render(device, scene).passes["Combined"]
    x, y = pixel_points(ortho=True)
    np.testing.assert_allclose(img[..., 1], point_oracle(pos, power, x, y), rtol=0.04)


def test_spot_light_is_a_point_light_inside_its_cone_and_dark_outside(device):
    pos, power = (0.0, 0.0, 2.0), 100.0
    angle = np.radians(40)
    scene = plane_scene(Lights.make([dict(kind=LIGHT_SPOT, position=pos, power=(power,) * 3,
                                          direction=(0, 0, -1), spot_angle=angle, spot_blend=0.0)]),
                        camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene).passes["Combined"][..., 0]
    x, y = pixel_points()
    off_axis = np.arctan2(np.hypot(x, y), pos[2])
    inside = off_axis < angle / 2 - 0.05
    outside = off_axis > angle / 2 + 0.05
    np.testing.assert_allclose(img[inside], point_oracle(pos, power, x, y)[inside], rtol=0.03)
    assert np.all(img[outside] == 0.0)


def test_sun_gives_uniform_irradiance_strength_times_cosine(device):
    theta = np.radians(35)
    direction = (np.sin(theta), 0.0, -np.cos(theta))
    scene = plane_scene(Lights.make([dict(kind=LIGHT_SUN, direction=direction, power=(3.0, 2.0, 1.0),
                                          sun_angle=np.radians(1))]), camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene).passes["Combined"]
    expected = ALBEDO / np.pi * np.array([3.0, 2.0, 1.0]) * np.cos(theta)
    np.testing.assert_allclose(img[..., :3].reshape(-1, 3), np.tile(expected, (SIZE * SIZE, 1)), rtol=0.01)


@pytest.mark.parametrize("shape", [0, 1])
def test_small_area_light_far_away_acts_like_a_cosine_emitter(device, shape):
    size, power, pos = 0.1, 40.0, np.array([0.0, 0.0, 2.0])
    scene = plane_scene(Lights.make([dict(kind=LIGHT_AREA, position=pos, power=(power,) * 3, direction=(0, 0, -1),
                                          axis_u=(size, 0, 0), axis_v=(0, size, 0), shape=shape)]),
                        camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene, samples=32).passes["Combined"][..., 0]
    x, y = pixel_points()
    d2 = x**2 + y**2 + pos[2] ** 2
    cos = pos[2] / np.sqrt(d2)
    expected = ALBEDO / np.pi * power * cos * cos / (np.pi * d2)
    np.testing.assert_allclose(img, expected, rtol=0.05)
    assert abs(img.mean() / expected.mean() - 1) < 0.01


def test_uniform_world_lights_an_open_plane_to_albedo_times_radiance(device):
    world = (0.5, 0.25, 1.0)
    scene = plane_scene(Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE), world=world)
    img = render(device, scene, samples=4).passes["Combined"]
    np.testing.assert_allclose(img[..., :3], np.broadcast_to(ALBEDO * np.array(world), img[..., :3].shape), rtol=1e-4)


def test_emitter_seen_directly_shows_its_radiance(device):
    scene = make_scene(quad((0, 0, 0), 10.0), [0], Materials.make([dict(base_color=(0, 0, 0), emission=(2.0, 3.0, 4.0))]),
                       Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE))
    scene = make_scene(scene.triangles, [0, 0], scene.materials, scene.lights, scene.camera)
    img = render(device, scene, samples=2).passes["Combined"]
    np.testing.assert_allclose(img[..., :3].reshape(-1, 3), np.tile([2.0, 3.0, 4.0], (SIZE * SIZE, 1)), rtol=1e-6)


def test_mirror_reflects_an_emitter_tinted_by_its_colour(device):
    mirror = quad((0, 0, 0), 20.0)
    sky_panel = quad((0, 0, 10.0), 200.0, flip=True)
    scene = make_scene(np.concatenate([mirror, sky_panel]), [0, 0, 1, 1],
                       Materials.make([dict(base_color=(0.9, 0.5, 0.2), metallic=1.0, roughness=0.0),
                                       dict(base_color=(0, 0, 0), emission=(1.0, 1.0, 1.0))]),
                       Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene, samples=2).passes["Combined"]
    # Schlick's Fresnel from the colour as F0 (Cycles' F82 tint at white), at each pixel's view angle
    x, y = pixel_points()
    cos = HEIGHT / np.sqrt(HEIGHT**2 + x**2 + y**2)
    f0 = np.array([0.9, 0.5, 0.2])
    expected = f0 + (1 - f0) * ((1 - cos) ** 5)[..., None]
    # (the samples spread over each pixel: the angle varies by a few 1e-5 in F)
    np.testing.assert_allclose(img[..., :3], expected, rtol=1e-5, atol=5e-5)


def test_glass_slab_transmits_by_fresnel(device):
    ior = 1.5
    r = ((ior - 1) / (ior + 1)) ** 2
    top, bottom = quad((0, 0, 1.0), 20.0), quad((0, 0, 0.9), 20.0, flip=True)
    emitter = quad((0, 0, 0.0), 200.0)
    scene = make_scene(np.concatenate([top, bottom, emitter]), [0, 0, 0, 0, 1, 1],
                       Materials.make([dict(base_color=(1, 1, 1), transmission=1.0, roughness=0.0, ior=ior),
                                       dict(base_color=(0, 0, 0), emission=(1.0, 1.0, 1.0))]),
                       Lights.make([]), camera_looking_down(HEIGHT, 0.2, SIZE))
    img = render(device, scene, samples=64).passes["Combined"]
    expected = (1 - r) ** 2 / (1 - r * r)  # two transmissions plus the internal reflections
    assert abs(img[..., 0].mean() / expected - 1) < 0.01
    assert img[..., 0].max() <= 1.0 + 1e-6


def test_occluder_casts_a_black_shadow(device):
    blocker = quad((0, 0, 1.0), 0.6, flip=True)  # black, so seeing it or its shadow both give 0
    scene = plane_scene(Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(100,) * 3)]),
                        camera_looking_down(HEIGHT, HALF, SIZE), extra_tris=[blocker],
                        extra_materials=[dict(base_color=(0.0, 0.0, 0.0))])
    img = render(device, scene).passes["Combined"][..., 0]
    x, y = pixel_points()
    reach = np.maximum(abs(x), abs(y))
    pixel = 2 * HALF / SIZE
    # the shadow of the blocker on z = 0 is the square |x|, |y| < 0.6
    assert np.all(img[reach < 0.6 - pixel] == 0.0)
    assert np.all(img[reach > 0.6 + pixel] > 0.0)


def test_depth_and_normal_passes(device):
    scene = plane_scene(Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 2.0), power=(10,) * 3)]),
                        camera_looking_down(HEIGHT, HALF, SIZE))
    res = render(device, scene, samples=1)
    np.testing.assert_allclose(res.passes["Depth"][..., 0], HEIGHT, rtol=1e-5)
    np.testing.assert_allclose(res.passes["Normal"].reshape(-1, 3), np.tile([0, 0, 1.0], (SIZE * SIZE, 1)), atol=1e-6)


def test_background_depth_and_transparent_film(device):
    scene = plane_scene(Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE), world=(0.2, 0.2, 0.2), plane_size=1.0)
    res = render(device, scene, samples=4, transparent_background=True)
    corner = res.passes["Combined"][0, 0]
    assert corner[3] == 0.0 and res.passes["Depth"][0, 0, 0] == pytest.approx(1e10)
    assert res.passes["Combined"][SIZE // 2, SIZE // 2, 3] == 1.0


def test_render_border_renders_exactly_the_window_pixels(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 1.0), power=(30,) * 3)])
    full = render(device, plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE))).passes["Combined"]
    cam = camera_looking_down(HEIGHT, HALF, SIZE)
    cam.border = (5, 9, 21, 30)
    part = render(device, plane_scene(lights, cam)).passes["Combined"]
    assert part.shape == (21, 16, 4)
    np.testing.assert_array_equal(part, full[9:30, 5:21])


def test_image_texture_multiplies_the_base_colour(device):
    scene = plane_scene(Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE), world=(1.0, 1.0, 1.0))
    scene.materials.texture_id[0] = 0
    scene.textures = [np.array([[[0.2, 0.5, 0.9, 1.0]]], np.float32)]
    res = render(device, scene, samples=2)
    np.testing.assert_allclose(res.passes["Combined"][..., :3].reshape(-1, 3),
                               np.tile(ALBEDO * np.array([0.2, 0.5, 0.9]), (SIZE * SIZE, 1)), rtol=1e-4)
    assert "textures" in res.stats["plan"]


def test_fully_transparent_surface_is_passed_through(device):
    cover = quad((0, 0, 1.0), 20.0)
    scene = plane_scene(Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE), world=(1.0, 1.0, 1.0),
                        extra_tris=[cover], extra_materials=[dict(base_color=(1, 0, 0), alpha=0.0)])
    img = render(device, scene, samples=2).passes["Combined"]
    np.testing.assert_allclose(img[..., :3], ALBEDO, rtol=1e-4)
