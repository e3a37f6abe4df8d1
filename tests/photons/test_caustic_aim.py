"""Caustic photons aimed at the surfaces that can bounce them specularly
(photons/aim.py): which material rows count, the boxes around their
triangles, and a caustic map that is the same whether or not the photons
that meet none of the boxes are traced."""

import numpy as np
from scenes_py import make_scene, plane_scene, quad, sphere

from gpu_core.photons import trace_photon_maps
from gpu_core.photons.aim import MAX_BOXES, caustic_boxes, device_boxes, specular_rows
from gpu_core.scene import LIGHT_AREA, LIGHT_POINT, LIGHT_SUN, Lights, Materials
from gpu_core.scene.tables import material_table

MIRROR = dict(base_color=(0.9,) * 3, metallic=1.0, roughness=0.0)


def rows_of(materials: list[dict], textures=()) -> np.ndarray:
    """specular_rows of a one-quad scene per material."""
    tris = np.concatenate([quad((3.0 * i, 0, 0), 1.0) for i in range(len(materials))])
    ids = np.repeat(np.arange(len(materials), dtype=np.int32), 2)
    scene = make_scene(tris, ids, Materials.make(materials), Lights.make([]), plane_scene(Lights.make([])).camera)
    scene.textures = list(textures)
    return specular_rows(material_table(scene), scene)


def test_rows_that_can_bounce_light_specularly_are_smooth_metal_glass_or_a_specular_layer():
    ramp = np.zeros((2, 2, 4), np.float32)
    ramp[..., :3] = np.array([[0.05, 0.6], [0.7, 0.9]])[..., None]  # roughness down to 0.05: smooth somewhere
    rough_ramp = ramp.copy()
    rough_ramp[..., :3] = 0.4
    materials = [
        dict(),  # diffuse, no specular layer
        MIRROR,
        dict(metallic=1.0, roughness=0.3),  # rough metal: glossy, not specular
        dict(transmission=1.0, roughness=0.05),  # glass
        dict(specular_ior_level=0.5, roughness=0.05),  # glossy plastic: its layer is near-specular
        dict(specular_ior_level=0.5, roughness=0.5),  # rough plastic
        dict(metallic=1.0, roughness=0.5, roughness_texture=0),  # metal smooth where the texture says
        dict(metallic=1.0, roughness=0.5, roughness_texture=1),  # metal rough everywhere
        dict(mix_next=9, mix_stop=0.5, mix_scale=2.0),  # a diffuse row mixed with a mirror row
        dict(MIRROR, mix_scale=2.0),
        dict(roughness=0.0),  # smooth but no lobe to bounce from: Lambertian only
    ]
    expected = [False, True, False, True, True, False, True, False, True, True, False]
    assert rows_of(materials, [ramp, rough_ramp]).tolist() == expected


def test_boxes_hold_every_specular_triangle_and_no_other_material():
    mirror, glass = quad((2.0, 1.0, 0.5), 0.4), sphere((-1.0, 0.0, 1.0), 0.3)
    scene = plane_scene(Lights.make([]), plane_size=10.0, extra_tris=[mirror, glass],
                        extra_materials=[MIRROR, dict(transmission=1.0, roughness=0.0)])
    boxes = caustic_boxes(scene, material_table(scene))
    assert len(boxes) == 2  # one per specular material; the diffuse plane has none
    for tris in (mirror, glass):
        inside = [np.all((tris.min(axis=(0, 1)) >= b[0]) & (tris.max(axis=(0, 1)) <= b[1])) for b in boxes]
        assert sum(inside) == 1
    assert not any(np.all(b[0] <= -4.0) for b in boxes)  # the plane spans -5..5


def test_many_specular_materials_merge_into_few_boxes_that_still_hold_them_all():
    rng = np.random.default_rng(4)
    centres = rng.uniform(-20, 20, (150, 3))
    groups = [quad(c, 0.5) for c in centres]
    scene = plane_scene(Lights.make([]), extra_tris=groups,
                        extra_materials=[dict(MIRROR, base_color=(0.5 + i / 400,) * 3) for i in range(150)])
    boxes = caustic_boxes(scene, material_table(scene))
    assert 1 <= len(boxes) <= MAX_BOXES
    corners = np.concatenate(groups).reshape(-1, 3)
    held = np.zeros(len(corners), bool)
    for b in boxes:
        held |= np.all((corners >= b[0]) & (corners <= b[1]), axis=1)
    assert held.all()


