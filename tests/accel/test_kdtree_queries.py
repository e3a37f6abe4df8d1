"""Kd-tree closest-hit and any-hit queries against a float64 brute force.

The oracle intersects every ray with every triangle in float64 (from the
same float32 inputs). A hit is *certain* when the ray passes inside the
triangle by more than a sliver, *possible* when it passes within a sliver
of an edge: the kd-tree must report the closest certain hit, may report a
possible one at the same distance (ties, grazing edges), and may miss only
where nothing is certain.
"""

from __future__ import annotations

import numpy as np
import pytest

from gpu_core.accel import kdtree

SLIVER = 1e-5  # barycentric margin of the "possible" band around each edge
REL_T = 1e-4  # relative tolerance on distances
ULPS = 2.0**-20  # ... or 16 float32 steps of the coordinates, for hits near the origin


def oracle_hits(tris, org, dirs, t_min, t_max):
    """(R, N) float64 distances of certain and of possible hits (inf where none)."""
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    org = np.asarray(org, np.float64)
    dirs = np.asarray(dirs, np.float64)
    r, n = len(org), len(tris)
    certain = np.full((r, n), np.inf)
    possible = np.full((r, n), np.inf)
    if n == 0:
        return certain, possible
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    for start in range(0, r, 256):
        o = org[start : start + 256, None, :]
        d = dirs[start : start + 256, None, :]
        p = np.cross(d, e2)
        det = (e1 * p).sum(-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0
            u = (s * p).sum(-1) * inv
            q = np.cross(s, e1)
            v = (d * q).sum(-1) * inv
            t = (e2 * q).sum(-1) * inv
            w = 1.0 - u - v
        lo, hi = np.asarray(t_min)[start : start + 256, None], np.asarray(t_max)[start : start + 256, None]
        live = (det != 0) & (t > lo) & (t < hi)
        edge = np.minimum(np.minimum(u, v), w)
        certain[start : start + 256] = np.where(live & (edge >= SLIVER), t, np.inf)
        possible[start : start + 256] = np.where(live & (edge >= -SLIVER), t, np.inf)
    return certain, possible


def default_t_min(tree, org, dirs):
    scale = np.maximum(np.abs(org).max(axis=1), tree.magnitude)
    return kdtree.SELF_HIT_SCALE * scale / np.linalg.norm(np.asarray(dirs, np.float64), axis=1)


def assert_closest_hits(tree, tris, org, dirs, t_max=None):
    """The tree's closest hits agree with the oracle; returns the number of certain hits."""
    org = np.asarray(org, np.float32)
    dirs = np.asarray(dirs, np.float32)
    t, tri = tree.intersect(org, dirs, t_max)
    t_min = default_t_min(tree, org, dirs)
    limit = np.full(len(org), np.inf) if t_max is None else np.broadcast_to(t_max, (len(org),))
    certain, possible = oracle_hits(tris, org, dirs, t_min, limit)
    best = certain.min(axis=1)
    rows = np.arange(len(org))
    scale = np.maximum(np.abs(org).max(axis=1), tree.magnitude) / np.linalg.norm(dirs.astype(np.float64), axis=1)
    # a hit: on a possible triangle, at that triangle's distance, no farther than the best certain hit
    hit = tri >= 0
    mine = np.where(hit, possible[rows, np.maximum(tri, 0)], np.inf)
    bad_tri = hit & ~np.isfinite(mine)
    with np.errstate(invalid="ignore"):
        tol = np.maximum(REL_T * np.abs(mine), ULPS * scale)
        bad_t = hit & np.isfinite(mine) & (np.abs(t - mine) > tol)
        too_far = hit & np.isfinite(best) & (t > best + np.maximum(REL_T * best, ULPS * scale))
    missed = ~hit & np.isfinite(best)
    for name, bad in [("not hit by that triangle", bad_tri), ("wrong distance", bad_t),
                      ("not the closest", too_far), ("missed", missed)]:
        assert not bad.any(), f"{bad.sum()} rays {name}: first {np.flatnonzero(bad)[:5]}"
    # where the closest hit is unique and certain, it is the same triangle
    unique = np.isfinite(best) & ((possible <= best[:, None] * (1 + 2 * REL_T)).sum(axis=1) == 1)
    assert (tri[unique] == certain[unique].argmin(axis=1)).all()
    return int(np.isfinite(best).sum())


def assert_any_hits(tree, tris, org, dirs, t_max):
    org = np.asarray(org, np.float32)
    dirs = np.asarray(dirs, np.float32)
    blocked = tree.occluded(org, dirs, t_max)
    t_min = default_t_min(tree, org, dirs)
    certain, possible = oracle_hits(tris, org, dirs, t_min, np.broadcast_to(t_max, (len(org),)))
    must = np.isfinite(certain).any(axis=1)
    may = np.isfinite(possible).any(axis=1)
    assert (blocked[must]).all(), f"{(~blocked & must).sum()} blocked rays reported free"
    assert not (blocked & ~may).any(), f"{(blocked & ~may).sum()} free rays reported blocked"
    return int(must.sum())


# ---- scenes ----------------------------------------------------------------

def random_soup(n, seed=0, size=0.05):
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-1.0, 1.0, (n, 1, 3))
    return (centers + rng.normal(0.0, size, (n, 3, 3))).astype(np.float32)


