"""Overlay trees (a base tree joined with a tree over the triangles moved
since) against the float64 brute force of test_kdtree_queries, and the
rule that decides when an overlay will do."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpu_core.accel import kdtree, kdtree_overlay
from test_kdtree_queries import (assert_any_hits, assert_closest_hits, boxes, random_rays, random_soup,
                                 rays_at)


def moved(tris, rows, offset):
    """``tris`` with the triangles of ``rows`` shifted by ``offset``."""
    out = np.array(tris, np.float32)
    out[rows] += np.asarray(offset, np.float32)
    return out


@pytest.fixture(scope="module")
def soup_base(device):
    tris = random_soup(3000)
    return tris, kdtree.build(device, tris)


def test_moved_rows_are_the_triangles_that_differ(soup_base):
    tris, _ = soup_base
    rows = np.arange(100, 160)
    assert (kdtree_overlay.moved_rows(tris, moved(tris, rows, (0.3, 0, 0))) == rows).all()
    assert len(kdtree_overlay.moved_rows(tris, tris.copy())) == 0


def test_moved_rows_ask_for_a_whole_build_past_the_share_or_without_a_base(soup_base):
    tris, _ = soup_base
    too_many = np.arange(int(kdtree_overlay.OVERLAY_SHARE * len(tris)) + 1)
    assert kdtree_overlay.moved_rows(tris, moved(tris, too_many, (0.1, 0, 0))) is None
    assert kdtree_overlay.moved_rows(None, tris) is None
    assert kdtree_overlay.moved_rows(tris[:-1], tris) is None  # another triangle count


def test_an_overlay_tree_hits_like_brute_force_after_a_move(device, soup_base):
    tris, base = soup_base
    rows = np.arange(500, 800)
    now = moved(tris, rows, (0.4, -0.2, 0.1))
    tree = kdtree_overlay.overlay(device, base, rows, now[rows])
    assert tree.base is base and tree.stats["overlay_triangles"] == len(rows)
    org, dirs = random_rays(3000)
    assert assert_closest_hits(tree, now, org, dirs) > 500
    org, dirs = rays_at(now[rows], 1500)  # aimed at the moved triangles
    assert assert_closest_hits(tree, now, org, dirs) > 1000
    assert assert_any_hits(tree, now, *random_rays(2000, seed=5), 1.0) > 200


def test_the_base_tree_alone_misses_where_the_moved_triangles_went(device, soup_base):
    # the oracle check above can fail: the base, read with the moved corners, misses them
    tris, base = soup_base
    rows = np.arange(500, 800)
    now = moved(tris, rows, (2.5, 0, 0))  # out of the base's root box
    stale = kdtree.KdTree(device, base.nodes, base.leaf_tris, kdtree.build(device, now).verts, base.bmin, base.bmax,
                          len(now), base.stats)
    org, dirs = rays_at(now[rows], 500)
    with pytest.raises(AssertionError):
        assert_closest_hits(stale, now, org, dirs)


def test_moved_triangles_are_not_found_through_their_old_cells(device, soup_base):
    # rays at where the moved triangles were: the base lists them there, but they are gone
    tris, base = soup_base
    rows = np.arange(0, 400)
    now = moved(tris, rows, (0, 0, 3.0))
    tree = kdtree_overlay.overlay(device, base, rows, now[rows])
    org, dirs = rays_at(tris[rows], 1500, seed=7)
    assert_closest_hits(tree, now, org, dirs)
    nodes, leaf_tris = tree.nodes_host()
    listed = leaf_tris[leaf_tris >= 0]
    assert np.isin(rows, listed).all() and (leaf_tris == -1).sum() > 0


def test_an_overlay_over_boxes_moved_far_away_hits_like_brute_force(device):
    # a moved part far outside the base's box, and rays along the axes through both
    tris = boxes(60, seed=3)
    base = kdtree.build(device, tris)
    rows = np.arange(36, 72)
    now = moved(tris, rows, (5.0, 0.0, -3.0))
    tree = kdtree_overlay.overlay(device, base, rows, now[rows])
    for axis in range(3):
        org, dirs = random_rays(800, seed=10 + axis, spread=6.0)
        dirs[:] = 0.0
        dirs[:, axis] = np.where(np.arange(800) % 2, 1.0, -1.0)
        assert_closest_hits(tree, now, org, dirs)
    assert assert_closest_hits(tree, now, *rays_at(now, 2000, seed=11)) > 1500


def test_an_overlay_with_nothing_moved_is_the_base(device, soup_base):
    tris, base = soup_base
    assert kdtree_overlay.overlay(device, base, np.zeros(0, np.int32), tris[:0]) is base


def test_an_overlay_keeps_the_tree_statistics_honest(device, soup_base):
    tris, base = soup_base
    rows = np.arange(10, 50)
    tree = kdtree_overlay.overlay(device, base, rows, moved(tris, rows, (0.1, 0.1, 0.1))[rows])
    nodes, leaf_tris = tree.nodes_host()
    assert len(nodes) == tree.stats["nodes"] == base.stats["nodes"] + tree.stats["overlay_nodes"] + 1
    assert np.isnan(nodes["split"][0]) and nodes["child"][0] == base.stats["nodes"] + 1
    assert len(leaf_tris) == tree.stats["leaf_references"]
    assert tree.stats["depth"] <= kdtree.MAX_DEPTH


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(count=st.integers(2, 400), share=st.floats(0.0, kdtree_overlay.OVERLAY_SHARE), seed=st.integers(0, 2**31),
       scale=st.sampled_from([1e-3, 1.0, 1e3]), shift=st.sampled_from([0.01, 0.5, 3.0]))
def test_random_moves_hit_what_a_tree_built_afresh_hits(device, count, share, seed, scale, shift):
    # soups at several scales (in the device frame: the renderer centres the scene), a random
    # part of them moved near or far; the same triangle test, so the same closest distances
    rng = np.random.default_rng(seed)
    tris = (random_soup(count, seed=seed % 1000, size=0.2) * scale).astype(np.float32)
    base = kdtree.build(device, tris)
    rows = np.sort(rng.choice(count, int(share * count), replace=False)).astype(np.int32)
    now = moved(tris, rows, rng.normal(size=3) * shift * scale)
    assert (kdtree_overlay.moved_rows(tris, now) == rows).all()
    tree, fresh = kdtree_overlay.overlay(device, base, rows, now[rows]), kdtree.build(device, now)
    for org, dirs in (rays_at(now, 300, seed=seed % 997), random_rays(300, seed=seed % 991, spread=1.5 * scale)):
        t, tri = tree.intersect(org, dirs)
        t_fresh, tri_fresh = fresh.intersect(org, dirs)
        np.testing.assert_array_equal(t, t_fresh)
        assert (tri == tri_fresh).mean() > 0.99  # equal distances may name either triangle
