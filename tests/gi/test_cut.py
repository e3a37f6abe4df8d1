"""The illumination cut of a photon tree: a valid cut, and irradiance from it
that matches the photons' density."""

from __future__ import annotations

import numpy as np
import pytest

from gpu_core.accel.point_tree import PointTree
from gpu_core.device.layout import float4_rows
from gpu_core.gi import cut

UP = np.array([0.0, 0.0, 1.0], np.float32)


def plane_photons(rng, n, irradiance, half=1.0, axis=2, offset=0.0):
    """Photons spread evenly on the square [-half, half]^2 of the plane
    x[axis] = offset, arriving along +axis, carrying the power that gives
    ``irradiance``."""
    pts = rng.uniform(-half, half, (n, 3)).astype(np.float32)
    pts[:, axis] = offset
    normal = np.zeros((n, 3), np.float32)
    normal[:, axis] = 1.0
    power = np.full((n, 3), irradiance * (2 * half) ** 2 / n, np.float32)
    return pts, power, normal


def build(device, pts, power, normal):
    return PointTree.build(device, pts, power, normal, normal)


def cut_is_valid(tree, chosen):
    """Exactly one chosen node on every root-to-leaf path to photons (and at
    most one on the paths to empty leaves, which the cut leaves out)."""
    nodes = tree.nodes()
    n = len(nodes)
    on_path = np.zeros(n, np.int64)  # chosen nodes from the root down to each node
    chosen_mask = np.zeros(n, bool)
    chosen_mask[chosen] = True
    on_path[0] = chosen_mask[0]
    for i in range(n):
        if nodes["axis"][i] != cut.LEAF:
            for child in (i + 1, nodes["child"][i]):
                on_path[child] = on_path[i] + chosen_mask[child]
    leaves = nodes["axis"] == cut.LEAF
    lit = tree.node_info()["count"] > 0
    return bool((on_path[leaves & lit] == 1).all() and (on_path[leaves] <= 1).all())


def test_cut_holds_one_node_on_every_root_to_leaf_path(device):
    rng = np.random.default_rng(0)
    tree = build(device, *plane_photons(rng, 20000, 3.0))
    chosen = cut.select(device, tree, 50)
    assert cut_is_valid(tree, chosen.nodes)


def test_evenly_lit_plane_is_cut_far_above_the_leaves(device):
    rng = np.random.default_rng(0)
    tree = build(device, *plane_photons(rng, 20000, 3.0))
    chosen = cut.select(device, tree, 50)
    leaves = int((tree.nodes()["axis"] == cut.LEAF).sum())
    assert 0 < len(chosen.nodes) < leaves / 20


def point_lit_plane_photons(rng, n, height=1.0, half=4.0):
    """Photons of a point light ``height`` above the square [-half, half]^2 of
    the plane z = 0, emitted downwards uniformly over directions, those that
    land carrying 1 W between them; and the light's intensity (W/sr)."""
    kept = []
    while sum(len(p) for p in kept) < n:
        d = rng.standard_normal((n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = d[d[:, 2] < -1e-3]
        p = d * (height / -d[:, 2])[:, None]
        kept.append(p[(np.abs(p[:, 0]) < half) & (np.abs(p[:, 1]) < half)])
    pts = np.concatenate(kept)[:n].astype(np.float32)
    pts[:, 2] = 0.0
    normal = np.tile(UP, (n, 1))
    # the square's solid angle seen from the light holds the 1 W
    solid_angle = 4.0 * np.arcsin(half * half / (half * half + height * height))
    return pts, np.full((n, 3), 1.0 / n, np.float32), normal, 1.0 / solid_angle


@pytest.mark.parametrize("n", [60_000, 150_000])
def test_a_plane_lit_from_one_point_keeps_its_falloff_in_the_cut(device, n):
    # one flat surface: no node is mixed, so without a bound on a coarse
    # node's photons a node near the root (the root itself in a demo scene)
    # could stand for the whole plane and flatten the light's falloff
    rng = np.random.default_rng(2)
    pts, power, normal, intensity = point_lit_plane_photons(rng, n)
    tree = build(device, pts, power, normal)
    chosen = cut.select(device, tree, 50)
    assert cut_is_valid(tree, chosen.nodes)
    inner = tree.nodes()["axis"][chosen.nodes] != cut.LEAF
    assert tree.node_info()["count"][chosen.nodes][inner].max(initial=0) <= cut.MAX_PHOTONS
    q = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]], np.float32)
    e = chosen.irradiance_at(q, np.tile(UP, (2, 1)))[:, 0]
    expected = intensity / (1.0 + (q[:, :2] ** 2).sum(1)) ** 1.5  # I cos(theta) / d^2 at height 1
    np.testing.assert_allclose(e, expected, rtol=0.15)


def test_irradiance_from_the_cut_matches_a_lit_plane(device):
    rng = np.random.default_rng(1)
    tree = build(device, *plane_photons(rng, 50000, 3.0))
    chosen = cut.select(device, tree, 50)
    q = np.zeros((2000, 3), np.float32)
    q[:, :2] = rng.uniform(-0.8, 0.8, (2000, 2))
    e = chosen.irradiance_at(q, np.tile(UP, (2000, 1)))
    assert abs(e.mean() / 3.0 - 1.0) < 0.05
    assert np.sqrt(((e / 3.0 - 1.0) ** 2).mean()) < 0.15


