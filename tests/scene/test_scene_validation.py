"""gpu_core.scene.validate: every bad input is dropped or repaired, counted and described."""

import dataclasses
import sys

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.errors import SceneError
from gpu_core.scene.validate import GeometryMemo
from gpu_core.scene import (
    AREA_RECTANGLE,
    CAMERA_ORTHO,
    LIGHT_AREA,
    LIGHT_POINT,
    LIGHT_SPOT,
    LIGHT_SUN,
    Camera,
    Lights,
    Materials,
    validate,
)

_MATERIAL_FIELDS = "base_color metallic roughness transmission ior emission alpha".split()
_LIGHT_FIELDS = "position direction axis_u axis_v power radius spot_angle spot_blend sun_angle".split()


def _scene(tris, ids=None, lights=None, materials=None, camera=None, world=(0, 0, 0)):
    """A scene of ``tris`` (face normals, zero UVs); NaN/Inf input is allowed."""
    tris = np.asarray(tris, np.float64)
    ids = np.zeros(len(tris), np.int32) if ids is None else np.asarray(ids, np.int32)
    with np.errstate(invalid="ignore", over="ignore"):
        return make_scene(tris, ids, materials or Materials.make([{}]), lights or Lights.make([]),
                          camera or camera_looking_down(), world)


def _camera(**change):
    """The 32x32 test camera with some fields replaced."""
    cam = camera_looking_down(size=32)
    fields = dict(matrix=cam.matrix, window=cam.window, width=cam.width, height=cam.height,
                  kind=cam.kind, clip_start=cam.clip_start, clip_end=cam.clip_end, border=None)
    fields.update(change)
    return Camera(**fields)


# -- triangles ----------------------------------------------------------------------


@pytest.mark.parametrize("bad_value", [np.nan, np.inf, -np.inf])
def test_nonfinite_triangles_are_dropped_and_counted(bad_value):
    tris = quad((0, 0, 0), 1.0)
    one = tris[:1].copy()
    one[0, 1, 2] = bad_value
    all_bad = np.full((1, 3, 3), bad_value)
    out = validate(_scene(np.concatenate([tris, one, all_bad])))
    assert out.triangle_count == 2
    assert out.report.dropped_nonfinite_triangles == 2
    assert out.report.as_stats()["dropped_nonfinite_triangles"] == 2
    np.testing.assert_array_equal(out.triangles, tris)
    assert any("NaN/Inf" in w and "2 " in w for w in out.warnings)


def test_corner_tangents_follow_the_triangles_kept_and_nonfinite_ones_become_none():
    tris = quad((0, 0, 0), 1.0)
    collinear = np.array([[[0, 0, 0], [1, 1, 1], [2, 2, 2]]], np.float64)
    scene = _scene(np.concatenate([tris, collinear]))
    scene.tangents = np.tile(np.array([1.0, 0.0, 0.0, -1.0], np.float32), (3, 3, 1))
    scene.tangents[1, 2] = (np.nan, 0.0, 0.0, 1.0)
    out = validate(scene)
    assert out.tangents.shape == (2, 3, 4) and np.isfinite(out.tangents).all()
    np.testing.assert_array_equal(out.tangents[1, 2], 0.0)
    np.testing.assert_array_equal(out.tangents[0], scene.tangents[0])
    scene.tangents = np.zeros((2, 3, 4), np.float32)  # one row short
    with pytest.raises(SceneError):
        validate(scene)


def test_zero_area_triangles_are_dropped_but_tiny_far_triangles_kept():
    collinear = [[[0, 0, 0], [1, 1, 1], [2, 2, 2]]]
    repeated = [[[0, 0, 0], [0, 0, 0], [1, 0, 0]]]
    all_same = [[[3, 4, 5], [3, 4, 5], [3, 4, 5]]]
    tiny_far = quad((1e5, 1e5, 0), 1e-4)
    out = validate(_scene(np.concatenate([collinear, repeated, tiny_far, all_same])))
    assert out.report.dropped_degenerate_triangles == 3
    assert out.report.as_stats()["dropped_degenerate_triangles"] == 3
    assert out.triangle_count == 2
    np.testing.assert_array_equal(out.triangles, tiny_far)
    assert any("zero-area" in w for w in out.warnings)


