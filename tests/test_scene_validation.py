"""gpu_core.scene.validate: every bad input is dropped or repaired, counted and described."""

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.errors import SceneError
from gpu_core.scene import LIGHT_POINT, Camera, Lights, Materials, validate


def _scene(tris, ids=None, lights=None, materials=None, camera=None):
    tris = np.asarray(tris, np.float64)
    ids = np.zeros(len(tris), np.int32) if ids is None else np.asarray(ids, np.int32)
    return make_scene(tris, ids, materials or Materials.make([{}]), lights or Lights.make([]), camera or camera_looking_down())


def test_nonfinite_triangles_are_dropped_and_counted():
    tris = quad((0, 0, 0), 1.0)
    bad = tris[:1].copy()
    bad[0, 1, 2] = np.nan
    inf = tris[:1].copy()
    inf[0, 0, 0] = np.inf
    out = validate(_scene(np.concatenate([tris, bad, inf])))
    assert out.triangle_count == 2
    assert out.report.dropped_nonfinite_triangles == 2
    assert any("NaN/Inf" in w for w in out.warnings)


def test_zero_area_triangles_are_dropped_but_tiny_far_triangles_kept():
    collinear = [[[0, 0, 0], [1, 1, 1], [2, 2, 2]]]
    repeated = [[[0, 0, 0], [0, 0, 0], [1, 0, 0]]]
    tiny_far = quad((1e5, 1e5, 0), 1e-4)
    out = validate(_scene(np.concatenate([collinear, repeated, tiny_far])))
    assert out.report.dropped_degenerate_triangles == 2
    assert out.triangle_count == 2
    np.testing.assert_allclose(out.triangles, tiny_far)


def test_out_of_range_material_ids_use_an_added_default_material():
    tris = np.concatenate([quad((0, 0, 0), 1.0), quad((2, 0, 0), 1.0)])
    out = validate(_scene(tris, ids=[0, 5, -1, 0]))
    assert out.report.repaired_material_ids == 2
    assert len(out.materials) == 2
    assert list(out.material_ids) == [0, 1, 1, 0]
    assert out.materials.names[-1] == "gpugi-default"


def test_invalid_normals_are_replaced_by_face_normals():
    scene = _scene(quad((0, 0, 0), 1.0))
    scene.normals[0, 0] = (0, 0, 0)
    scene.normals[1, 2] = (np.nan, 0, 1)
    out = validate(scene)
    assert out.report.repaired_normals == 2
    np.testing.assert_allclose(out.normals[0, 0], (0, 0, 1), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(out.normals, axis=2), 1.0, atol=1e-6)


def test_lights_with_negative_or_nan_power_are_dropped_with_a_warning():
    lights = Lights.make([
        dict(kind=LIGHT_POINT, power=(10, 10, 10), name="good"),
        dict(kind=LIGHT_POINT, power=(-1, 0, 0), name="negative"),
        dict(kind=LIGHT_POINT, power=(np.nan, 1, 1), name="nan"),
        dict(kind=LIGHT_POINT, position=(np.inf, 0, 0), power=(1, 1, 1), name="far"),
    ])
    out = validate(_scene(quad((0, 0, 0), 1.0), lights=lights))
    assert out.report.dropped_lights == 3
    assert out.lights.names == ["good"]
    assert any("negative" in w and "nan" in w for w in out.warnings)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(matrix=np.zeros((4, 4))), "singular"),
        (dict(window=(1.0, 1.0, 0.0, 1.0)), "window"),
        (dict(border=(0, 0, 100, 10)), "border"),
        (dict(width=0), "empty"),
        (dict(clip_start=5.0, clip_end=1.0), "clipping"),
    ],
)
def test_unusable_camera_raises_a_scene_error(change, message):
    cam = camera_looking_down(size=32)
    fields = dict(matrix=cam.matrix, window=cam.window, width=cam.width, height=cam.height,
                  kind=cam.kind, clip_start=cam.clip_start, clip_end=cam.clip_end, border=None)
    fields.update(change)
    with pytest.raises(SceneError, match=message):
        validate(_scene(quad((0, 0, 0), 1.0), camera=Camera(**fields)))


def test_validate_leaves_the_input_arrays_unchanged():
    tris = np.concatenate([quad((0, 0, 0), 1.0), [[[0, 0, 0], [0, 0, 0], [1, 0, 0]]]])
    scene = _scene(tris, ids=[0, 0, 7])
    scene.normals[0, 0] = 0.0
    before = [a.copy() for a in (scene.triangles, scene.normals, scene.material_ids)]
    validate(scene)
    for old, new in zip(before, (scene.triangles, scene.normals, scene.material_ids)):
        np.testing.assert_array_equal(old, new)