def test_walls_meeting_at_a_corner_keep_their_own_irradiance(device):
    # a floor at E = 2 and a wall at E = 6 meet along x = -1: nodes spanning both are split
    rng = np.random.default_rng(2)
    floor = plane_photons(rng, 30000, 2.0, axis=2, offset=-1.0)
    wall = plane_photons(rng, 30000, 6.0, axis=0, offset=-1.0)
    tree = build(device, *(np.concatenate(pair) for pair in zip(floor, wall)))
    chosen = cut.select(device, tree, 50)
    assert chosen.stats["mixed_nodes"] > 0
    q_floor = rng.uniform(-0.7, 0.7, (500, 3)).astype(np.float32)
    q_floor[:, 2] = -1.0
    q_wall = rng.uniform(-0.7, 0.7, (500, 3)).astype(np.float32)
    q_wall[:, 0] = -1.0
    e_floor = chosen.irradiance_at(q_floor, np.tile(UP, (500, 1)))
    e_wall = chosen.irradiance_at(q_wall, np.tile([1.0, 0.0, 0.0], (500, 1)))
    assert abs(e_floor.mean() / 2.0 - 1.0) < 0.06
    assert abs(e_wall.mean() / 6.0 - 1.0) < 0.06


def test_points_facing_away_from_every_node_get_no_light(device):
    rng = np.random.default_rng(3)
    tree = build(device, *plane_photons(rng, 5000, 1.0))
    chosen = cut.select(device, tree, 30)
    q = np.zeros((10, 3), np.float32)
    assert np.all(chosen.irradiance_at(q, np.tile(-UP, (10, 1))) == 0.0)


def test_points_beyond_every_node_take_the_nearest_facing_node(device):
    rng = np.random.default_rng(4)
    tree = build(device, *plane_photons(rng, 5000, 2.0))
    chosen = cut.select(device, tree, 30)
    far = np.array([[50.0, 0.0, 0.0]], np.float32)
    e = chosen.irradiance_at(far, UP[None])
    assert np.isfinite(e).all() and e[0, 0] > 0.5


def test_no_photons_give_an_empty_cut_and_zero_irradiance(device):
    empty = np.zeros((0, 3), np.float32)
    tree = PointTree.build(device, empty, empty, empty, empty)
    chosen = cut.select(device, tree, 50)
    assert len(chosen.nodes) == 0
    assert np.all(chosen.irradiance_at(np.zeros((3, 3)), np.tile(UP, (3, 1))) == 0.0)


@pytest.mark.parametrize("power_scale", [1e-6, 1e8])
def test_dim_and_blinding_photons_scale_the_irradiance_linearly(device, power_scale):
    rng = np.random.default_rng(5)
    pts, power, normal = plane_photons(rng, 20000, 1.0)
    base = cut.select(device, build(device, pts, power, normal), 50)
    scaled = cut.select(device, build(device, pts, power * np.float32(power_scale), normal), 50)
    q = np.zeros((200, 3), np.float32)
    q[:, :2] = rng.uniform(-0.8, 0.8, (200, 2))
    e0 = base.irradiance_at(q, np.tile(UP, (200, 1)))
    e1 = scaled.irradiance_at(q, np.tile(UP, (200, 1)))
    assert np.isfinite(e1).all()
    np.testing.assert_allclose(e1 / power_scale, e0, rtol=1e-3)


@pytest.mark.parametrize("scale", [1e-3, 1e4])
def test_tiny_and_huge_scenes_give_irradiance_over_scale_squared(device, scale):
    rng = np.random.default_rng(6)
    pts, power, normal = plane_photons(rng, 20000, 1.0)
    base = cut.select(device, build(device, pts, power, normal), 50)
    scaled = cut.select(device, build(device, pts * np.float32(scale), power, normal), 50)
    q = np.zeros((200, 3), np.float32)
    q[:, :2] = rng.uniform(-0.8, 0.8, (200, 2))
    e0 = base.irradiance_at(q, np.tile(UP, (200, 1)))
    e1 = scaled.irradiance_at(q * np.float32(scale), np.tile(UP, (200, 1)))
    np.testing.assert_allclose(e1 * scale**2, e0, rtol=1e-2)


def _caustic_estimates(device, tree, q, k):
    """(bounded, unbounded): cut.caustic_irradiance at host points ``q`` on
    the plane facing up, and the same estimate without a reach."""
    n = len(q)
    pos, nrm = device.to_device(float4_rows(q)), device.to_device(float4_rows(np.tile(UP, (n, 1))))
    bounded, unbounded = device.empty(16 * n), device.empty(16 * n)
    cut.caustic_irradiance(tree, pos, nrm, n, k, bounded)
    tree.irradiance_on_device(pos, nrm, n, k, unbounded)
    return device.read_xyz(bounded, n), device.read_xyz(unbounded, n)


def test_caustic_estimates_gather_only_within_the_reach_of_the_maps_radius(device):
    rng = np.random.default_rng(7)
    # a bright caustic on a small square, seen from inside it and from far away
    tree = build(device, *plane_photons(rng, 20000, 50.0, half=0.05))
    inside = np.zeros((200, 3), np.float32)
    inside[:, :2] = rng.uniform(-0.04, 0.04, (200, 2))
    bounded, unbounded = _caustic_estimates(device, tree, inside, 32)
    np.testing.assert_array_equal(bounded, unbounded)  # k photons lie well within the reach
    assert abs(bounded.mean() / 50.0 - 1.0) < 0.05
    reach = cut.CAUSTIC_REACH * tree.radius
    far = np.array([[0.05 + 2 * reach, 0.0, 0.0], [0.0, -0.05 - 1.5 * reach, 0.0]], np.float32)
    bounded, unbounded = _caustic_estimates(device, tree, far, 32)
    assert (unbounded[:, 0] > 0).all()  # the unbounded search reaches the caustic and smears it out
    assert (bounded == 0).all()