def test_tiny_triangles_at_the_origin_and_huge_ones_are_kept():
    tiny = quad((0, 0, 0), 1e-6)
    huge = quad((0, 0, 0), 1e6)
    out = validate(_scene(np.concatenate([tiny, huge])))
    assert out.report.dropped_degenerate_triangles == 0
    assert out.triangle_count == 4


def test_collinear_triangle_far_from_the_origin_is_dropped():
    # collinear in exact arithmetic; rounding at 1e5 leaves a cross product of
    # about 1e-12, which is noise, not area
    origin = np.array([1e5, 1e5, 1e5])
    collinear = np.array([[origin, origin + (0.1, 0.2, 0.3), origin + (0.2, 0.4, 0.6)]])
    kept = quad((1e5, 1e5, 1e5), 0.1)
    out = validate(_scene(np.concatenate([collinear, kept])))
    assert out.report.dropped_degenerate_triangles == 1
    np.testing.assert_array_equal(out.triangles, kept)


def test_empty_scene_is_valid_and_stays_empty():
    out = validate(_scene(np.zeros((0, 3, 3))))
    assert out.triangle_count == 0
    assert out.normals.shape == (0, 3, 3) and out.uvs.shape == (0, 3, 2) and out.material_ids.shape == (0,)
    assert out.report.as_stats() == dict.fromkeys(out.report.as_stats(), 0)


def test_array_with_the_wrong_shape_raises_a_scene_error():
    scene = _scene(quad((0, 0, 0), 1.0))
    scene.material_ids = np.zeros(5, np.int32)
    with pytest.raises(SceneError, match="shape"):
        validate(scene)


# -- materials ----------------------------------------------------------------------


def test_out_of_range_and_negative_material_ids_use_an_added_default_material():
    tris = np.concatenate([quad((0, 0, 0), 1.0), quad((2, 0, 0), 1.0), quad((4, 0, 0), 1.0)])
    materials = Materials.make([{"name": "a", "base_color": (1, 0, 0)}, {"name": "b"}])
    out = validate(_scene(tris, ids=[0, 1, 2, -1, 99, 1], materials=materials))
    assert out.report.repaired_material_ids == 3
    assert out.report.as_stats()["repaired_material_ids"] == 3
    assert len(out.materials) == 3
    assert out.materials.names == ["a", "b", "gpugi-default"]
    assert list(out.material_ids) == [0, 1, 2, 2, 2, 1]
    np.testing.assert_array_equal(out.materials.base_color[:2], materials.base_color)
    assert any("material index" in w for w in out.warnings)


def test_valid_material_ids_add_no_default_material():
    tris = quad((0, 0, 0), 1.0)
    materials = Materials.make([{"name": "a"}, {"name": "b"}])
    out = validate(_scene(tris, ids=[1, 0], materials=materials))
    assert out.report.repaired_material_ids == 0
    assert out.materials.names == ["a", "b"]
    assert list(out.material_ids) == [1, 0]


def test_nonfinite_material_values_are_repaired_and_named():
    materials = Materials.make([
        {"name": "fine"},
        {"name": "broken", "base_color": (np.nan, 0.5, 0.5), "roughness": np.inf, "ior": np.nan,
         "emission": (np.inf, 0.0, -1.0)},
    ])
    out = validate(_scene(quad((0, 0, 0), 1.0), ids=[0, 1], materials=materials))
    for name in _MATERIAL_FIELDS:
        assert np.isfinite(getattr(out.materials, name)).all(), name
    assert (out.materials.emission >= 0).all()
    np.testing.assert_array_equal(out.materials.base_color[0], materials.base_color[0])
    assert any("broken" in w for w in out.warnings)


# -- normals ------------------------------------------------------------------------


def test_zero_and_nan_normals_are_replaced_by_face_normals():
    scene = _scene(quad((0, 0, 0), 1.0))
    scene.normals[0, 0] = (0, 0, 0)
    scene.normals[1, 2] = (np.nan, 0, 1)
    scene.normals[1, 1] = (0, 1, 1)  # valid, only not unit length
    out = validate(scene)
    assert out.report.repaired_normals == 2
    assert out.report.as_stats()["repaired_normals"] == 2
    np.testing.assert_allclose(out.normals[0, 0], (0, 0, 1), atol=1e-6)
    np.testing.assert_allclose(out.normals[1, 2], (0, 0, 1), atol=1e-6)
    np.testing.assert_allclose(out.normals[1, 1], (0, 2**-0.5, 2**-0.5), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(out.normals, axis=2), 1.0, atol=1e-6)
    assert any("normals" in w for w in out.warnings)


