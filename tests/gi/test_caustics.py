"""Caustics seen directly (gi/caustics.py): the caustic map's estimates on
the shading points' grid, estimated at anchors and interpolated between
them only where the estimate is smooth."""

from __future__ import annotations

import numpy as np
import pytest

from gpu_core.accel.point_tree import PointTree
from gpu_core.device.layout import float4_rows
from gpu_core.gi import caustics, cut
from gpu_core.gi.shading_points import ShadingPoints

UP = np.array([0.0, 0.0, 1.0], np.float32)
K = 16


def photons_on_floor(rng, n, irradiance, half):
    """Photons spread evenly on the square [-half, half]^2 of the plane z = 0,
    arriving from above, carrying the power that gives ``irradiance``."""
    pts = rng.uniform(-half, half, (n, 3)).astype(np.float32)
    pts[:, 2] = 0.0
    power = np.full((n, 3), irradiance * (2 * half) ** 2 / n, np.float32)
    return pts, power, np.tile(UP, (n, 1))


def tree_of(device, pts, power, normal):
    return PointTree.build(device, pts, power, normal, normal)


def grid_points(device, pos, nrm, has):
    """Shading points of a window of ``pos.shape[:2]`` (rows, columns) pixels,
    one a pixel: positions, normals and whether each slot holds a point."""
    height, width = has.shape
    grid_pos = float4_rows(pos.reshape(-1, 3))
    grid_pos[:, 3] = has.reshape(-1)
    return ShadingPoints(device, device.to_device(grid_pos), device.to_device(float4_rows(nrm.reshape(-1, 3))),
                         None, None, None, None, int(has.sum()), width, height, 1)


def floor_grid(device, width, height, half):
    """A grid of points over [-half, half]^2 of the floor, facing up."""
    xs, ys = np.linspace(-half, half, width), np.linspace(-half, half, height)
    pos = np.zeros((height, width, 3), np.float32)
    pos[..., 0], pos[..., 1] = xs[None, :], ys[:, None]
    return grid_points(device, pos, np.broadcast_to(UP, pos.shape).copy(), np.ones((height, width), bool))


def estimates(device, tree, points):
    """(grid, exact): caustics.irradiance on the grid, and the map's own
    estimate at every slot (zero where the slot holds no point)."""
    grid = device.read_xyz(caustics.irradiance(tree, points, K), points.grid_size)
    pos = device.read(points.grid_pos, (points.grid_size, 4), np.float32)
    nrm = device.read_xyz(points.grid_nrm, points.grid_size)
    exact = tree.irradiance(pos[:, :3], nrm, K, max_radius=cut.caustic_max_radius(tree))
    exact[pos[:, 3] == 0] = 0.0
    shape = (points.height, points.width, 3)
    return grid.reshape(shape), exact.reshape(shape)


def interpolated_within_own_changes(grid, exact):
    """The share of slots interpolated (not their own estimate), once
    checked that each departs from its own estimate by less than that
    estimate changes from one pixel to the next (photons entering and
    leaving its k): on average by less than half of it, at most by its
    largest change."""
    interpolated = ~np.isclose(grid, exact, rtol=1e-6).all(axis=2)
    deviation = (np.abs(grid - exact) / exact).max(axis=2)
    step = np.abs(np.diff(exact[..., 0], axis=1)) / exact[:, 1:, 0]
    assert deviation[interpolated].mean() < 0.5 * step.mean()
    assert deviation.max() < step.max()
    return interpolated.mean()


def scaled_estimates(device, scale, offset):
    """estimates() of sparse photons (a 16-photon radius of about 0.4) and a
    grid over them (pixels 0.03 apart), both scaled by ``scale`` and moved by
    ``offset``, the power scaled with the area (the irradiance the unit's)."""
    rng = np.random.default_rng(4)
    pts, power, normal = photons_on_floor(rng, 300, 2.0, 1.0)
    tree = tree_of(device, pts * np.float32(scale) + np.float32(offset), power * np.float32(scale**2), normal)
    points = floor_grid(device, 61, 53, 0.8)
    pos = device.read(points.grid_pos, (points.grid_size, 4), np.float32)
    pos[:, :3] = pos[:, :3] * np.float32(scale) + np.float32(offset)
    points.grid_pos = device.to_device(pos)
    return estimates(device, tree, points)


@pytest.mark.parametrize("scale, offset", [(1e-3, 0.0), (1e4, 0.0), (1.0, 1e5)])
def test_tiny_huge_and_distant_grids_interpolate_like_the_unit_grid(device, scale, offset):
    unit_grid, unit_exact = scaled_estimates(device, 1.0, 0.0)
    grid, exact = scaled_estimates(device, scale, offset)
    assert np.isfinite(grid).all()
    share = interpolated_within_own_changes(grid, exact)
    assert abs(share - interpolated_within_own_changes(unit_grid, unit_exact)) < 0.05
    if offset:  # float32 positions 1e5 m out move by millimetres: a few estimates take another photon
        assert abs(grid.mean() / unit_grid.mean() - 1.0) < 0.01
    else:
        np.testing.assert_allclose(grid, unit_grid, rtol=1e-3)