def box_triangles(lo, hi):
    """12 triangles of an axis-aligned box, outward winding."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    c = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    out = []
    for a, b, cc, d in quads:
        out += [(c[a], c[b], c[cc]), (c[a], c[cc], c[d])]
    return np.array(out, np.float32)


def boxes(count, seed=0):
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(count):
        lo = rng.uniform(-1, 0.8, 3).round(2)
        parts.append(box_triangles(lo, lo + rng.uniform(0.05, 0.4, 3).round(2)))
    return np.concatenate(parts)


def grid(n, z=0.0):
    """A closed-edge grid of 2 n^2 triangles over [-1, 1]^2 at height z."""
    xs = np.linspace(-1.0, 1.0, n + 1)
    out = []
    for i in range(n):
        for j in range(n):
            a, b = (xs[i], xs[j], z), (xs[i + 1], xs[j], z)
            c, d = (xs[i + 1], xs[j + 1], z), (xs[i], xs[j + 1], z)
            out += [(a, b, c), (a, c, d)]
    return np.array(out, np.float32)


def random_rays(n, seed=1, spread=1.5):
    rng = np.random.default_rng(seed)
    org = rng.uniform(-spread, spread, (n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3)).astype(np.float32)
    return org, dirs


def rays_at(tris, n, seed=2, distance=3.0):
    """Rays from random far points towards random points on the triangles."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(tris), n)
    w = rng.dirichlet((1, 1, 1), n)
    target = (w[:, :, None] * tris[pick].astype(np.float64)).sum(axis=1)
    span = float(np.abs(tris).max())
    org = target + rng.normal(size=(n, 3)) * distance * span
    return org.astype(np.float32), (target - org).astype(np.float32)


# ---- closest hits ------------------------------------------------------------

def test_random_soup_hits_match_brute_force(device):
    tris = random_soup(3000)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(3000)
    assert assert_closest_hits(tree, tris, org, dirs) > 500
    org, dirs = rays_at(tris, 2000)
    assert assert_closest_hits(tree, tris, org, dirs) > 1500


def test_large_overlapping_triangles_hit_like_brute_force(device):
    # big triangles spanning the whole scene: every split duplicates most of them
    tris = random_soup(400, seed=3, size=0.8)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=4)
    assert assert_closest_hits(tree, tris, org, dirs) > 1000


def test_axis_aligned_boxes_hit_like_brute_force(device):
    tris = boxes(60)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=5)
    assert assert_closest_hits(tree, tris, org, dirs) > 300
    org, dirs = rays_at(tris, 2000, seed=6)
    assert assert_closest_hits(tree, tris, org, dirs) > 1500


def test_rays_along_each_axis_hit_like_brute_force(device):
    tris = np.concatenate([boxes(40, seed=7), grid(8, z=0.25)])
    tree = kdtree.build(device, tris)
    rng = np.random.default_rng(8)
    org = rng.uniform(-1.2, 1.2, (3000, 3)).round(2).astype(np.float32)  # often on box faces and edges
    axes = np.concatenate([np.eye(3), -np.eye(3)]).astype(np.float32)
    dirs = axes[rng.integers(0, 6, 3000)]
    assert assert_closest_hits(tree, tris, org, dirs) > 500


