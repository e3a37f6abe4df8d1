"""Irradiance interpolation (gpu_core.cache.interpolate) against a numpy
brute-force weighted sum over every sample, with Ward's weights, the
rejection tests and the nearest-sample fallback."""

import numpy as np
import pytest
from cache_shapes import shading_points

from gpu_core.gi.cache.interpolation import interpolate
from gpu_core.gi.cache.interpolation import BEHIND, COVER, GRADIENT_LIMIT

SIZE = 64
TIE = 1e-6  # CACHE_TIE (normalised units): nearer samples within it tie, lowest index wins


def brute_force(spos, sn, se, sr, pts, nrm, a=COVER, behind=BEHIND):
    """(N, 3) irradiance and per-point kind: 1 covered, 2 nearest compatible, 3 nearest."""
    spos, sn, se, sr, pts, nrm = (np.asarray(v, np.float64) for v in (spos, sn, se, sr, pts, nrm))
    extent = np.ptp(np.concatenate([spos, pts]), axis=0).max()
    out, kind = np.zeros((len(pts), 3)), np.zeros(len(pts), int)
    for i, (x, n) in enumerate(zip(pts, nrm)):
        d = x - spos
        dist = np.linalg.norm(d, axis=1)
        cos = sn @ n
        ok = (dist < a * sr) & (cos > 0.01) & (np.sum(d * (n + sn), axis=1) >= -behind * sr)
        if ok.any():
            w = 1.0 / np.maximum(dist[ok] / sr[ok] + np.linalg.norm(n - sn[ok], axis=1), 1e-6)
            out[i] = (w[:, None] * se[ok]).sum(axis=0) / w.sum()
            kind[i] = 1
            continue
        compatible = cos > 0.01
        pool = np.flatnonzero(compatible) if compatible.any() else np.arange(len(spos))
        near = dist[pool] / extent
        pick = pool[np.argmax(near <= near.min() + TIE * (1.0 + near.min()))]
        out[i] = se[pick]
        kind[i] = 2 if compatible.any() else 3
    return out, kind


def cache_on(shape, count, seed=1, scale=1.0, r_range=(0.2, 0.6)):
    """Shading points of ``shape`` and ``count`` of them as samples with
    random irradiance and harmonic-mean distance."""
    pos, nrm, _ = shading_points(shape, SIZE, SIZE, scale=scale)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(pos), count, replace=False)
    irradiance = rng.uniform(0.1, 5.0, (count, 3)).astype(np.float32)
    radius = (rng.uniform(*r_range, count) * scale).astype(np.float32)
    return (pos[pick], nrm[pick], irradiance, radius), (pos, nrm)


@pytest.mark.parametrize("shape", ["plane", "two_planes", "sphere", "box"])
def test_interpolation_equals_the_brute_force_weighted_sum(device, shape):
    samples, (pos, nrm) = cache_on(shape, 120)
    got, stats = interpolate(device, *samples, pos, nrm)
    want, kind = brute_force(*samples, pos, nrm)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)
    assert stats["covered"] == pytest.approx((kind == 1).mean())
    assert stats["fallback"] == (kind > 1).sum()
    assert np.isfinite(got).all()


@pytest.mark.parametrize("shape", ["two_planes", "box"])
def test_radii_over_four_decades_equal_the_brute_force_sum(device, shape):
    """Samples on many levels of the hash grid, listed in every cell their
    sphere meets: none found twice, none missed."""
    (spos, snrm, irradiance, _), (pos, nrm) = cache_on(shape, 300, seed=4)
    radius = np.exp(np.random.default_rng(5).uniform(np.log(1e-3), np.log(10.0), len(spos))).astype(np.float32)
    got, _ = interpolate(device, spos, snrm, irradiance, radius, pos, nrm)
    want, _ = brute_force(spos, snrm, irradiance, radius, pos, nrm)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)


def test_uncovered_points_take_the_nearest_sample_facing_their_way(device):
    samples, (pos, nrm) = cache_on("box", 80, r_range=(1e-4, 2e-4))
    got, stats = interpolate(device, *samples, pos, nrm)
    want, kind = brute_force(*samples, pos, nrm)
    assert (kind > 1).mean() > 0.9  # nearly nothing is covered
    np.testing.assert_array_equal(got, want.astype(np.float32))
    assert stats["fallback"] == (kind > 1).sum()


def test_constant_irradiance_interpolates_to_exactly_that_constant(device):
    samples, (pos, nrm) = cache_on("box", 150)
    constant = np.array([0.7, 1.3, 1e-3], np.float32)
    got, _ = interpolate(device, samples[0], samples[1], np.tile(constant, (150, 1)), samples[3], pos, nrm)
    assert (got == constant).all()


def test_samples_in_front_of_the_point_or_facing_away_are_rejected(device):
    point, up = np.array([[0.0, 0.0, 0.0]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32)
    spos = np.array([[0.0, 0.0, 0.05],   # on a parallel surface just above: in front of the point
                     [0.02, 0.0, 0.0],   # beside it, facing away
                     [0.0, 0.03, 0.0],   # beside it, same way: the only one accepted
                     [0.0, -0.03, 0.0]], np.float32)
    # the last one is tilted to n . n_j = 0.009, below the 0.01 limit
    sn = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1], [0.0, np.sqrt(1 - 0.009**2), 0.009]], np.float32)
    se = np.array([[9, 9, 9], [8, 8, 8], [1, 2, 3], [7, 7, 7]], np.float32)
    sr = np.full(4, 1.0, np.float32)
    got, stats = interpolate(device, spos, sn, se, sr, point, up)
    np.testing.assert_array_equal(got, [[1, 2, 3]])
    assert stats["covered"] == 1.0


