"""The light table's pick CDF: shadow rays pick lights in proportion to the power they emit."""

import numpy as np
from scenes_py import make_scene, quad, camera_looking_down

from gpu_core.scene import LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Lights, Materials, validate
from gpu_core.scene.tables import scene_tables, spot_power


def _tables(lights, emission=None):
    floor = quad((0, 0, 0), 4.0)
    tris, ids, rows = [floor], [0, 0], [{"base_color": (0.8, 0.8, 0.8)}]
    if emission is not None:  # a 1 x 1 emissive square over the floor
        tris.append(quad((0, 0, 1.5), 1.0, flip=True))
        ids += [1, 1]
        rows.append({"emission": emission})
    scene = make_scene(np.concatenate(tris), np.array(ids, np.int32), Materials.make(rows), Lights.make(lights),
                       camera_looking_down())
    return scene_tables(validate(scene))


def test_the_pick_cdf_follows_the_power_each_light_emits():
    spot = dict(kind=LIGHT_SPOT, position=(0, 0, 2), power=(40.0,) * 3, direction=(0, 0, -1),
                spot_angle=np.radians(60), spot_blend=0.3)
    tables = _tables([dict(kind=LIGHT_POINT, position=(1, 0, 2), power=(10.0, 20.0, 30.0)), spot,
                      dict(kind=LIGHT_SUN, power=(2.0,) * 3, direction=(0, 0, -1))], emission=(5.0, 5.0, 5.0))
    rows = tables.lights
    emitted = np.array([
        60.0,
        spot_power(np.full(3, 40.0), float(rows["cos_half"][1]), float(rows["spot_smooth"][1])).sum(),
        3 * 2.0 * np.pi * tables.radius**2,
        3 * 5.0 * 2.0 * np.pi * 1.0,  # both faces of a 1 m^2 emitter of radiance 5
    ])
    np.testing.assert_allclose(rows["pick"], np.cumsum(emitted) / emitted.sum(), rtol=1e-5)
    assert rows["pick"][-1] == 1.0


def test_lights_without_power_have_no_chance_of_being_picked():
    tables = _tables([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(0.0,) * 3),
                      dict(kind=LIGHT_POINT, position=(1, 0, 2), power=(5.0,) * 3),
                      dict(kind=LIGHT_POINT, position=(2, 0, 2), power=(0.0,) * 3)])
    np.testing.assert_array_equal(np.diff(np.concatenate([[0.0], tables.lights["pick"]])), [0.0, 1.0, 0.0])


def test_no_light_with_power_leaves_the_pick_at_zero():
    tables = _tables([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(0.0,) * 3)])
    assert np.all(tables.lights["pick"] == 0.0)


def test_a_light_of_enormous_power_among_others_keeps_the_pick_finite():
    tables = _tables([dict(kind=LIGHT_POINT, position=(0, 0, 2), power=(1e38,) * 3),
                      dict(kind=LIGHT_POINT, position=(1, 0, 2), power=(1e38,) * 3),
                      dict(kind=LIGHT_POINT, position=(2, 0, 2), power=(1.0,) * 3)])
    pick = tables.lights["pick"]
    assert np.all(np.isfinite(pick)) and pick[-1] == 1.0
    np.testing.assert_allclose(pick[:2], [0.5, 1.0], atol=1e-6)