def test_face_normal_replacement_follows_the_winding():
    scene = _scene(quad((0, 0, 0), 1.0, flip=True))
    scene.normals[:] = 0.0
    out = validate(scene)
    np.testing.assert_allclose(out.normals.reshape(-1, 3), np.tile((0, 0, -1), (6, 1)), atol=1e-6)


def test_normals_of_extreme_length_come_out_unit_length():
    scene = _scene(quad((0, 0, 0), 1.0))
    scene.normals[0, 0] = (1e30, 1e30, 0)  # finite in float32, its square is not
    scene.normals[0, 1] = (0, 3e-3, 4e-3)
    out = validate(scene)
    assert np.isfinite(out.normals).all()
    np.testing.assert_allclose(np.linalg.norm(out.normals, axis=2), 1.0, atol=1e-6)
    np.testing.assert_allclose(out.normals[0, 0], (2**-0.5, 2**-0.5, 0), atol=1e-6)
    np.testing.assert_allclose(out.normals[0, 1], (0, 0.6, 0.8), atol=1e-6)


def test_nonfinite_uvs_become_zero():
    scene = _scene(quad((0, 0, 0), 1.0))
    scene.uvs[0, 0] = (np.nan, 0.25)
    scene.uvs[1, 1] = (0.5, 0.75)
    out = validate(scene)
    np.testing.assert_array_equal(out.uvs[0, 0], (0, 0.25))
    np.testing.assert_array_equal(out.uvs[1, 1], (0.5, 0.75))


# -- lights and world ---------------------------------------------------------------


def test_lights_with_negative_or_nan_power_are_dropped_with_a_warning():
    lights = Lights.make([
        dict(kind=LIGHT_POINT, power=(10, 10, 10), name="good"),
        dict(kind=LIGHT_POINT, power=(-1, 0, 0), name="negative"),
        dict(kind=LIGHT_POINT, power=(np.nan, 1, 1), name="nan"),
        dict(kind=LIGHT_POINT, position=(np.inf, 0, 0), power=(1, 1, 1), name="far"),
        dict(kind=LIGHT_SUN, power=(0, 0, 0), name="off"),
    ])
    out = validate(_scene(quad((0, 0, 0), 1.0), lights=lights))
    assert out.report.dropped_lights == 3
    assert out.report.as_stats()["dropped_lights"] == 3
    assert out.lights.names == ["good", "off"]
    assert len(out.lights) == 2 and out.lights.power.shape == (2, 3)
    assert any("negative" in w and "nan" in w and "far" in w for w in out.warnings)


def test_lights_with_nonfinite_shape_values_do_not_reach_the_renderer():
    lights = Lights.make([
        dict(kind=LIGHT_POINT, power=(10, 10, 10), radius=np.nan, name="nan radius"),
        dict(kind=LIGHT_SPOT, power=(10, 10, 10), spot_angle=np.nan, spot_blend=np.inf, name="nan cone"),
        dict(kind=LIGHT_SUN, power=(1, 1, 1), sun_angle=np.nan, name="nan sun"),
        dict(kind=LIGHT_AREA, power=(10, 10, 10), axis_u=(np.nan, 0, 0), shape=AREA_RECTANGLE, name="nan area"),
        dict(kind=LIGHT_POINT, power=(10, 10, 10), name="good"),
    ])
    out = validate(_scene(quad((0, 0, 0), 1.0), lights=lights))
    for name in _LIGHT_FIELDS:
        assert np.isfinite(getattr(out.lights, name)).all(), name
    assert "good" in out.lights.names
    for name in ("nan radius", "nan cone", "nan sun", "nan area"):
        assert any(name in w for w in out.warnings), name


def test_negative_or_nonfinite_world_colour_becomes_black_with_a_warning():
    out = validate(_scene(quad((0, 0, 0), 1.0), world=(0.2, -1.0, 0.3)))
    np.testing.assert_array_equal(out.world_color, (0, 0, 0))
    assert any("world" in w for w in out.warnings)
    out = validate(_scene(quad((0, 0, 0), 1.0), world=(0.2, 0.5, 0.3)))
    np.testing.assert_allclose(out.world_color, (0.2, 0.5, 0.3))
    assert not out.warnings