def test_with_no_span_every_slot_takes_its_own_estimate(device, monkeypatch):
    rng = np.random.default_rng(3)
    tree = tree_of(device, *photons_on_floor(rng, 300, 2.0, 1.0))
    monkeypatch.setattr(caustics, "SPAN", 0.0)
    grid, exact = estimates(device, tree, floor_grid(device, 37, 29, 1.0))
    np.testing.assert_allclose(grid, exact, rtol=1e-6, atol=1e-9)


def test_sparse_photons_are_interpolated_within_the_estimates_own_changes(device):
    grid, exact = scaled_estimates(device, 1.0, 0.0)
    anchors = np.zeros(grid.shape[:2], bool)
    anchors[::caustics.ANCHOR_SPACING, ::caustics.ANCHOR_SPACING] = True
    np.testing.assert_allclose(grid[anchors], exact[anchors], rtol=1e-6)
    assert interpolated_within_own_changes(grid, exact) > 0.5  # most slots between anchors take their mean


def test_a_sharp_caustic_keeps_every_slots_own_estimate(device):
    rng = np.random.default_rng(5)
    tree = tree_of(device, *photons_on_floor(rng, 20000, 50.0, 0.05))  # a bright spot 0.1 wide
    grid, exact = estimates(device, tree, floor_grid(device, 63, 63, 0.1))  # pixels 3 mm apart, the spot's radius 1.6 mm
    xs = np.linspace(-0.1, 0.1, 63)
    spot = (np.abs(xs)[None, :] < 0.045) & (np.abs(xs)[:, None] < 0.045)
    np.testing.assert_allclose(grid[spot], exact[spot], rtol=1e-6)
    assert abs(grid[spot].mean() / 50.0 - 1.0) < 0.05


def test_anchors_on_another_surface_or_without_a_point_are_not_used(device):
    rng = np.random.default_rng(6)
    # a floor (rows 0-29) meeting a wall facing -y (rows 30-), the wall's light 100 times the floor's
    floor = photons_on_floor(rng, 300, 1.0, 1.0)
    wall_pts = rng.uniform(-1.0, 1.0, (300, 3)).astype(np.float32)
    wall_pts[:, 1] = 1.0
    wall_nrm = np.tile(np.array([0.0, -1.0, 0.0], np.float32), (300, 1))
    tree = tree_of(device, np.concatenate([floor[0], wall_pts]),
                   np.concatenate([floor[1], np.full((300, 3), 400.0 / 300, np.float32)]),
                   np.concatenate([floor[2], wall_nrm]))
    width, height = 41, 45
    pos = np.zeros((height, width, 3), np.float32)
    nrm = np.zeros((height, width, 3), np.float32)
    t = np.linspace(-0.6, 0.6, width)
    for row in range(height):
        on_floor = row < 30
        pos[row, :, 0] = t
        pos[row, :, 1] = 1.0 - (30 - row) * 0.01 if on_floor else 1.0
        pos[row, :, 2] = 0.0 if on_floor else (row - 30) * 0.01
        nrm[row] = UP if on_floor else [0.0, -1.0, 0.0]
    has = np.ones((height, width), bool)
    has[8, :] = False  # an anchor row and column without points (holes in the view)
    has[:, 20] = False
    grid, exact = estimates(device, tree, grid_points(device, pos, nrm, has))
    np.testing.assert_array_equal(grid[~has], 0.0)
    # row 29 lies between the floor's row 28 and the wall's row 30, and row
    # 30's even columns between rows 28 and 32 (its odd ones between its
    # even ones); rows 7 and 9, columns 19 and 21 beside a hole
    np.testing.assert_allclose(grid[[29, 7, 9]], exact[[29, 7, 9]], rtol=1e-6)
    np.testing.assert_allclose(grid[30, ::2], exact[30, ::2], rtol=1e-6)
    np.testing.assert_allclose(grid[:, [19, 21]], exact[:, [19, 21]], rtol=1e-6)
    deviation = np.abs(grid - exact).max(axis=2) / np.maximum(exact.max(axis=2), 1e-12)
    assert deviation[has].max() < 0.5  # a blend of the wall's light and the floor's would be many times either


def test_slots_past_the_last_anchor_take_their_own_estimates(device):
    rng = np.random.default_rng(8)
    tree = tree_of(device, *photons_on_floor(rng, 300, 2.0, 1.0))
    # anchors every 4 pixels: the last column 40, the last row 36; then every 2: row 38
    grid, exact = estimates(device, tree, floor_grid(device, 42, 39, 0.8))
    np.testing.assert_allclose(grid[:, 41], exact[:, 41], rtol=1e-6)  # no column 42 to interpolate from
    np.testing.assert_allclose(grid[38, ::2], exact[38, ::2], rtol=1e-6)  # no row 40
