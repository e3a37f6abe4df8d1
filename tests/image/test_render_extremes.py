"""Numbers stay finite and images stay right at the extremes of scale, power and input."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, plane_scene, quad

from gpu_core.errors import RenderCancelled
from gpu_core.renderer import Renderer
from gpu_core.scene import AREA_ELLIPSE, LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Lights, Materials
from gpu_core.settings import RenderSettings

SIZE = 32


def _scene(scale=1.0, offset=(0.0, 0.0, 0.0), power=100.0):
    """A plane, a floating occluder and a point light, scaled and moved as a whole."""
    off = np.asarray(offset, np.float64)
    blocker = quad((0.4, 0.0, 1.0), 0.5, flip=True) * scale + off
    lights = Lights.make([dict(kind=LIGHT_POINT, position=np.array([0.0, 0.0, 2.0]) * scale + off,
                               power=(power * scale**2,) * 3)])
    cam = camera_looking_down(4.0 * scale, 2.0 * scale, SIZE)
    cam.matrix[:3, 3] += off
    cam.clip_start, cam.clip_end = 1e-3 * scale, 100.0 * scale
    tris = quad((0, 0, 0), 40.0) * scale + off
    return make_scene(np.concatenate([tris, blocker]), [0, 0, 1, 1],
                      Materials.make([dict(base_color=(0.8, 0.8, 0.8)), dict(base_color=(0.3, 0.6, 0.3))]), lights, cam)


def _render(device, scene, **kw):
    return Renderer(device).render(scene, RenderSettings(samples=8, **kw))


@pytest.fixture(scope="module")
def unit_image(device):
    return _render(device, _scene()).passes["Combined"]


@pytest.mark.parametrize("scale, offset", [(1e-4, (0, 0, 0)), (1e-3, (0, 0, 0)), (1e4, (0, 0, 0)), (1e5, (0, 0, 0)),
                                           (1.0, (1e5, -1e5, 1e5)), (1e-3, (50.0, 0, 0))])
def test_scaled_and_distant_scenes_render_like_the_unit_scene(device, unit_image, scale, offset):
    img = _render(device, _scene(scale, offset)).passes["Combined"]
    assert np.isfinite(img).all()
    diff = np.abs(img[..., :3] - unit_image[..., :3])
    # pixels straddling the shadow edge may flip; everything else agrees closely
    assert np.mean(diff < 0.02 * unit_image[..., :3].max()) > 0.97
    assert abs(img[..., :3].mean() / unit_image[..., :3].mean() - 1) < 0.02


@pytest.mark.parametrize("power", [1e8, 1e-6])
def test_blinding_and_dim_lights_stay_finite_and_proportional(device, unit_image, power):
    img = _render(device, _scene(power=power)).passes["Combined"]
    assert np.isfinite(img).all()
    np.testing.assert_allclose(img[..., :3], unit_image[..., :3] * (power / 100.0), rtol=1e-3, atol=1e-30)


def test_no_lights_gives_a_black_finite_image(device):
    scene = plane_scene(Lights.make([]), camera_looking_down(size=SIZE))
    res = _render(device, scene)
    assert np.all(res.passes["Combined"][..., :3] == 0.0)
    assert np.isfinite(res.passes["Depth"]).all()


def test_zero_triangles_show_only_the_world(device):
    scene = make_scene(np.zeros((0, 3, 3)), [], Materials.make([]), Lights.make([dict(kind=LIGHT_POINT, power=(5,) * 3)]),
                       camera_looking_down(size=SIZE), world=(0.1, 0.2, 0.3))
    img = _render(device, scene).passes["Combined"]
    np.testing.assert_allclose(img[..., :3].reshape(-1, 3), np.tile([0.1, 0.2, 0.3], (SIZE * SIZE, 1)), rtol=1e-6)


@pytest.mark.parametrize("albedo", [0.0, 1.0])
def test_albedo_zero_and_one(device, albedo):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(50,) * 3)])
    img = _render(device, plane_scene(lights, camera_looking_down(size=SIZE), albedo=albedo)).passes["Combined"]
    assert np.isfinite(img).all()
    assert (img[..., :3].max() == 0.0) == (albedo == 0.0)


def test_degenerate_geometry_and_lights_render_finite(device):
    sliver = np.array([[[0, 0, 1], [1, 0, 1], [2, 0, 1]], [[0, 0, 1], [0, 0, 1], [0, 0, 1]]], np.float64)
    lights = Lights.make([
        dict(kind=LIGHT_POINT, position=(0, 0, 0.0), power=(10,) * 3),  # on the plane itself
        dict(kind=LIGHT_AREA, position=(0, 0, 1.0), power=(10,) * 3, axis_u=(0, 0, 0), axis_v=(0, 0, 0)),
    ])
    scene = plane_scene(lights, camera_looking_down(size=SIZE), extra_tris=[sliver], extra_materials=[{}])
    res = _render(device, scene)
    assert np.isfinite(res.passes["Combined"]).all()
    assert res.stats["dropped_degenerate_triangles"] == 2


@pytest.mark.parametrize("light", [
    dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(1e8,) * 3, radius=1e-30),  # radiance beyond float32
    dict(kind=LIGHT_POINT, position=(0, 0, 0.5), power=(10,) * 3, radius=1e6),  # the scene inside the light
    dict(kind=LIGHT_SPOT, position=(0, 0, 1.0), power=(10,) * 3, spot_angle=0.0, spot_blend=0.0),
    dict(kind=LIGHT_SPOT, position=(0, 0, 1.0), power=(10,) * 3, spot_angle=np.pi, spot_blend=1.0, radius=0.2),
    dict(kind=LIGHT_SUN, direction=(0, 0, -1), power=(5,) * 3, sun_angle=np.pi),
    dict(kind=LIGHT_SUN, direction=(0, 0, 0), power=(5,) * 3, sun_angle=1e-30),  # no direction
    dict(kind=LIGHT_AREA, position=(0, 0, 1.0), power=(1e8,) * 3, axis_u=(1e-20, 0, 0), axis_v=(0, 1e-20, 0)),
    dict(kind=LIGHT_AREA, position=(0, 0, 1e-9), power=(10,) * 3, axis_u=(1e6, 0, 0), axis_v=(0, 1e6, 0),
         shape=AREA_ELLIPSE),
    dict(kind=LIGHT_AREA, position=(0, 0, 1.0), power=(10,) * 3, axis_u=(1, 0, 0), axis_v=(2, 0, 0)),  # flat
])
def test_extreme_light_parameters_render_finite(device, light):
    scene = plane_scene(Lights.make([light]), camera_looking_down(size=SIZE))
    res = _render(device, scene)
    assert np.isfinite(res.passes["Combined"]).all()
    assert (res.passes["Combined"][..., :3] >= 0).all()


def test_cancel_stops_after_the_first_batch(device):
    scene = plane_scene(Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 1.0), power=(50,) * 3)]),
                        camera_looking_down(size=96))
    calls = []

    def progress(fraction, message):
        calls.append(fraction)

    with pytest.raises(RenderCancelled):
        Renderer(device).render(scene, RenderSettings(samples=64, batch_pixels=256), progress=progress,
                                should_stop=lambda: len(calls) >= 1)
    assert len(calls) == 1 and calls[0] < 0.1
