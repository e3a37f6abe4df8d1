"""The pixel filter: camera samples offset from the pixel centre by the
filter's inverse CDF, so an edge is spread as Cycles' box, Gaussian and
Blackman-Harris filters spread it (closed forms here, Cycles in
tests/addon/test_addon_pixel_filter.py)."""

from math import erf, sqrt

import numpy as np
import pytest
from scenes_py import camera_looking_down, make_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import FILTER_BLACKMAN_HARRIS, FILTER_BOX, FILTER_GAUSSIAN, Lights, Materials
from gpu_core.settings import RenderSettings
from gpu_core.shading.pixel_filter import filter_table

SIZE = 32
EDGE = 0.3  # scene units = pixels from the image centre


def blackman_harris_cdf(t: float) -> float:
    a = 2 * np.pi * t
    return (0.35875 * t - 0.48829 * np.sin(a) / (2 * np.pi) + 0.14128 * np.sin(2 * a) / (4 * np.pi)
            - 0.01168 * np.sin(3 * a) / (6 * np.pi)) / 0.35875


def gaussian_cdf(t: float) -> float:
    k = sqrt(72.0)
    return (erf(k * (t - 0.5)) + erf(k * 0.5)) / (2 * erf(k * 0.5))


# kind -> (support in widths, CDF over the support)
CLOSED_FORMS = {FILTER_BOX: (1.0, lambda t: t), FILTER_GAUSSIAN: (3.0, gaussian_cdf),
                FILTER_BLACKMAN_HARRIS: (2.0, blackman_harris_cdf)}


def expected_columns(kind: int, width: float) -> np.ndarray:
    """Fraction of each column's samples that land right of the edge."""
    support, cdf = CLOSED_FORMS[kind]
    support *= width
    out = []
    for column in range(SIZE):
        d = EDGE + SIZE / 2 - (column + 0.5)  # the edge, from the pixel centre
        t = min(max(d / support + 0.5, 0.0), 1.0)
        out.append(1.0 - cdf(t))
    return np.array(out)


def edge_scene(kind: int, width: float):
    """An emitter of radiance 1 right of x = EDGE under an orthographic camera, one unit per pixel."""
    camera = camera_looking_down(height=4.0, half_width=SIZE / 2, size=SIZE, ortho=True)
    camera.filter_kind, camera.filter_width = kind, width
    tris = quad((EDGE + 100.0, 0.0, 0.0), 200.0)
    materials = Materials.make([{"base_color": (0, 0, 0), "emission": (1.0, 1.0, 1.0)}])
    return make_scene(tris, np.zeros(2, np.int32), materials, Lights.make([]), camera)


@pytest.mark.parametrize("kind, width", [(FILTER_BOX, 1.0), (FILTER_GAUSSIAN, 1.5), (FILTER_BLACKMAN_HARRIS, 1.5),
                                         (FILTER_BLACKMAN_HARRIS, 3.0)])
def test_an_edge_is_spread_as_the_filter_spreads_it(device, kind, width):
    image = Renderer(device).render(edge_scene(kind, width), RenderSettings(samples=512)).passes["Combined"]
    columns = image[..., 0].mean(axis=0)
    np.testing.assert_allclose(columns, expected_columns(kind, width), atol=0.015)


def test_the_default_box_of_one_pixel_covers_exactly_the_pixel():
    np.testing.assert_allclose(filter_table(FILTER_BOX, 1.0), np.linspace(-0.5, 0.5, len(filter_table(FILTER_BOX, 1.0))),
                               atol=1e-6)


@pytest.mark.parametrize("kind", [FILTER_GAUSSIAN, FILTER_BLACKMAN_HARRIS])
def test_filter_tables_rise_symmetrically_within_the_support(kind):
    table = filter_table(kind, 1.5).astype(np.float64)
    support = CLOSED_FORMS[kind][0] * 1.5
    assert np.all(np.diff(table) > 0)
    np.testing.assert_allclose(table, -table[::-1], atol=1e-5)
    assert -support / 2 <= table[0] and table[-1] <= support / 2


@pytest.mark.parametrize("width", [float("nan"), float("inf"), -1.0, 0.0, 1e9])
def test_a_bad_filter_width_gives_a_finite_bounded_table(width):
    table = filter_table(FILTER_BLACKMAN_HARRIS, width)
    assert np.all(np.isfinite(table)) and np.abs(table).max() <= 10.0
