"""Light sampling and lights seen by rays, against numerically integrated oracles.

The oracles integrate Cycles' light models (kernels/lights.h header comment)
over the light's surface with a midpoint rule and average over each pixel's
footprint, so per-pixel comparisons are not blurred by anti-aliasing.
"""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import AREA_ELLIPSE, AREA_RECTANGLE, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Lights, Materials
from gpu_core.settings import RenderSettings

SIZE = 24
HEIGHT = 4.0
HALF = 2.0
ALBEDO = 0.8


def render(device, scene, samples=16, **kw):
    return Renderer(device).render(scene, RenderSettings(samples=samples, **kw)).passes["Combined"]


def footprint_average(f, sub=4):
    """f(x, y) on the plane z = 0 averaged over each pixel of camera_looking_down(HEIGHT, HALF, SIZE)."""
    pixel = 2 * HALF / SIZE
    offsets = ((np.arange(sub) + 0.5) / sub - 0.5) * pixel
    c = ((np.arange(SIZE) + 0.5) / SIZE * 2 - 1) * HALF
    x, y = np.meshgrid(c, c)
    return np.mean([f(x + dx, y + dy) for dx in offsets for dy in offsets], axis=0)


def blocks(img, k=4):
    """Means over k x k pixel blocks: noise drops k times, structure stays."""
    h, w = img.shape[:2]
    return img[: h - h % k, : w - w % k].reshape(h // k, k, w // k, k).mean(axis=(1, 3))


def plane_radiance(points_fn, radiance_fn, n=64):
    """Radiance ALBEDO/pi * E of the plane, E integrated over light points.

    points_fn() -> (points (K, 3), area per point); radiance_fn(points, x) ->
    radiance of each light point towards each plane point x (..., K).
    """
    pts, d_area = points_fn(n)

    def radiance(x, y):
        p = np.stack([x, y, np.zeros_like(x)], -1)[..., None, :]
        d = pts - p
        d2 = (d**2).sum(-1)
        w = d / np.sqrt(d2)[..., None]
        cos_x = np.maximum(w[..., 2], 0.0)
        return ALBEDO / np.pi * (radiance_fn(pts, w) * cos_x / d2 * d_area).sum(-1)

    return footprint_average(radiance, sub=3)


def area_light_points(center, u, v, ellipse):
    def points(n):
        a = (np.arange(n) + 0.5) / n - 0.5
        s, t = [g.ravel() for g in np.meshgrid(a, a)]
        if ellipse:
            keep = s**2 + t**2 <= 0.25
            s, t = s[keep], t[keep]
        area = np.linalg.norm(np.cross(u, v)) * (np.pi / 4 if ellipse else 1.0)
        pts = np.asarray(center) + s[:, None] * np.asarray(u) + t[:, None] * np.asarray(v)
        return pts, area / len(s)

    return points


@pytest.mark.parametrize("shape", [AREA_RECTANGLE, AREA_ELLIPSE])
def test_large_close_area_light_matches_integrated_radiance_power_over_pi_area(device, shape):
    center, u, v, power = (0.3, -0.2, 0.5), (1.2, 0.0, 0.0), (0.0, 0.8, 0.0), 30.0
    area = 1.2 * 0.8 * (np.pi / 4 if shape == AREA_ELLIPSE else 1.0)
    scene = plane_scene(Lights.make([dict(kind=LIGHT_AREA, position=center, power=(power,) * 3, direction=(0, 0, -1),
                                          axis_u=u, axis_v=v, shape=shape)]), camera_looking_down(HEIGHT, HALF, SIZE))
    # rectangles are sampled by solid angle, ellipses by area (noisier)
    img = render(device, scene, samples=64, light_samples=1 if shape == AREA_RECTANGLE else 4)[..., 0]
    # one-sided emitter facing -Z: cos_y is the downward component of the direction
    expected = plane_radiance(area_light_points(center, u, v, shape == AREA_ELLIPSE),
                              lambda pts, w: power / (np.pi * area) * np.maximum(w[..., 2], 0.0))
    assert abs(img.mean() / expected.mean() - 1) < 0.01
    np.testing.assert_allclose(blocks(img), blocks(expected), rtol=0.03 if shape == AREA_RECTANGLE else 0.05)


def test_area_light_lights_only_its_front_and_the_camera_does_not_see_it(device):
    up_facing = Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, 0.5), power=(30,) * 3, direction=(0, 0, 1),
                                  axis_u=(1, 0, 0), axis_v=(0, 1, 0))])
    img = render(device, plane_scene(up_facing, camera_looking_down(HEIGHT, HALF, SIZE)), samples=4)
    # the plane lies behind the light, and lights are hidden from camera rays (Cycles' default)
    assert np.all(img[..., :3] == 0.0)