# -- camera -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(matrix=np.zeros((4, 4))), "singular"),
        (dict(matrix=np.diag([1.0, 1.0, 0.0, 1.0])), "singular"),
        (dict(matrix=np.full((4, 4), np.nan)), "matrix"),
        (dict(matrix=np.eye(3)), "matrix"),
        (dict(window=(1.0, 1.0, 0.0, 1.0)), "window"),
        (dict(window=(0.0, 1.0, 0.5, -0.5)), "window"),
        (dict(window=(0.0, np.inf, 0.0, 1.0)), "window"),
        (dict(border=(0, 0, 100, 10)), "border"),
        (dict(border=(-1, 0, 10, 10)), "border"),
        (dict(border=(10, 10, 10, 20)), "border"),
        (dict(width=0), "empty"),
        (dict(height=-4), "empty"),
        (dict(clip_start=5.0, clip_end=1.0), "clipping"),
    ],
    ids=lambda v: v if isinstance(v, str) else None,
)
def test_unusable_camera_raises_a_scene_error(change, message):
    with pytest.raises(SceneError, match=message):
        validate(_scene(quad((0, 0, 0), 1.0), camera=_camera(**change)))


def test_usable_cameras_pass_unchanged():
    far = np.eye(4)
    far[:3, 3] = (1e5, -1e5, 4.0)
    for cam in (_camera(border=(8, 0, 32, 16)), _camera(matrix=far), _camera(kind=CAMERA_ORTHO, clip_start=0.0)):
        out = validate(_scene(quad((0, 0, 0), 1.0), camera=cam))
        assert out.camera.pixel_window == cam.pixel_window
        np.testing.assert_array_equal(out.camera.matrix, cam.matrix)


# -- the input stays as it was ------------------------------------------------------


def test_validate_leaves_the_input_unchanged():
    repeated = [[[0, 0, 0], [0, 0, 0], [1, 0, 0]]]
    nan = [[[np.nan, 0, 0], [1, 0, 0], [0, 1, 0]]]
    tris = np.concatenate([quad((0, 0, 0), 1.0), repeated, nan])
    lights = Lights.make([dict(power=(1, 1, 1), name="ok"), dict(power=(-1, 1, 1), name="bad")])
    materials = Materials.make([{"name": "glowing", "emission": (np.nan, 1.0, 1.0)}])
    scene = _scene(tris, ids=[0, 7, 0, -3], lights=lights, materials=materials)
    scene.normals[0, 0] = 0.0
    scene.uvs[1, 1] = np.nan
    scene.warnings.append("from the exporter")
    arrays = ("triangles", "normals", "uvs", "material_ids")
    before = {name: getattr(scene, name).copy() for name in arrays}
    light_power = scene.lights.power.copy()
    emission = scene.materials.emission.copy()
    out = validate(scene)
    for name in arrays:
        np.testing.assert_array_equal(getattr(scene, name), before[name], err_msg=name)
        assert not np.shares_memory(getattr(out, name), getattr(scene, name)), name
    np.testing.assert_array_equal(scene.lights.power, light_power)
    assert scene.lights.names == ["ok", "bad"]
    assert len(scene.materials) == 1 and scene.materials.names == ["glowing"]
    np.testing.assert_array_equal(scene.materials.emission, emission)
    assert scene.warnings == ["from the exporter"]
    assert out.warnings[0] == "from the exporter" and len(out.warnings) > 1


def test_clean_scene_passes_with_no_repairs_and_no_warnings():
    tris = np.concatenate([quad((0, 0, 0), 2.0), quad((0, 0, 1), 0.5, flip=True)])
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0, 0, 3), power=(100, 100, 100), name="lamp")])
    scene = _scene(tris, lights=lights)
    out = validate(scene)
    assert out.warnings == []
    assert out.report.as_stats() == dict.fromkeys(out.report.as_stats(), 0)
    np.testing.assert_array_equal(out.triangles, scene.triangles)
    np.testing.assert_allclose(out.normals, scene.normals, atol=1e-6)
    assert out.lights.names == ["lamp"]


# -- the geometry memo (the viewport's passes share a scene's arrays) ---------------