def test_parallel_rays_hit_like_brute_force(device):
    tris = random_soup(2000, seed=9)
    tree = kdtree.build(device, tris)
    u = np.linspace(-1.2, 1.2, 60)
    gx, gy = np.meshgrid(u, u)
    org = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 3.0)], axis=1).astype(np.float32)
    dirs = np.broadcast_to(np.array([0.3, -0.2, -1.0], np.float32), org.shape)
    assert assert_closest_hits(tree, tris, org, dirs) > 800


def test_coplanar_overlapping_triangles_hit_at_the_shared_distance(device):
    rng = np.random.default_rng(10)
    layers = []
    for z in (-0.5, 0.0, 0.5):
        c = rng.uniform(-1, 1, (150, 1, 2))
        xy = c + rng.normal(0, 0.3, (150, 3, 2))
        layers.append(np.concatenate([xy, np.full((150, 3, 1), z)], axis=2))
    tris = np.concatenate(layers).astype(np.float32)
    tris = np.concatenate([tris, tris[:100]])  # exact duplicates too
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=11)
    assert assert_closest_hits(tree, tris, org, dirs) > 500


def test_all_triangles_in_one_plane(device):
    tris = random_soup(1500, seed=12, size=0.1)
    tris[:, :, 2] = 0.25
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=13)
    assert assert_closest_hits(tree, tris, org, dirs) > 200
    # rays inside the plane hit nothing
    org[:, 2] = 0.25
    dirs[:, 2] = 0.0
    t, tri = tree.intersect(org, dirs)
    assert (tri == -1).all() and np.isinf(t).all()


def test_zero_area_triangles_are_never_hit(device):
    good = random_soup(600, seed=14)
    rng = np.random.default_rng(15)
    points = np.repeat(rng.uniform(-1, 1, (200, 1, 3)), 3, axis=1)  # all corners equal
    base = rng.uniform(-1, 1, (200, 1, 3))
    step = rng.uniform(-0.1, 0.1, (200, 1, 3)).round(3)
    lines = base + np.array([0.0, 1.0, 2.0])[None, :, None] * step  # collinear corners
    tris = np.concatenate([good, points, lines]).astype(np.float32)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=16)
    assert assert_closest_hits(tree, tris, org, dirs) > 100
    t, tri = tree.intersect(org, dirs)
    assert (tri < len(good)).all()


def test_only_degenerate_triangles_build_and_miss(device):
    tris = np.zeros((500, 3, 3), np.float32)  # 500 triangles collapsed to one point
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(500, seed=17)
    t, tri = tree.intersect(org, dirs)
    assert (tri == -1).all()
    assert tree.stats["leaves"] >= 1


def test_one_triangle(device):
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32)
    tree = kdtree.build(device, tris)
    org = np.array([[0.25, 0.25, 1.0], [0.9, 0.9, 1.0], [0.25, 0.25, -1.0]], np.float32)
    dirs = np.array([[0, 0, -1], [0, 0, -1], [0, 0, -2]], np.float32)
    t, tri, uv = tree.intersect(org, dirs, barycentrics=True)
    np.testing.assert_array_equal(tri, [0, -1, -1])
    assert t[0] == pytest.approx(1.0, rel=1e-6) and np.isinf(t[1])
    np.testing.assert_allclose(uv[0], [0.25, 0.25], rtol=1e-6)
    org2, dirs2 = random_rays(1000, seed=18)
    assert assert_closest_hits(tree, tris, org2, dirs2) > 0


def test_zero_triangles_miss_everything(device):
    tree = kdtree.build(device, np.zeros((0, 3, 3), np.float32))
    org, dirs = random_rays(100, seed=19)
    t, tri = tree.intersect(org, dirs)
    assert (tri == -1).all() and np.isinf(t).all()
    assert not tree.occluded(org, dirs, 10.0).any()
    assert tree.stats["nodes"] == 1 and tree.stats["leaves"] == 1


def test_empty_ray_batch(device):
    tree = kdtree.build(device, random_soup(10))
    t, tri = tree.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert t.shape == (0,) and tri.shape == (0,)


