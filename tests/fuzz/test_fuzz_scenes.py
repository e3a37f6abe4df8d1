"""Random gpu_core scenes (hypothesis): triangle soups with degenerate,
tiny, huge, far-off, coincident and non-finite triangles; materials inside
and beyond their ranges; every light type with extreme sizes, angles and
powers; odd cameras; tiny photon and cache counts. Every render either
raises a GpuGiError (a message for the user) or returns finite,
non-negative pixels, and leaves the caller's scene arrays unchanged.

The CI run is ``FUZZ_EXAMPLES`` scenes with a fixed seed; the long run is
``GPUGI_FUZZ_EXAMPLES=2000 .venv/bin/python -m pytest -m fuzz -q tests/fuzz``.
"""

from __future__ import annotations

import copy
import dataclasses
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpu_core.errors import GpuGiError
from gpu_core.renderer import Renderer
from gpu_core.scene import (AREA_ELLIPSE, AREA_RECTANGLE, CAMERA_ORTHO, CAMERA_PERSP, LIGHT_AREA, LIGHT_POINT,
                            LIGHT_SPOT, LIGHT_SUN, MATERIAL_GLASS, MATERIAL_GLOSSY, MATERIAL_PRINCIPLED, Camera,
                            Lights, Materials, Scene)
from gpu_core.settings import RenderSettings

pytestmark = pytest.mark.fuzz

FUZZ_EXAMPLES = int(os.environ.get("GPUGI_FUZZ_EXAMPLES", "150"))
SIZE = 8  # pixels per side

# numbers a user's scene can hold: ordinary, tiny, huge, zero, negative, and not finite
_ODD = st.sampled_from([0.0, -0.0, 1e-30, -1e-30, 1e-7, 1e7, 1e30, -1e30, np.nan, np.inf, -np.inf])
_WIDE = st.floats(-1e6, 1e6, allow_nan=False)


def _values(low: float, high: float):
    """Mostly in [low, high], sometimes just outside, sometimes odd."""
    return st.one_of(st.floats(low, high), st.floats(low - 1.0, high + 1.0), _ODD)