def test_a_scene_with_the_same_geometry_arrays_is_not_checked_again_but_its_repairs_still_count():
    tris = np.concatenate([quad((0, 0, 0), 1.0), quad((2, 0, 0), 1.0)])
    tris[0, 0, 0] = np.nan
    first = _scene(tris, ids=[0, 5, 0, 0], lights=Lights.make([dict(kind=LIGHT_POINT, power=(10,) * 3)]))
    memo = GeometryMemo()
    checked = validate(first, memo)
    brighter = dataclasses.replace(first, lights=Lights.make([dict(kind=LIGHT_POINT, power=(20,) * 3)]),
                                   materials=Materials.make([{"base_color": (0.1, 0.2, 0.3)}]))
    again = validate(brighter, memo)
    assert again.triangles is checked.triangles and again.normals is checked.normals  # not checked again
    assert again.report.as_stats() == checked.report.as_stats()  # 1 NaN triangle dropped, 1 id repaired
    assert again.report.dropped_nonfinite_triangles == 1 and again.report.repaired_material_ids == 1
    assert again.lights.power[0, 0] == 20 and again.materials.base_color[0, 0] == np.float32(0.1)
    assert again.materials.names[-1] == "gpugi-default"
    moved = dataclasses.replace(first, triangles=first.triangles + 1.0)
    assert validate(moved, memo).triangles is not checked.triangles  # new arrays: checked again
    np.testing.assert_array_equal(validate(moved, memo).triangles, checked.triangles + 1.0)


def _clean_pair():
    """Two quads, and the same with the second moved, given new arrays."""
    tris = np.concatenate([quad((0, 0, 0), 1.0), quad((2, 0, 0), 1.0)])
    first = _scene(tris)
    tris = first.triangles.copy()
    tris[2:] += (0.0, 0.5, 0.25)
    return first, dataclasses.replace(first, triangles=tris, normals=first.normals.copy())


def test_a_moved_part_of_a_clean_scene_is_checked_alone_and_gives_what_a_whole_check_gives(monkeypatch):
    first, moved = _clean_pair()
    memo = GeometryMemo()
    checked = validate(first, memo)
    module = sys.modules[GeometryMemo.__module__]
    sizes, check = [], module._checked_geometry
    monkeypatch.setattr(module, "_checked_geometry", lambda scene: sizes.append(len(scene.triangles)) or check(scene))
    patched, whole = validate(moved, memo), validate(moved)
    assert sizes == [2, 4]  # the memo checked the moved quad's two triangles
    for name in ("triangles", "normals", "uvs", "material_ids", "tangents"):
        np.testing.assert_array_equal(getattr(patched, name), getattr(whole, name), err_msg=name)
    # the moved rows are written into a copy; arrays equal row for row (the normals given as a new
    # array, the shared ones) are the last result's own
    assert not np.shares_memory(patched.triangles, checked.triangles)
    for name in ("normals", "uvs", "material_ids"):
        assert getattr(patched, name) is getattr(checked, name), name
    np.testing.assert_array_equal(checked.triangles, first.triangles)  # the last result is not written into
    assert patched.report.as_stats() == dict.fromkeys(patched.report.as_stats(), 0)


def test_a_moved_part_that_needs_a_repair_is_checked_with_the_whole_scene():
    first, moved = _clean_pair()
    memo = GeometryMemo()
    validate(first, memo)
    moved.triangles[3, 0, 0] = np.nan  # the moved quad's second triangle
    moved.normals[2] = 0.0
    patched = validate(moved, memo)
    assert patched.report.dropped_nonfinite_triangles == 1 and patched.report.repaired_normals == 1
    assert len(patched.triangles) == 3
    # and a clean move after a scene that needed repairs: the whole scene again
    again = dataclasses.replace(moved, triangles=moved.triangles.copy())
    assert validate(again, memo).report.dropped_nonfinite_triangles == 1


def test_the_materials_in_use_are_kept_for_the_scenes_material_ids_and_follow_a_new_array():
    tris = np.stack([quad((x, 0.0, 0.0), 1.0)[0] for x in range(4)])
    scene = _scene(tris, ids=[0, 0, 2, 2], materials=Materials.make([{"base_color": (0.5, 0.5, 0.5)}] * 3))
    used = scene.used_materials()
    np.testing.assert_array_equal(used, [0, 2])
    assert not used.flags.writeable  # shared by the plan's many questions
    scene.material_ids = np.array([1, 1, 1, 1], np.int32)
    np.testing.assert_array_equal(scene.used_materials(), [1])