def pixel_radius():
    """Distance from the image centre, on the plane z = 0, of each pixel centre."""
    c = ((np.arange(SIZE) + 0.5) / SIZE * 2 - 1) * HALF
    x, y = np.meshgrid(c, c)
    return np.hypot(x, y), np.maximum(abs(x), abs(y))


def mirror_scene(lights, world=(0, 0, 0), tint=(0.9, 0.6, 0.3)):
    """A tinted perfect mirror on z = 0 under camera_looking_down."""
    return make_scene(quad((0, 0, 0), 40.0), [0, 0], Materials.make([dict(base_color=tint, metallic=1.0, roughness=0.0)]),
                      lights, camera_looking_down(HEIGHT, HALF, SIZE), world=world)


@pytest.mark.parametrize("facing", [-1.0, 1.0])
def test_mirror_shows_the_emitting_face_of_an_area_light_with_radiance_power_over_pi_area(device, facing):
    tint = np.array([0.9, 0.6, 0.3])
    panel = Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, 1.0), power=(30,) * 3, direction=(0, 0, facing),
                              axis_u=(2, 0, 0), axis_v=(0, 2, 0))])
    img = render(device, mirror_scene(panel, tint=tuple(tint)), samples=4)[..., :3]
    _, square = pixel_radius()
    reach = square * (HEIGHT + 1.0) / HEIGHT  # where the reflected ray crosses z = 1
    pixel = 2 * HALF / SIZE * (HEIGHT + 1.0) / HEIGHT
    inside, outside = img[reach < 1.0 - pixel], img[reach > 1.0 + pixel]
    assert len(inside) >= 16 and len(outside) >= 16
    expected = tint * 30.0 / (4 * np.pi) if facing < 0 else 0.0 * tint  # seen from below only when it shines down
    np.testing.assert_allclose(inside, np.broadcast_to(expected, inside.shape), rtol=1e-5)
    assert np.all(outside == 0.0)


def test_soft_point_light_is_a_disk_facing_each_receiver(device):
    center, radius, power = np.array([0.2, 0.1, 0.6]), 0.45, 80.0

    def radiance(x, y):
        # Cycles' soft-falloff point light: disk of radius r centred on the
        # light, facing the receiver, radiance P / (4 pi^2 r^2)
        p = np.stack([x, y, np.zeros_like(x)], -1)
        axis = p - center
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        t1 = np.cross(axis, [1.0, 0.0, 0.0])
        t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
        t2 = np.cross(axis, t1)
        n = 48
        a = (np.arange(n) + 0.5) / n * 2 - 1
        s, t = [g.ravel() for g in np.meshgrid(a, a)]
        keep = s**2 + t**2 <= 1.0
        s, t = s[keep] * radius, t[keep] * radius
        pts = center + s[:, None] * t1[..., None, :] + t[:, None] * t2[..., None, :]
        d = pts - p[..., None, :]
        d2 = (d**2).sum(-1)
        w = d / np.sqrt(d2)[..., None]
        cos_x = np.maximum(w[..., 2], 0.0)
        cos_disk = np.maximum(-(w * axis[..., None, :]).sum(-1), 0.0)
        d_area = np.pi * radius**2 / len(s)
        return ALBEDO / np.pi * (power / (4 * np.pi**2 * radius**2) * cos_disk * cos_x / d2 * d_area).sum(-1)

    lights = Lights.make([dict(kind=LIGHT_POINT, position=center, power=(power,) * 3, radius=radius)])
    img = render(device, plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE)), samples=32, light_samples=2)[..., 0]
    expected = footprint_average(radiance, sub=2)
    assert abs(img.mean() / expected.mean() - 1) < 0.01
    np.testing.assert_allclose(blocks(img), blocks(expected), rtol=0.03)


def test_spot_blend_follows_cycles_smoothstep_without_a_cosine_term(device):
    pos, power, angle, blend = np.array([0.0, 0.0, 1.5]), 100.0, np.radians(70), 0.6
    scene = plane_scene(Lights.make([dict(kind=LIGHT_SPOT, position=pos, power=(power,) * 3, direction=(0, 0, -1),
                                          spot_angle=angle, spot_blend=blend)]), camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene, samples=64)[..., 0]
    cos_half = np.cos(angle / 2)

    def radiance(x, y):
        d2 = x**2 + y**2 + pos[2] ** 2
        cos = pos[2] / np.sqrt(d2)  # both the receiver cosine and the cosine to the spot axis
        s = np.clip((cos - cos_half) / ((1 - cos_half) * blend), 0.0, 1.0)
        return ALBEDO / np.pi * power / (4 * np.pi * d2) * cos * s * s * (3 - 2 * s)

    expected = footprint_average(radiance, sub=8)
    # pixels on the steep blend edge converge slowest: a loose per-pixel check, a tight one per block
    np.testing.assert_allclose(img, expected, rtol=0.1, atol=2e-3 * expected.max())
    np.testing.assert_allclose(blocks(img), blocks(expected), rtol=0.01, atol=1e-3 * expected.max())
    assert np.all(img[expected == 0.0] == 0.0)