def test_device_boxes_are_float32_and_grow_outwards_far_from_the_origin():
    boxes = np.array([[[1e6 + 0.25, -3.0, 2.0], [1e6 + 0.75, -2.0, 2.0]]])  # flat in z
    center = np.array([1e6, 0.0, 0.0])
    out = device_boxes(boxes, center)
    assert out.dtype == np.float32 and out.shape == (2, 4)
    local = boxes[0] - center
    assert np.all(out[0, :3] < local[0]) and np.all(out[1, :3] > local[1])
    assert np.all(out[1, :3] - out[0, :3] < 0.01 + (local[1] - local[0]))


def aim_scene():
    """A closed room lit by an area light, a point light and the sun through
    an open top: a mirror, a glass sphere, a glossy plastic quad, a mix of
    diffuse and mirror, and a half-transparent diffuse sheet over the mirror."""
    size, h = 4.0, 2.0
    walls = np.concatenate([quad((0, 0, -h), size), quad((0, -h, 0), size, normal_axis=1),
                            quad((0, h, 0), size, normal_axis=1, flip=True), quad((-h, 0, 0), size, normal_axis=0),
                            quad((h, 0, 0), size, normal_axis=0, flip=True)])
    parts = [walls, quad((1.0, 1.0, -1.9), 0.8), sphere((-0.8, -0.5, -1.2), 0.5, rings=8, segments=12),
             quad((-1.0, 1.2, -1.95), 0.6), quad((1.0, -1.0, -1.9), 0.6), quad((1.0, 1.0, -1.6), 0.8)]
    materials = [dict(), MIRROR, dict(transmission=1.0, ior=1.45, roughness=0.0),
                 dict(specular_ior_level=0.5, roughness=0.02), dict(mix_next=5, mix_stop=0.4, mix_scale=1 / 0.4),
                 dict(MIRROR, mix_scale=1 / 0.6), dict(alpha=0.5)]
    ids = np.concatenate([np.full(len(p), m, np.int32) for p, m in zip(parts, (0, 1, 2, 3, 4, 6))])
    lights = Lights.make([dict(kind=LIGHT_AREA, position=(0, 0, 1.9), power=(80, 80, 80), axis_u=(0.6, 0, 0),
                               axis_v=(0, 0.6, 0)),
                          dict(kind=LIGHT_POINT, position=(0.5, -0.5, 0.5), power=(30, 20, 10)),
                          dict(kind=LIGHT_SUN, direction=(0.2, 0.1, -1), power=(1, 1, 1))])
    return make_scene(np.concatenate(parts), ids, Materials.make(materials), lights,
                      plane_scene(lights).camera)


def test_aimed_caustic_photons_leave_the_same_caustic_map_for_fewer_traced(device):
    scene = aim_scene()
    aimed = trace_photon_maps(device, scene, global_photons=2000, caustic_photons=40000, seed=5)
    every = trace_photon_maps(device, scene, global_photons=2000, caustic_photons=40000, seed=5, aimed=False)
    assert aimed.stats["aim_boxes"] == 4 and "aim_boxes" not in every.stats
    assert every.stats["traced"]["caustic"] == every.stats["emitted"]["caustic"] == 40000
    assert 0 < aimed.stats["traced"]["caustic"] < 0.8 * 40000
    assert aimed.stats["traced"]["global"] == 2000
    assert aimed.stats["stored"]["caustic"] == every.stats["stored"]["caustic"] > 500
    a, b = aimed.caustic_map.photons(), every.caustic_map.photons()
    for name in ("direction", "power", "normal"):
        np.testing.assert_array_equal(a[name], b[name])
    np.testing.assert_array_equal(aimed.caustic_map.positions(), every.caustic_map.positions())
