"""Leaf blocks of the triangle kd-tree (kdtree_blocks.py): their layout
against the leaf lists and corners read back, and the traversal that tests
a block's four triangles at once against the one that tests them one at a
time, hit for hit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gpu_core.accel import kdtree, kdtree_blocks, kdtree_overlay
from gpu_core.device.constants import KD_BLOCK_LANES, KD_BLOCK_ROWS
from test_kdtree_queries import boxes, grid, random_rays, random_soup, rays_at


def expected_blocks(nodes, leaf_tris, tris):
    """Each leaf's blocks built on the host: (first block, (B, ROWS, 4) rows) per leaf, in node order."""
    out = []
    for node in nodes[nodes["axis"] == kdtree.LEAF]:
        ids = leaf_tris[node["child"] : node["child"] + node["count"]]
        rows = []
        for start in range(0, len(ids), KD_BLOCK_LANES):
            lane_ids = np.full(KD_BLOCK_LANES, -1, np.int32)
            lane_ids[: len(ids[start : start + KD_BLOCK_LANES])] = ids[start : start + KD_BLOCK_LANES]
            corners = np.zeros((KD_BLOCK_LANES, 3, 3), np.float32)
            corners[lane_ids >= 0] = tris[lane_ids[lane_ids >= 0]]
            block = np.zeros((KD_BLOCK_ROWS, KD_BLOCK_LANES), np.float32)
            block[:9] = corners.reshape(KD_BLOCK_LANES, 9).T  # v0.x, v0.y, v0.z, v1.x, ... a lane a triangle
            block[9] = lane_ids.view(np.float32)
            rows.append(block)
        out.append((int(np.float32(node["split"]).view(np.int32)), np.array(rows, np.float32).reshape(-1, KD_BLOCK_ROWS, 4)))
    return out


@pytest.mark.parametrize("make", [lambda: random_soup(2000), lambda: boxes(30), lambda: grid(12)],
                         ids=["soup", "boxes", "grid"])
def test_each_leaf_holds_its_triangles_four_to_a_block_from_the_first_block_in_its_split(device, make):
    tris = make()
    tree = kdtree.build(device, tris, blocks=True)
    nodes, leaf_tris = tree.nodes_host()
    blocks = device.get(tree.blocks).reshape(-1, KD_BLOCK_ROWS, 4)
    assert len(blocks) == tree.stats["blocks"] == sum(-(-int(c) // KD_BLOCK_LANES) for c in nodes["count"][nodes["axis"] == kdtree.LEAF])
    covered = np.zeros(len(blocks), bool)
    for first, rows in expected_blocks(nodes, leaf_tris, tris):
        np.testing.assert_array_equal(blocks[first : first + len(rows)].view(np.int32), rows.view(np.int32))
        assert not covered[first : first + len(rows)].any()  # no block serves two leaves
        covered[first : first + len(rows)] = True
    assert covered.all()


def random_cases():
    soup = random_soup(3000, seed=7)
    yield "soup", soup, random_rays(4000, seed=8)
    yield "soup aimed", soup, rays_at(soup, 3000, seed=9)
    box = boxes(40, seed=3)
    yield "boxes", box, random_rays(4000, seed=10)
    flat = grid(16)
    yield "grid", flat, rays_at(flat, 3000, seed=11)
    # coplanar overlapping copies (equal distances: the lowest lane and the list's first must agree)
    stack = np.concatenate([flat, flat[::-1], flat + np.float32([0.01, 0.0, 0.0])])
    yield "coplanar stack", stack, rays_at(flat, 3000, seed=12)
    # zero-area triangles among the others
    line = soup.copy()
    line[::5, 2] = line[::5, 0]
    yield "degenerate", line, random_rays(3000, seed=13)


@pytest.mark.parametrize("name, tris, rays", list(random_cases()), ids=[case[0] for case in random_cases()])
def test_blocks_find_the_same_hits_as_triangles_one_at_a_time_bit_for_bit(device, name, tris, rays):
    # the same tree traced both ways (a tree built without blocks weighs its nodes otherwise)
    blocked = kdtree.build(device, tris, blocks=True)
    plain = dataclasses.replace(blocked, blocks=None)
    assert blocked.blocks is not None
    org, dirs = rays
    t, tri, uv = blocked.intersect(org, dirs, barycentrics=True)
    t0, tri0, uv0 = plain.intersect(org, dirs, barycentrics=True)
    assert (tri >= 0).sum() > len(org) // 10  # the rays hit something
    np.testing.assert_array_equal(tri, tri0)
    np.testing.assert_array_equal(t.view(np.int32), t0.view(np.int32))
    np.testing.assert_array_equal(uv.view(np.int32), uv0.view(np.int32))
    for t_max in (0.5, 2.0):
        np.testing.assert_array_equal(blocked.occluded(org, dirs, t_max), plain.occluded(org, dirs, t_max))


def test_an_overlay_tree_blocks_its_joined_leaves_with_moved_triangles_left_empty(device):
    tris = random_soup(3000)
    rows = np.arange(400, 700)
    now = tris.copy()
    now[rows] += np.float32([0.3, 0.0, -0.2])
    joined = {blocks: kdtree_overlay.overlay(device, kdtree.build(device, tris, blocks=blocks), rows, now[rows])
              for blocks in (True, False)}
    assert joined[True].blocks is not None and joined[False].blocks is None
    nodes, leaf_tris = joined[True].nodes_host()
    blocks = device.get(joined[True].blocks).reshape(-1, KD_BLOCK_ROWS, 4)
    for first, expect in expected_blocks(nodes, leaf_tris, now):
        np.testing.assert_array_equal(blocks[first : first + len(expect)].view(np.int32), expect.view(np.int32))
    ids = blocks[:, 9].view(np.int32)
    assert (np.isin(rows, ids[ids >= 0])).all()  # the moved triangles, in the overlay's leaves
    org, dirs = rays_at(now[rows], 2000)
    a, b = joined[True].intersect(org, dirs), joined[False].intersect(org, dirs)
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[0], b[0])


def test_a_tree_whose_blocks_would_outgrow_the_limit_tests_its_triangles_one_at_a_time(device, monkeypatch):
    tris = random_soup(1500)
    monkeypatch.setattr(kdtree_blocks, "MAX_BYTES", 10 * kdtree_blocks.BLOCK_BYTES)
    tree = kdtree.build(device, tris, blocks=True)
    assert tree.blocks is None and tree.stats["blocks"] == 0
    nodes, _ = tree.nodes_host()
    assert (nodes["split"][nodes["axis"] == kdtree.LEAF] == 0.0).all()  # the nodes are as built
    org, dirs = random_rays(2000)
    plain = kdtree.build(device, tris, blocks=False)
    np.testing.assert_array_equal(tree.intersect(org, dirs)[1], plain.intersect(org, dirs)[1])


def test_trees_get_blocks_by_default_on_a_cpu_device_only(device):
    tree = kdtree.build(device, random_soup(200))
    assert (tree.blocks is not None) == device.is_cpu == kdtree_blocks.wanted(device)