def test_a_point_with_no_sample_facing_its_way_takes_the_nearest_sample(device):
    spos = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.2]], np.float32)
    sn = np.array([[0, 0, -1], [0, 0, -1]], np.float32)
    se = np.array([[1, 1, 1], [2, 2, 2]], np.float32)
    got, stats = interpolate(device, spos, sn, se, np.ones(2, np.float32), np.zeros((1, 3), np.float32),
                             np.array([[0, 0, 1]], np.float32))
    np.testing.assert_array_equal(got, [[2, 2, 2]])
    assert stats["fallback"] == 1 and stats["fallback_any_normal"] == 1


def test_no_samples_or_no_points_give_zeros(device):
    pos, nrm, _ = shading_points("sphere", 16, 16)
    none = np.zeros((0, 3), np.float32)
    got, stats = interpolate(device, none, none, none, np.zeros(0, np.float32), pos, nrm)
    assert got.shape == pos.shape and (got == 0).all()
    got, _ = interpolate(device, pos[:3], nrm[:3], np.ones((3, 3)), np.ones(3), none, none)
    assert got.shape == (0, 3)


def test_one_sample_gives_its_irradiance_everywhere_it_faces(device):
    pos, nrm, _ = shading_points("plane", 32, 32)
    got, stats = interpolate(device, pos[:1], nrm[:1], np.array([[3.0, 2.0, 1.0]]), np.array([0.1]), pos, nrm)
    assert (got == np.array([3.0, 2.0, 1.0], np.float32)).all()
    assert 0.0 < stats["covered"] < 1.0


def test_a_sample_gradient_carries_its_irradiance_to_a_point_up_to_its_limit_and_coverage(device):
    # one sample at the origin facing up, R_j = 1 (it covers 0.5 around it), E_j = (1, 2, 4)
    spos, snrm, e, r = np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 2.0, 4.0]]), np.array([1.0])
    pts = np.array([[0.3, 0.0, 0.0], [0.0, -0.2, 0.0], [-0.4, 0.1, 0.0]])
    grad = np.zeros((1, 3, 3))  # channel, axis
    grad[0, 0, 0] = 0.2  # red: 0.2 over R_j, within the limit of 0.5 x 1
    grad[0, 1, 1] = 5.0  # green: 5 over R_j, scaled down to 0.5 x 2
    grad[0, 2, 0] = -2.0  # blue: 2 over R_j, just the limit of 0.5 x 4
    got, stats = interpolate(device, spos, snrm, e, r, pts, np.repeat(snrm, 3, axis=0), samples_grad=grad)
    assert stats["covered"] == 1.0
    green = GRADIENT_LIMIT * 2.0  # the gradient's length after the limit
    expected = [[1.0 + 0.2 * 0.3, 2.0, 4.0 - 2.0 * 0.3],
                [1.0, 2.0 - green * 0.2, 4.0],
                [1.0 - 0.2 * 0.4, 2.0 + green * 0.1, 4.0 + 2.0 * 0.4]]
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    # without gradients the sample's value, unchanged
    plain, _ = interpolate(device, spos, snrm, e, r, pts, np.repeat(snrm, 3, axis=0))
    assert (plain == np.array([1.0, 2.0, 4.0], np.float32)).all()
    # a point past its coverage (0.5) takes it carried from the edge of its coverage
    far, stats = interpolate(device, spos, snrm, e, r, np.array([[2.0, 0.0, 0.0]]), snrm, samples_grad=grad)
    assert stats["covered"] == 0.0 and stats["fallback"] == 1
    np.testing.assert_allclose(far, [[1.0 + 0.2 * COVER, 2.0, 4.0 - 2.0 * COVER]], rtol=1e-5)
    # and one that faces away from it, its value as it is
    away, _ = interpolate(device, spos, snrm, e, r, np.array([[0.1, 0.0, 0.0]]), -snrm, samples_grad=grad)
    assert (away == np.array([1.0, 2.0, 4.0], np.float32)).all()


def test_extreme_irradiance_and_distances_stay_finite(device):
    samples, (pos, nrm) = cache_on("box", 100)
    spos, sn, _, _ = samples
    rng = np.random.default_rng(3)
    irradiance = rng.choice([0.0, 1e-30, 1e8, 3e30], (100, 3)).astype(np.float32)
    radius = rng.choice([0.0, -1.0, np.nan, np.inf, 1e-30, 1e30, 0.3], 100).astype(np.float32)
    got, _ = interpolate(device, spos, sn, irradiance, radius, pos, nrm)
    assert np.isfinite(got).all()
    assert (got >= 0).all() and (got <= 3e30).all()


@pytest.mark.parametrize("scale", [1e-3, 1e4])
def test_scaled_scenes_interpolate_the_same(device, scale):
    samples, (pos, nrm) = cache_on("two_planes", 100)
    unit, unit_stats = interpolate(device, *samples, pos, nrm)
    samples, (pos, nrm) = cache_on("two_planes", 100, scale=scale)
    got, stats = interpolate(device, *samples, pos, nrm)
    np.testing.assert_allclose(got, unit, rtol=1e-5)
    assert stats["covered"] == unit_stats["covered"]
    assert stats["fallback"] == unit_stats["fallback"]


def test_a_scene_far_from_the_origin_equals_the_brute_force_sum(device):
    (spos, sn, se, sr), (pos, nrm) = cache_on("two_planes", 100)
    offset = np.array([1e5, -1e5, 1e5], np.float32)
    spos, pos = spos + offset, pos + offset
    got, stats = interpolate(device, spos, sn, se, sr, pos, nrm)
    want, kind = brute_force(spos, sn, se, sr, pos, nrm)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)
    assert stats["covered"] == pytest.approx((kind == 1).mean())