def test_wide_sun_gives_its_strength_at_normal_incidence(device):
    strength = 2.5
    scene = plane_scene(Lights.make([dict(kind=LIGHT_SUN, direction=(0, 0, -1), power=(strength,) * 3,
                                          sun_angle=np.radians(60))]), camera_looking_down(HEIGHT, HALF, SIZE))
    img = render(device, scene, samples=16)[..., 0]
    # Cycles normalises the sun disk so that it delivers S on a surface facing it
    np.testing.assert_allclose(img.mean(), ALBEDO / np.pi * strength, rtol=0.005)


def test_sun_disk_is_seen_in_a_mirror_with_radiance_strength_over_pi_sin2(device):
    strength, angle, tint = 3.0, np.radians(20), np.array([0.9, 0.6, 0.3])
    scene = make_scene(quad((0, 0, 0), 40.0), [0, 0], Materials.make([dict(base_color=tuple(tint), metallic=1.0, roughness=0.0)]),
                       Lights.make([dict(kind=LIGHT_SUN, direction=(0, 0, -1), power=(strength,) * 3, sun_angle=angle)]),
                       camera_looking_down(HEIGHT, HALF, SIZE), world=(0.01, 0.01, 0.01))
    img = render(device, scene, samples=4)[..., :3]
    c = ((np.arange(SIZE) + 0.5) / SIZE * 2 - 1) * HALF
    x, y = np.meshgrid(c, c)
    off_axis = np.arctan2(np.hypot(x, y), HEIGHT)  # angle of the reflected ray to the sun's direction
    sun_radiance = strength / (np.pi * np.sin(angle / 2) ** 2)
    pixel = np.arctan(2 * HALF / SIZE / HEIGHT)
    inside, outside = off_axis < angle / 2 - pixel, off_axis > angle / 2 + pixel
    assert inside.sum() >= 4
    # the mirror reflects by Schlick's Fresnel from its colour (Cycles' F82 tint at white), at the
    # pixel centre's angle (the samples spread over the pixel: some 1e-5 apart)
    fresnel = tint + (1 - tint) * ((1 - np.cos(off_axis)) ** 5)[..., None]
    np.testing.assert_allclose(img[inside], (fresnel * (sun_radiance + 0.01))[inside], rtol=5e-5)
    np.testing.assert_allclose(img[outside], (fresnel * 0.01)[outside], rtol=5e-5)


def test_mirror_shows_a_point_light_disk_with_radiance_power_over_4_pi2_r2(device):
    power, radius, tint = 50.0, 1.0, np.array([0.9, 0.6, 0.3])
    img = render(device, mirror_scene(Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(power,) * 3,
                                                        radius=radius)]), tint=tuple(tint)), samples=4)[..., :3]
    r, _ = pixel_radius()
    # the reflected ray from (x, y, 0) towards (x, y, HEIGHT) passes the disk (which faces the
    # mirror point) about 1.25 r from its centre; margins cover the tilt and the pixel size
    reach = r * (HEIGHT + 1.0) / HEIGHT
    pixel = 2 * HALF / SIZE * 1.5
    inside, outside = img[reach * 1.15 < radius - pixel], img[reach * 0.85 > radius + pixel]
    assert len(inside) >= 16 and len(outside) >= 16
    np.testing.assert_allclose(inside, np.broadcast_to(tint * power / (4 * np.pi**2 * radius**2), inside.shape), rtol=1e-5)
    assert np.all(outside == 0.0)


def test_lights_are_see_through_and_add_to_what_lies_behind(device):
    # a mirror sees a large area light shining down, and the world behind it
    panel = dict(kind=LIGHT_AREA, position=(0, 0, 1.0), power=(6.0,) * 3, direction=(0, 0, -1),
                 axis_u=(10, 0, 0), axis_v=(0, 10, 0))
    img = render(device, mirror_scene(Lights.make([panel]), world=(0.5, 0.5, 0.5), tint=(1, 1, 1)), samples=4)[..., 0]
    np.testing.assert_allclose(img, 6.0 / (np.pi * 100.0) + 0.5, rtol=1e-4)