@st.composite
def triangles(draw) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 3) corners and (T, 3, 3) corner normals of a soup at one scale and place."""
    count = draw(st.integers(0, 24))
    scale = 10.0 ** draw(st.floats(-3, 4))
    offset = np.array(draw(st.tuples(_WIDE, _WIDE, _WIDE))) * draw(st.sampled_from([0.0, 1e-6, 1.0]))
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    tris = rng.normal(size=(count, 3, 3)) * scale + offset
    kinds = draw(st.lists(st.sampled_from(["plain", "collinear", "point", "duplicate", "odd", "flat"]),
                          min_size=count, max_size=count))
    for i, kind in enumerate(kinds):
        if kind == "collinear":
            tris[i, 2] = tris[i, 0] + 2.0 * (tris[i, 1] - tris[i, 0])
        elif kind == "point":
            tris[i] = tris[i, 0]
        elif kind == "duplicate" and i:
            tris[i] = tris[i - 1]
        elif kind == "odd":
            tris[i, draw(st.integers(0, 2)), draw(st.integers(0, 2))] = draw(_ODD)
        elif kind == "flat":
            tris[i, :, 2] = offset[2]
    normals = rng.normal(size=(count, 3, 3)).astype(np.float32)
    if count and draw(st.booleans()):
        normals[draw(st.integers(0, count - 1))] = draw(st.sampled_from([0.0, np.nan, np.inf, 1e30]))
    return tris, normals


@st.composite
def materials(draw) -> Materials:
    rows = []
    for _ in range(draw(st.integers(1, 4))):
        rows.append(dict(
            base_color=draw(st.tuples(*[_values(0.0, 1.0)] * 3)), metallic=draw(_values(0.0, 1.0)),
            roughness=draw(_values(0.0, 1.0)), transmission=draw(_values(0.0, 1.0)), ior=draw(_values(1.0, 3.0)),
            emission=draw(st.tuples(*[st.one_of(st.floats(0.0, 1e4), _ODD)] * 3)), alpha=draw(_values(0.0, 1.0)),
            specular_ior_level=draw(_values(0.0, 1.0)), specular_tint=draw(st.tuples(*[_values(0.0, 1.0)] * 3)),
            shader=draw(st.sampled_from([MATERIAL_PRINCIPLED, MATERIAL_GLOSSY, MATERIAL_GLASS]))))
    return Materials.make(rows)


@st.composite
def lights(draw) -> Lights:
    rows = []
    for _ in range(draw(st.integers(0, 3))):
        power = 10.0 ** draw(st.floats(-6, 12))
        rows.append(dict(
            kind=draw(st.sampled_from([LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, LIGHT_AREA])),
            position=draw(st.tuples(_WIDE, _WIDE, st.one_of(st.floats(-10, 10), _ODD))),
            direction=draw(st.sampled_from([(0, 0, -1), (0, 0, 1), (1, 0, 0), (0, 0, 0), (np.nan, 0, -1)])),
            axis_u=(draw(st.one_of(st.floats(0, 1e3), _ODD)), 0, 0), axis_v=(0, draw(st.floats(0, 1e3)), 0),
            power=(power * draw(st.floats(0, 1)), power, draw(st.one_of(st.just(power), _ODD))),
            radius=draw(st.one_of(st.floats(0, 1e3), _ODD)), spot_angle=draw(st.floats(0, 2 * np.pi)),
            spot_blend=draw(_values(0.0, 1.0)), sun_angle=draw(st.floats(0, np.pi)),
            shape=draw(st.sampled_from([AREA_RECTANGLE, AREA_ELLIPSE]))))
    return Lights.make(rows)


@st.composite
def cameras(draw) -> Camera:
    height = 10.0 ** draw(st.floats(-3, 4))
    matrix = np.eye(4)
    matrix[:3, 3] = (0.0, 0.0, height)
    half = 10.0 ** draw(st.floats(-4, 3))
    near = draw(st.sampled_from([1e-6, 1e-3, 0.1])) * height
    far = draw(st.sampled_from([1e-2, 1.0, 1e3, 1e9])) * height
    kind = draw(st.sampled_from([CAMERA_PERSP, CAMERA_ORTHO]))
    return Camera(matrix=matrix, window=(-half, half, -half, half), width=SIZE, height=SIZE, kind=kind,
                  clip_start=near, clip_end=far)


@st.composite
def render_settings(draw) -> RenderSettings:
    return RenderSettings(
        mode=draw(st.sampled_from(["gi", "reference"])), samples=1, seed=draw(st.integers(0, 3)),
        max_bounces=draw(st.integers(0, 4)), diffuse_bounces=draw(st.integers(0, 2)),
        global_photons=draw(st.sampled_from([0, 1, 300, 2000])), caustic_photons=draw(st.sampled_from([0, 1, 300])),
        photon_k=draw(st.integers(1, 8)), cache_seeds=draw(st.integers(1, 16)), gather_rays=draw(st.integers(1, 9)),
        gi_subpixels=draw(st.integers(1, 2)), clamp=draw(st.sampled_from([0.0, 1.0, 1e9])))


@st.composite
def scenes(draw) -> Scene:
    tris, normals = draw(triangles())
    table = draw(materials())
    ids = np.array(draw(st.lists(st.integers(-2, len(table) + 2), min_size=len(tris), max_size=len(tris))), np.int32)
    world = draw(st.tuples(*[st.one_of(st.floats(0, 10), _ODD)] * 3))
    return Scene(triangles=tris, normals=normals, uvs=np.zeros((len(tris), 3, 2), np.float32), material_ids=ids,
                 materials=table, lights=draw(lights()), camera=draw(cameras()),
                 world_color=np.array(world, np.float32))


@pytest.fixture(scope="module")
def renderer_factory(request):
    from gpu_core.device import get_device

    device = get_device(None)
    return lambda: Renderer(device)


def _copy(scene: Scene) -> Scene:
    return copy.deepcopy(scene)


def _assert_unchanged(before: Scene, after: Scene) -> None:
    for f in dataclasses.fields(Scene):
        a, b = getattr(before, f.name), getattr(after, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b, err_msg=f.name)
    for table in ("materials", "lights"):
        for f in dataclasses.fields(getattr(before, table)):
            a, b = getattr(getattr(before, table), f.name), getattr(getattr(after, table), f.name)
            if isinstance(a, np.ndarray):
                np.testing.assert_array_equal(a, b, err_msg=f"{table}.{f.name}")
    np.testing.assert_array_equal(before.camera.matrix, after.camera.matrix)


@settings(max_examples=FUZZ_EXAMPLES, derandomize=True, database=None, deadline=None, print_blob=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example,
                                 HealthCheck.function_scoped_fixture])
@given(scene=scenes(), config=render_settings())
def test_a_random_scene_renders_finite_non_negative_pixels_or_says_why(renderer_factory, scene, config):
    before = _copy(scene)
    try:
        result = renderer_factory().render(scene, config)
    except GpuGiError as err:
        assert str(err)  # a message the user can act on
    else:
        image = result.passes["Combined"]
        assert image.shape == (SIZE, SIZE, 4)
        assert np.isfinite(image).all() and image.min() >= 0.0
    _assert_unchanged(before, scene)