@pytest.mark.parametrize("scale,offset", [(1e5, 0.0), (1e-4, 0.0), (1e2, 1e5), (1e-4, 1.0)])
def test_extreme_coordinates_hit_like_brute_force(device, scale, offset):
    base = random_soup(1500, seed=20)
    tris = (base.astype(np.float64) * scale + offset).astype(np.float32)
    tree = kdtree.build(device, tris)
    org, dirs = rays_at(tris - np.float32(offset), 1500, seed=21)
    org = (org.astype(np.float64) + offset).astype(np.float32)
    assert assert_closest_hits(tree, tris, org, dirs) > 1000
    org, dirs = random_rays(1500, seed=22)
    org = (org.astype(np.float64) * scale + offset).astype(np.float32)
    assert assert_closest_hits(tree, tris, org, dirs) > 100


def test_rays_starting_on_a_surface_do_not_hit_it(device):
    tris = np.concatenate([boxes(30, seed=23), random_soup(800, seed=24)])
    tree = kdtree.build(device, tris)
    rng = np.random.default_rng(25)
    pick = rng.integers(0, len(tris), 3000)
    w = rng.dirichlet((2, 2, 2), 3000)
    org = (w[:, :, None] * tris[pick].astype(np.float64)).sum(axis=1).astype(np.float32)
    dirs = rng.normal(size=(3000, 3)).astype(np.float32)
    assert assert_closest_hits(tree, tris, org, dirs) > 500
    # away from grazing angles, where the float32 origin's rounding off the
    # plane can make a true second crossing, no ray hits its own triangle
    t, tri = tree.intersect(org, dirs)
    v = tris[pick].astype(np.float64)
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    cos = np.abs((normal * dirs).sum(1)) / np.linalg.norm(normal, axis=1) / np.linalg.norm(dirs, axis=1)
    steep = cos > 0.05
    assert steep.sum() > 2500
    assert not (tri == pick)[steep].any()


def test_barycentrics_give_the_hit_point(device):
    tris = random_soup(1000, seed=26)
    tree = kdtree.build(device, tris)
    org, dirs = rays_at(tris, 1000, seed=27)
    t, tri, uv = tree.intersect(org, dirs, barycentrics=True)
    hit = tri >= 0
    corners = tris[tri[hit]].astype(np.float64)
    u, v = uv[hit, 0:1], uv[hit, 1:2]
    point = (1 - u - v) * corners[:, 0] + u * corners[:, 1] + v * corners[:, 2]
    expected = org[hit] + t[hit, None] * dirs[hit].astype(np.float64)
    assert hit.sum() > 900
    assert (uv[hit] >= -1e-6).all() and (uv[hit].sum(axis=1) <= 1 + 1e-6).all()
    np.testing.assert_allclose(point, expected, atol=1e-4)


def test_t_max_limits_closest_hits(device):
    tris = random_soup(1500, seed=28)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(2000, seed=29)
    assert assert_closest_hits(tree, tris, org, dirs, t_max=0.7) > 100


def test_a_given_t_min_skips_the_surfaces_before_it(device):
    # two unit squares at z = 1 and z = 2 over rays going up from z = 0
    square = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], np.float32)
    tree = kdtree.build(device, np.concatenate([square + [0, 0, 1], square + [0, 0, 2]]))
    rng = np.random.default_rng(30)
    org = np.column_stack([rng.uniform(-0.9, 0.9, (500, 2)), np.zeros(500)]).astype(np.float32)
    dirs = np.tile(np.float32([0, 0, 1]), (500, 1))
    np.testing.assert_allclose(tree.intersect(org, dirs)[0], 1.0)
    np.testing.assert_allclose(tree.intersect(org, dirs, t_min=1.5)[0], 2.0)  # one start for all
    starts = np.where(np.arange(500) % 2 == 0, 0.5, 1.5).astype(np.float32)  # one start a ray
    np.testing.assert_allclose(tree.intersect(org, dirs, t_min=starts)[0], np.where(starts < 1, 1.0, 2.0))
    np.testing.assert_array_equal(tree.occluded(org, dirs, np.inf, t_min=2.5), False)
    np.testing.assert_array_equal(tree.occluded(org, dirs, np.inf, t_min=starts), True)