def test_emissive_mesh_lights_like_an_area_light_of_the_same_power(device):
    size, height, radiance = 0.4, 1.0, 20.0
    emitter = quad((0, 0, height), size, flip=True)  # faces the plane; both faces emit
    mesh = plane_scene(Lights.make([]), camera_looking_down(HEIGHT, HALF, SIZE), extra_tris=[emitter],
                       extra_materials=[dict(base_color=(0, 0, 0), emission=(radiance,) * 3)])
    area = plane_scene(Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, height), power=(radiance * np.pi * size**2,) * 3,
                                         direction=(0, 0, -1), axis_u=(size, 0, 0), axis_v=(0, size, 0))]),
                       camera_looking_down(HEIGHT, HALF, SIZE))
    a = render(device, mesh, samples=32)[..., 0]
    b = render(device, area, samples=32)[..., 0]
    c = ((np.arange(SIZE) + 0.5) / SIZE * 2 - 1) * HALF
    x, y = np.meshgrid(c, c)
    covered = np.maximum(abs(x), abs(y)) * (HEIGHT - height) / HEIGHT < size / 2 + 2 * HALF / SIZE
    # the camera sees the mesh emitter itself where it covers the plane
    assert abs(a[~covered].mean() / b[~covered].mean() - 1) < 0.01
    ring = np.where(covered, b, a)  # the area light is invisible from above: its back faces the camera
    np.testing.assert_allclose(blocks(ring), blocks(b), rtol=0.03)
    inner = np.maximum(abs(x), abs(y)) * (HEIGHT - height) / HEIGHT < size / 2 - 2 * HALF / SIZE
    np.testing.assert_allclose(a[inner], radiance, rtol=1e-5)


def test_more_light_samples_lower_the_noise(device):
    center, u, v = (0.0, 0.0, 0.4), (0.0, 1.5, 0.0), (1.5, 0.0, 0.0)
    scene = plane_scene(Lights.make([dict(kind=LIGHT_AREA, position=center, power=(30,) * 3, direction=(0, 0, -1),
                                          axis_u=u, axis_v=v, shape=AREA_ELLIPSE)]), camera_looking_down(HEIGHT, HALF, SIZE))
    one = render(device, scene, samples=2, light_samples=1)[..., 0]
    eight = render(device, scene, samples=2, light_samples=8)[..., 0]
    reference = render(device, scene, samples=64, light_samples=8, seed=7)[..., 0]
    err_one = np.sqrt(np.mean((one - reference) ** 2))
    err_eight = np.sqrt(np.mean((eight - reference) ** 2))
    assert err_eight < 0.55 * err_one  # 1/sqrt(8) = 0.35 for independent samples


def hard_point_lights_radiance(positions, powers):
    """Plane radiance under hard point lights: ALBEDO/pi * sum P/(4 pi d^2) cos."""

    def radiance(x, y):
        total = np.zeros_like(x)
        for pos, power in zip(positions, powers):
            d = np.stack([pos[0] - x, pos[1] - y, np.full_like(x, pos[2])], -1)
            d2 = (d**2).sum(-1)
            total += power / (4 * np.pi * d2) * d[..., 2] / np.sqrt(d2)
        return ALBEDO / np.pi * total

    return footprint_average(radiance, sub=2)


def test_many_lights_picked_by_power_give_the_sum_of_their_light(device):
    # more lights than get a shadow ray each (IMAGE_ALL_LIGHTS): one light
    # per shadow ray, picked by power, must still add up to every light's
    rng = np.random.default_rng(3)
    positions = np.column_stack([rng.uniform(-2, 2, 12), rng.uniform(-2, 2, 12), rng.uniform(0.8, 2.0, 12)])
    powers = rng.uniform(5.0, 60.0, 12)
    lights = Lights.make([dict(kind=LIGHT_POINT, position=p, power=(w,) * 3) for p, w in zip(positions, powers)])
    img = render(device, plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE)), samples=256)[..., 0]
    expected = hard_point_lights_radiance(positions, powers)
    assert np.all(np.isfinite(img))
    assert abs(img.mean() / expected.mean() - 1) < 0.01
    np.testing.assert_allclose(blocks(img), blocks(expected), rtol=0.05)


def test_many_lights_of_which_some_emit_nothing_stay_finite_and_right(device):
    # lights without power are never picked; they must not divide by zero
    positions = [(x, y, 1.5) for x in (-1.0, 0.0, 1.0) for y in (-1.0, 1.0)] + [(0.0, 0.0, 1.0)]
    powers = [0.0, 40.0, 0.0, 0.0, 25.0, 0.0, 0.0]
    lights = Lights.make([dict(kind=LIGHT_POINT, position=p, power=(w,) * 3) for p, w in zip(positions, powers)])
    img = render(device, plane_scene(lights, camera_looking_down(HEIGHT, HALF, SIZE)), samples=128)[..., 0]
    expected = hard_point_lights_radiance(positions, powers)
    assert np.all(np.isfinite(img))
    assert abs(img.mean() / expected.mean() - 1) < 0.01