def test_the_default_t_min_is_the_coordinates_scale_over_the_direction_length(device):
    # a ray from a surface point just past its own surface: the default start
    # (SELF_HIT_SCALE x the coordinates' scale / |dir|) skips it, a start of 0 does not
    tris = random_soup(300, seed=31)
    tree = kdtree.build(device, tris)
    rng = np.random.default_rng(32)
    weights = rng.dirichlet([1, 1, 1], 300).astype(np.float32)
    points = np.einsum("nk,nkj->nj", weights, tris)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    dirs = (normals * rng.uniform(0.5, 4.0, (300, 1))).astype(np.float32)  # lengths differ
    t_self = default_t_min(tree, points, dirs)
    rows = np.arange(300)
    from_zero = tree.intersect(points, dirs, t_min=np.zeros(300, np.float32))[1]
    assert (from_zero == rows).sum() > 30  # a start of 0 finds some rays' own triangle at their origin
    tri_default = tree.intersect(points, dirs)[1]
    assert not (tri_default == rows).any()
    np.testing.assert_array_equal(tree.intersect(points, dirs, t_min=t_self)[1], tri_default)


# ---- watertightness ------------------------------------------------------------

def test_rays_through_shared_edges_and_corners_never_slip_through(device):
    tris = grid(16)
    tree = kdtree.build(device, tris)
    # every corner and every edge midpoint of the grid, from random points above
    xs = np.linspace(-1.0, 1.0, 17)[1:-1]
    gx, gy = np.meshgrid(xs, xs)
    mids = np.linspace(-1.0, 1.0, 33)[1:-1]
    mx, my = np.meshgrid(mids, mids)
    targets = np.concatenate([np.stack([gx.ravel(), gy.ravel()], 1), np.stack([mx.ravel(), my.ravel()], 1)])
    targets = np.concatenate([targets, np.zeros((len(targets), 1))], axis=1)
    rng = np.random.default_rng(30)
    for _ in range(4):
        org = targets + rng.normal(0, 0.7, targets.shape) + [0.0, 0.0, 2.0]
        dirs = (targets - org).astype(np.float32)
        t, tri = tree.intersect(org.astype(np.float32), dirs)
        assert (tri >= 0).all(), f"{(tri < 0).sum()} rays slipped through the grid"
    # axis-aligned rays straight down onto corners and edges
    org = (targets + [0.0, 0.0, 1.0]).astype(np.float32)
    t, tri = tree.intersect(org, np.tile(np.float32([0, 0, -1]), (len(org), 1)))
    assert (tri >= 0).all()
    np.testing.assert_allclose(t, 1.0, rtol=1e-6)


def test_rays_from_inside_a_closed_box_always_hit_it(device):
    tris = box_triangles([-1, -1, -1], [1, 1, 1])
    tree = kdtree.build(device, tris)
    rng = np.random.default_rng(31)
    org = rng.uniform(-0.9, 0.9, (4000, 3)).astype(np.float32)
    corners = rng.choice([-1.0, 1.0], (4000, 3))  # aim at the box corners and edges
    corners[::2, rng.integers(0, 3)] = 0.0
    dirs = (corners - org).astype(np.float32)
    t, tri = tree.intersect(org, dirs)
    assert (tri >= 0).all()


# ---- any hits ----------------------------------------------------------------------

def test_occluded_matches_brute_force(device):
    tris = np.concatenate([boxes(30, seed=32), random_soup(1000, seed=33)])
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(3000, seed=34)
    assert assert_any_hits(tree, tris, org, dirs, 0.5) > 300
    org, dirs = rays_at(tris, 2000, seed=35)
    assert assert_any_hits(tree, tris, org, dirs, 0.9) > 300


def test_occluded_agrees_with_intersect(device):
    tris = random_soup(2000, seed=36)
    tree = kdtree.build(device, tris)
    org, dirs = random_rays(3000, seed=37)
    t, tri = tree.intersect(org, dirs)
    limit = np.where(np.isfinite(t), t, 1.0)
    # shorter than the closest hit: free; longer: blocked
    assert not tree.occluded(org, dirs, limit * 0.999).any()
    np.testing.assert_array_equal(tree.occluded(org, dirs, np.where(tri >= 0, t * 1.001, 1e30)), tri >= 0)
