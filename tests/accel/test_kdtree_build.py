"""Invariants of built kd-trees, read back from the device.

The node array is walked on the host from the root box down through the
split planes: the preorder layout must be a tree that reaches every node
once, every plane must lie inside its node's cell, every triangle that
reaches into a leaf's cell must be listed in that leaf, and ``stats`` must
agree with what the walk counts.
"""

from __future__ import annotations

import numpy as np
import pytest
from pyopencl import cltypes

from gpu_core.accel import kdtree, kdtree_build
from gpu_core.accel.kdtree_build import (BAD_SPLITS, COST_TRAVERSE_BLOCKS, SAH_GROUP, SMALL, build_tree, cost_traverse,
                                         depth_limit)

MARGIN = 1e-5  # leaf cells shrink by this fraction of the scene size before the overlap test


# ---- scenes -------------------------------------------------------------------------------


def random_soup(n, seed=0, size=0.05):
    """``n`` random triangles of about ``size`` in the unit cube."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n, 1, 3))
    return (centres + size * rng.standard_normal((n, 3, 3))).astype(np.float32)


def sphere(rings=40, segments=60):
    """A closed UV sphere of radius 1 (2 * rings * segments triangles, some degenerate at the poles)."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pts = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    a, b = pts[:-1, :-1], pts[:-1, 1:]
    c, d = pts[1:, :-1], pts[1:, 1:]
    return np.concatenate([np.stack([a, c, d], -2), np.stack([a, d, b], -2)]).reshape(-1, 3, 3).astype(np.float32)


def box_grid(k=6):
    """Axis-aligned cubes on a grid: many triangles lying exactly in candidate planes."""
    faces = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for side in (0.0, 1.0):
            quad = np.zeros((4, 3))
            quad[:, axis] = side
            quad[:, u] = [0, 1, 1, 0]
            quad[:, v] = [0, 0, 1, 1]
            faces += [quad[[0, 1, 2]], quad[[0, 2, 3]]]
    cube = np.array(faces) * 0.6
    offsets = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), -1).reshape(-1, 1, 1, 3)
    return (cube[None] + offsets).reshape(-1, 3, 3).astype(np.float32)


def big_and_small():
    """A few large triangles across the scene among many small ones (clipping in the large stage)."""
    rng = np.random.default_rng(3)
    big = (rng.random((8, 3, 3)) * 2.0 - 0.5).astype(np.float32)
    return np.concatenate([big, random_soup(1500, seed=4, size=0.02)])


def fan(n, height=0.2):
    """``n`` triangles around one vertex (a cone's side: a UV sphere's pole, a cylinder's cap)."""
    a = np.linspace(0.0, 2.0 * np.pi, n + 1)
    ring = np.stack([np.cos(a), np.sin(a), np.full_like(a, height)], -1)
    return np.stack([np.zeros((n, 3)), ring[:-1], ring[1:]], 1).astype(np.float32)


def stack(n):
    """``n`` copies of one triangle, each a micron above the last."""
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return (tri[None] + np.linspace(0.0, 1e-6 * n, n)[:, None, None] * [0, 0, 1]).astype(np.float32)


SCENES = {
    "random_soup": lambda: random_soup(2000),
    "fan": lambda: fan(300),
    "stack": lambda: stack(200),
    "sphere": sphere,
    "box_grid": box_grid,
    "big_and_small": big_and_small,
    "few_triangles": lambda: random_soup(40, seed=5),
}


@pytest.fixture(scope="module", params=[(name, blocks) for name in sorted(SCENES) for blocks in (True, False)],
                ids=lambda p: f"{p[0]}-{'blocks' if p[1] else 'one_by_one'}")
def built(request, device):
    """A scene and its tree, built for leaves tested from blocks or one triangle at a time (the SAH differs)."""
    name, blocks = request.param
    tris = SCENES[name]()
    return tris, kdtree.build(device, tris, blocks=blocks)


# ---- host walk of the node array ----------------------------------------------------------


def walk(tree):
    """Visit the tree from the root cell: per node its cell, depth and how often it was reached.

    Raises AssertionError on a child index out of range or on a cycle.
    """
    nodes, _ = tree.nodes_host()
    n = len(nodes)
    lo = np.zeros((n, 3))
    hi = np.zeros((n, 3))
    depth = np.zeros(n, int)
    reached = np.zeros(n, int)
    stack = [(0, tree.bmin[:3].astype(np.float64), tree.bmax[:3].astype(np.float64), 0)]
    while stack:
        i, cell_lo, cell_hi, d = stack.pop()
        assert 0 <= i < n, f"child index {i} outside the {n} nodes"
        reached[i] += 1
        assert reached[i] == 1, f"node {i} reached twice"
        lo[i], hi[i], depth[i] = cell_lo, cell_hi, d
        node = nodes[i]
        if node["axis"] == kdtree.LEAF:
            continue
        axis, split = int(node["axis"]), float(node["split"])
        assert axis in (0, 1, 2), f"node {i} has axis {axis}"
        left_hi, right_lo = cell_hi.copy(), cell_lo.copy()
        left_hi[axis] = right_lo[axis] = split
        stack.append((int(node["child"]), right_lo, cell_hi, d + 1))
        stack.append((i + 1, cell_lo, left_hi, d + 1))
    return nodes, lo, hi, depth, reached


def triangle_box_overlap(tris, lo, hi):
    """Whether each triangle meets the open box ``(lo, hi)`` (separating-axis test, float64).

    ``tris`` (M, 3, 3), ``lo`` and ``hi`` (M, 3): one triangle and one box per row.
    """
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    v = tris.astype(np.float64) - centre[:, None, :]
    edges = v[:, [1, 2, 0]] - v
    normal = np.cross(edges[:, 0], edges[:, 1])
    unit = np.eye(3)
    axes = [np.broadcast_to(unit[a], normal.shape) for a in range(3)] + [normal]
    axes += [np.cross(edges[:, e], unit[a]) for e in range(3) for a in range(3)]
    overlap = np.ones(len(tris), bool)
    for axis in axes:
        p = np.einsum("mvk,mk->mv", v, axis)
        r = (half * np.abs(axis)).sum(-1)
        nonzero = np.abs(axis).sum(-1) > 0
        separated = nonzero & ((p.min(-1) >= r) | (p.max(-1) <= -r))
        overlap &= ~separated
    return overlap


def unlisted_overlaps(tris, nodes, leaf_tris, lo, hi, margin):
    """(leaf, triangle) pairs where the triangle reaches into the leaf's cell but is not listed."""
    leaves = np.flatnonzero(nodes["axis"] == kdtree.LEAF)
    tri_lo, tri_hi = tris.min(axis=1), tris.max(axis=1)
    missing = []
    for leaf in leaves:
        cell_lo, cell_hi = lo[leaf] + margin, hi[leaf] - margin
        if np.any(cell_lo >= cell_hi):
            continue  # thinner than the margin
        near = np.flatnonzero(np.all((tri_lo < cell_hi) & (tri_hi > cell_lo), axis=1))
        if len(near) == 0:
            continue
        boxes_lo = np.broadcast_to(cell_lo, (len(near), 3))
        boxes_hi = np.broadcast_to(cell_hi, (len(near), 3))
        inside = near[triangle_box_overlap(tris[near], boxes_lo, boxes_hi)]
        start, count = int(nodes[leaf]["child"]), int(nodes[leaf]["count"])
        listed = set(leaf_tris[start : start + count].tolist())
        missing += [(int(leaf), int(t)) for t in inside if int(t) not in listed]
    return missing


def scene_margin(tree):
    return MARGIN * float(np.max(tree.bmax[:3] - tree.bmin[:3]))


# ---- tests ------------------------------------------------------------------------------


def test_preorder_layout_reaches_every_node_once(built):
    _, tree = built
    nodes, _, _, _, reached = walk(tree)
    assert len(nodes) == tree.stats["nodes"]
    assert np.all(reached == 1), f"{int((reached == 0).sum())} node(s) never reached"
    inner = np.flatnonzero(nodes["axis"] != kdtree.LEAF)
    assert np.all(nodes["child"][inner] > inner + 1), "a right child does not come after its left subtree"


def test_leaf_lists_are_in_range_and_hold_each_triangle_once(built):
    tris, tree = built
    nodes, leaf_tris = tree.nodes_host()
    leaves = nodes[nodes["axis"] == kdtree.LEAF]
    assert np.all(leaves["count"] >= 0)
    assert np.all(leaves["child"] >= 0) and np.all(leaves["child"] + leaves["count"] <= len(leaf_tris))
    for leaf in leaves:
        listed = leaf_tris[leaf["child"] : leaf["child"] + leaf["count"]]
        assert np.all((listed >= 0) & (listed < len(tris)))
        assert len(np.unique(listed)) == len(listed), "a leaf lists a triangle twice"


def test_split_planes_lie_inside_their_node_cell(built):
    _, tree = built
    nodes, lo, hi, _, _ = walk(tree)
    inner = np.flatnonzero(nodes["axis"] != kdtree.LEAF)
    axis = nodes["axis"][inner]
    split = nodes["split"][inner].astype(np.float64)
    cell_lo, cell_hi = lo[inner, axis], hi[inner, axis]
    outside = ~((cell_lo < split) & (split < cell_hi))
    bad = inner[outside]
    assert not outside.any(), f"{len(bad)} plane(s) on or outside their cell, first at node {bad[:1]}"


def test_every_triangle_reaching_into_a_leaf_cell_is_listed_there(built):
    tris, tree = built
    nodes, lo, hi, _, _ = walk(tree)
    _, leaf_tris = tree.nodes_host()
    missing = unlisted_overlaps(tris, nodes, leaf_tris, lo, hi, scene_margin(tree))
    assert not missing, f"{len(missing)} (leaf, triangle) pairs missing, e.g. {missing[:5]}"


def test_every_triangle_is_listed_in_a_leaf_holding_its_centroid(built):
    # also covers triangles lying in a split plane, which reach into no open cell
    tris, tree = built
    nodes, lo, hi, _, _ = walk(tree)
    _, leaf_tris = tree.nodes_host()
    leaves = np.flatnonzero(nodes["axis"] == kdtree.LEAF)
    centroid = tris.astype(np.float64).mean(axis=1)
    holds = np.all((lo[leaves, None] <= centroid) & (centroid <= hi[leaves, None]), axis=-1)
    listed = np.zeros_like(holds)
    for row, leaf in enumerate(leaves):
        start, count = int(nodes[leaf]["child"]), int(nodes[leaf]["count"])
        listed[row, leaf_tris[start : start + count]] = True
    orphans = np.flatnonzero(~(holds & listed).any(axis=0))
    assert len(orphans) == 0, f"{len(orphans)} triangle(s) in no leaf around their centroid, e.g. {orphans[:5]}"


def test_overlap_check_finds_a_triangle_removed_from_its_leaf(device):
    tris = random_soup(300, seed=7)
    tree = kdtree.build(device, tris)
    nodes, lo, hi, _, _ = walk(tree)
    _, leaf_tris = tree.nodes_host()
    leaf = np.flatnonzero((nodes["axis"] == kdtree.LEAF) & (nodes["count"] > 0))[0]
    damaged = leaf_tris.copy()
    damaged[nodes[leaf]["child"]] = -1
    missing = unlisted_overlaps(tris, nodes, damaged, lo, hi, scene_margin(tree))
    assert (int(leaf), int(leaf_tris[nodes[leaf]["child"]])) in missing


def test_overlap_oracle_on_simple_cases():
    box_lo, box_hi = np.zeros((1, 3)), np.ones((1, 3))
    across = np.array([[[-1, 0.5, 0.5], [2, 0.5, 0.5], [0.5, 2, 0.5]]])
    beside = np.array([[[1.5, 0, 0], [3, 0, 0], [1.5, 1, 1]]])
    on_face = np.array([[[1, 0, 0], [1, 1, 0], [1, 0, 1]]])  # in the plane x = 1: not inside the open box
    corner_cut = np.array([[[0.9, 1.5, 0.5], [1.5, 0.9, 0.5], [1.5, 1.5, 0.5]]])  # misses, though its box overlaps
    expect = [True, False, False, False]
    for tri, want in zip([across, beside, on_face, corner_cut], expect):
        assert triangle_box_overlap(tri, box_lo, box_hi)[0] == want


def test_stats_agree_with_the_node_array(built):
    tris, tree = built
    nodes, lo, hi, depth, _ = walk(tree)
    stats = tree.stats
    leaf = nodes["axis"] == kdtree.LEAF
    counts = nodes["count"][leaf]
    assert stats["nodes"] == len(nodes)
    assert stats["leaves"] == int(leaf.sum())
    assert stats["leaves"] == (len(nodes) + 1) // 2  # a full binary tree
    assert stats["depth"] == int(depth.max())
    assert stats["depth"] <= depth_limit(len(tris))
    assert stats["leaf_references"] == int(counts.sum())
    assert stats["max_leaf_size"] == int(counts.max())
    assert stats["mean_leaf_size"] == pytest.approx(counts.mean())
    assert stats["max_leaf_size"] >= stats["mean_leaf_size"]
    assert stats["triangles"] == len(tris)


def test_sah_cost_matches_the_cells_of_the_walk(built):
    _, tree = built
    nodes, lo, hi, _, _ = walk(tree)
    d = hi - lo
    area = 2.0 * (d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0])
    leaf = nodes["axis"] == kdtree.LEAF
    cost = np.where(leaf, nodes["count"], tree.stats["cost_traverse"]) * area
    assert tree.stats["sah_cost"] == pytest.approx(cost.sum() / area[0], rel=1e-3)


def test_stats_time_every_build_stage(built):
    _, tree = built
    ms = tree.stats["ms"]
    one_item = ("serial",) if "serial" in ms else ("large", "small", "output")
    for stage in ("upload", "setup", *one_item, "total"):
        assert ms[stage] >= 0.0, stage
    stages = sum(v for k, v in ms.items() if k != "total")
    assert ms["total"] >= stages * (1 - 1e-6)


def test_large_scenes_pass_through_both_stages(device):
    tris = random_soup(5000, seed=1, size=0.01)
    stats = kdtree.build(device, tris).stats
    assert stats["large_levels"] >= 1
    assert stats["small_roots"] >= len(tris) // SMALL
    assert stats["small_levels"] >= 1


def test_small_scenes_skip_the_large_stage(device):
    stats = kdtree.build(device, random_soup(SMALL, seed=2)).stats
    assert stats["large_levels"] == 0
    assert stats["small_roots"] == 1


def test_a_fan_stops_splitting_before_the_depth_limit(device):
    # every median split through a fan's centre keeps all the triangles
    # there on both sides; after BAD_SPLITS such splits a path ends in leaves
    tris = fan(2000)
    stats = kdtree.build(device, tris).stats
    assert stats["depth"] < depth_limit(len(tris))


def test_a_stack_of_triangles_ends_in_leaves_after_the_unpaid_splits(device):
    # no split of a stack pays: at most BAD_SPLITS + 1 levels of them copy it
    tris = stack(500)
    stats = kdtree.build(device, tris).stats
    assert stats["leaf_references"] <= 2 ** (BAD_SPLITS + 1) * len(tris)


def test_an_object_over_a_wide_floor_keeps_small_leaves(device):
    # the object's side of each split keeps the floor and the whole object
    # until the cells shrink to the object: progress all the same
    floor = np.array([[[-20, -20, 0], [20, -20, 0], [20, 20, 0]], [[-20, -20, 0], [20, 20, 0], [-20, 20, 0]]])
    ball = 0.5 * sphere(16, 32) + np.array([3.0, 2.0, 0.6])
    stats = kdtree.build(device, np.concatenate([floor, ball]).astype(np.float32)).stats
    assert stats["max_leaf_size"] <= SMALL // 2  # a leaf of the whole ball would hold 1,024


@pytest.mark.parametrize("blocks, largest_mean", [(False, 4.0), (True, 2 * COST_TRAVERSE_BLOCKS)])
def test_leaves_stay_small_where_triangles_are_separable(device, blocks, largest_mean):
    # well-separated tiny triangles: the SAH should isolate them in leaves
    # of a few triangles, more where a leaf's triangles are tested four at a time
    tris = random_soup(4000, seed=6, size=0.001)
    stats = kdtree.build(device, tris, blocks=blocks).stats
    assert stats["mean_leaf_size"] <= largest_mean
    assert stats["leaf_references"] <= 2 * len(tris)


def test_a_tree_built_for_blocks_weighs_node_steps_more_and_has_fewer_larger_leaves(device):
    tris = random_soup(4000, seed=6, size=0.02)
    one_by_one, blocked = (kdtree.build(device, tris, blocks=b).stats for b in (False, True))
    assert (one_by_one["cost_traverse"], blocked["cost_traverse"]) == (cost_traverse(False), cost_traverse(True))
    assert cost_traverse(True) > cost_traverse(False)
    assert blocked["leaves"] < one_by_one["leaves"] / 2
    assert blocked["mean_leaf_size"] > 2 * one_by_one["mean_leaf_size"]


def device_verts(device, tris):
    """The corners of ``tris`` (N, 3, 3) as the device's float4 array, and N."""
    corners = tris.reshape(-1, 3)
    verts = np.zeros((len(corners), 4), np.float32)
    verts[:, :3] = corners
    return device.array_from(verts.view(cltypes.float4).reshape(-1)), len(corners) // 3


def assert_same_tree(a, b):
    """The same node array, leaf lists and statistics (times aside)."""
    assert np.array_equal(a.nodes.get(), b.nodes.get())
    used = a.stats["leaf_references"]
    assert np.array_equal(a.leaf_tris.get()[:used], b.leaf_tris.get()[:used])
    assert {k: v for k, v in a.stats.items() if k != "ms"} == {k: v for k, v in b.stats.items() if k != "ms"}


@pytest.mark.parametrize("lanes", [8, SAH_GROUP])
def test_sah_search_makes_the_same_tree_with_any_lane_count(device, lanes):
    # the CPU searches a node's candidates in one work-item, a GPU in a work-group
    verts_dev, count = device_verts(device, box_grid(4))
    reference = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0)
    other = build_tree(device, verts_dev, count, sah_lanes=lanes)
    assert "serial" not in other.stats["ms"]  # one work-item searches with one lane only
    assert_same_tree(other, reference)


def flat_lattice(n, seed=12):
    """Axis-aligned flat triangles with corners on a small integer lattice:
    bounds tie everywhere and lie in one another's planes."""
    rng = np.random.default_rng(seed)
    tris = rng.integers(0, 6, (n, 3, 3)).astype(np.float32)
    axis = rng.integers(0, 3, n)
    tris[np.arange(n), :, axis] = tris[np.arange(n), 0, axis][:, None]
    return tris


def degenerate_soup(n, seed=13):
    """Points, segments and repeated triangles among ordinary ones."""
    rng = np.random.default_rng(seed)
    tris = rng.normal(size=(n, 3, 3)).astype(np.float32)
    kind = rng.integers(0, 3, n)
    tris[kind == 0, 1] = tris[kind == 0, 2] = tris[kind == 0, 0]
    tris[kind == 1, 2] = tris[kind == 1, 1]
    tris[: n // 4] = tris[rng.integers(0, n, n // 4)]
    return tris


MASK_SCENES = {**{k: v for k, v in SCENES.items() if k != "stack"},  # the stack has no small root
               "flat_lattice": lambda: flat_lattice(1500), "degenerate_soup": lambda: degenerate_soup(1500)}


@pytest.mark.parametrize("name", sorted(MASK_SCENES))
@pytest.mark.parametrize("serial_max", [0, 1 << 30], ids=["launched", "one_work_item"])
def test_candidate_masks_from_sorted_bounds_make_the_same_tree(device, name, serial_max):
    """A CPU's masks (two sorts and two sweeps per root and axis) against a
    GPU's (each candidate against every element of its root): the same
    records, tree and leaf lists, on scenes full of ties and of triangles
    flat in a split plane (the box grid, the fan, the lattice) and of
    degenerate ones."""
    verts_dev, count = device_verts(device, MASK_SCENES[name]())
    by_sort = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=serial_max, sorted_masks=True)
    by_candidate = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=serial_max, sorted_masks=False)
    assert by_sort.stats["small_roots"] > 0
    assert_same_tree(by_sort, by_candidate)


@pytest.mark.parametrize("name", sorted(MASK_SCENES))
def test_one_lane_searching_an_element_six_planes_at_once_picks_what_lanes_plane_by_plane_pick(device, name):
    """One lane's search (a CPU's) takes an element's six candidate planes as
    two float4 of costs; several lanes take them one at a time: the same
    costs, the same cheapest candidate with ties to the lowest, so the same
    tree, on scenes full of tied and flat bounds."""
    verts_dev, count = device_verts(device, MASK_SCENES[name]())
    one_lane = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0)
    plane_by_plane = build_tree(device, verts_dev, count, sah_lanes=8, sorted_masks=True)
    assert_same_tree(one_lane, plane_by_plane)


@pytest.mark.parametrize("name", ["random_soup", "big_and_small", "sphere", "degenerate_soup", "stack"])
def test_element_runs_make_the_same_tree_as_one_element_a_work_item(device, name, monkeypatch):
    """The large stage's classification and scatter taking runs of elements
    a work-item (a CPU's form, asking for straddlers' corners ahead) against
    one element a work-item: the same tree, on scenes whose levels end inside
    a run and straddle planes (short runs, so that every level has several)."""
    monkeypatch.setattr(kdtree_build, "RUN", 7)
    monkeypatch.setattr(kdtree_build, "PREFETCH_AHEAD", 3)
    verts_dev, count = device_verts(device, {**MASK_SCENES, **SCENES}[name]())
    in_runs = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0, runs=True)
    one_each = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0, runs=False)
    assert in_runs.stats["large_levels"] > 1
    assert_same_tree(in_runs, one_each)


def test_a_cpu_device_builds_in_runs_asking_ahead_for_straddlers_corners(device):
    """Every CPU device (PoCL as well as Intel's runtime: measured to pay on
    both) takes the large stage's elements in runs and asks ahead for a
    straddler's corners; other devices one element a work-item."""
    defines = kdtree_build.programs(device)[0][1]
    if device.is_cpu:
        assert (defines["KD_RUN"], defines["KD_PREFETCH_AHEAD"]) == (kdtree_build.RUN, kdtree_build.PREFETCH_AHEAD)
    else:
        assert (defines["KD_RUN"], defines["KD_PREFETCH_AHEAD"]) == (1, 0)


@pytest.mark.parametrize("seed", range(4))
def test_candidate_masks_from_sorted_bounds_match_each_candidate_against_every_element(device, seed):
    """The two mask kernels side by side, mask for mask, on small roots of 1
    to 64 elements whose bounds lie on a small lattice: ties among low
    faces, among high faces and across them, elements flat in a plane,
    repeated elements (a tree comparison would miss a wrong mask that only
    loses the SAH search)."""
    rng = np.random.default_rng(seed)
    sizes = [1, 2, 3, 7, 16, 33, 63, 64, *rng.integers(1, SMALL + 1, 8)]
    lo = rng.integers(0, 5, (sum(sizes), 4)).astype(np.float32)
    hi = lo + rng.integers(0, 3, lo.shape).astype(np.float32)  # a third of the extents flat
    repeat = rng.random(len(lo)) < 0.2
    lo[repeat], hi[repeat] = lo[0], hi[0]
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    roots = np.zeros((len(sizes), 4), np.int32)
    roots[:, 0], roots[:, 1] = first, sizes
    sel_root = np.repeat(np.arange(len(sizes), dtype=np.int32), sizes)
    program, defines = kdtree_build.programs(device)[0]
    roots_d, sel_root_d = device.to_device(roots), device.to_device(sel_root)
    lo_d, hi_d = device.to_device(lo), device.to_device(hi)
    masks = {}
    for sorted_form in (True, False):
        cand = device.empty(16 * 6 * len(lo))
        if sorted_form:
            device.kernel(program, "KdBuild_small_masks_sorted", defines)(
                3 * len(sizes), roots_d, lo_d, hi_d, np.int32(3 * len(sizes)), cand)
        else:
            device.kernel(program, "KdBuild_small_masks", defines)(
                6 * len(lo), roots_d, sel_root_d, lo_d, hi_d, np.int32(6 * len(lo)), cand)
        masks[sorted_form] = device.read(cand, (len(lo), 6, 2), np.uint64)
    assert masks[False].any()
    np.testing.assert_array_equal(masks[True], masks[False])


@pytest.mark.parametrize("name", sorted(SCENES) + ["one_triangle", "small_root", "one_above"])
def test_the_one_work_item_build_makes_the_level_by_level_tree(device, name):
    """The same steps in the same order: the same records, tree and leaf
    lists bit for bit."""
    extra = {"one_triangle": lambda: random_soup(1, seed=7), "small_root": lambda: random_soup(SMALL, seed=8),
             "one_above": lambda: random_soup(SMALL + 1, seed=9)}
    verts_dev, count = device_verts(device, {**SCENES, **extra}[name]())
    serial = build_tree(device, verts_dev, count, serial_max=1 << 30, sah_lanes=1)
    launched = build_tree(device, verts_dev, count, serial_max=0, sah_lanes=1)
    assert "serial" in serial.stats["ms"] and "serial" not in launched.stats["ms"]
    assert_same_tree(serial, launched)


def tree_shape(tree):
    """The tree as a list in preorder: (axis, split, right child) for an
    inner node, the triangle list for a leaf (where the lists lie in the
    leaf array depends on the level a leaf was made in)."""
    nodes, leaf_tris = tree.nodes.get(), tree.leaf_tris.get()
    return [tuple(leaf_tris[n["child"]: n["child"] + n["count"]]) if n["axis"] == kdtree_build.LEAF
            else (int(n["axis"]), float(n["split"]), int(n["child"])) for n in nodes]


@pytest.mark.parametrize("serial_max", [0, 1 << 30], ids=["launched", "one_work_item"])
def test_cuts_chained_in_one_level_make_the_tree_of_one_cut_a_level(device, monkeypatch, serial_max):
    """A large node's empty-space cuts made before its split in one level
    (its elements passed over once) against one cut a level: the same
    splits and leaf lists in the same preorder, in fewer levels where cuts
    are (the sphere, the fan, the stack)."""
    fewer = []
    for name, make in sorted(MASK_SCENES.items()) + [("stack", SCENES["stack"])]:
        verts_dev, count = device_verts(device, make())
        chained = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=serial_max)
        monkeypatch.setattr(kdtree_build, "MAX_CHAIN", 0)
        level_by_level = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=serial_max)
        monkeypatch.undo()
        assert tree_shape(chained) == tree_shape(level_by_level), name
        same = ("nodes", "leaves", "leaf_references", "depth", "small_roots", "max_leaf_size")
        assert {k: chained.stats[k] for k in same} == {k: level_by_level.stats[k] for k in same}, name
        assert chained.stats["sah_cost"] == pytest.approx(level_by_level.stats["sah_cost"], rel=1e-9)
        assert chained.stats["large_levels"] <= level_by_level.stats["large_levels"], name
        if chained.stats["large_levels"] < level_by_level.stats["large_levels"]:
            fewer.append(name)
    assert {"sphere", "fan", "stack"} <= set(fewer)


@pytest.mark.parametrize("room", ["elements", "small", "records", "leaves", "small_nodes"])
def test_the_one_work_item_build_falls_back_when_it_outgrows_its_room(device, monkeypatch, room):
    monkeypatch.setitem(kdtree_build.SERIAL_ROOM, room, 0)
    monkeypatch.setattr(kdtree_build, "SERIAL_SLACK", 40)
    verts_dev, count = device_verts(device, random_soup(1000, seed=11))
    tree = build_tree(device, verts_dev, count, serial_max=1 << 30, sah_lanes=1)
    assert "serial" not in tree.stats["ms"]
    assert_same_tree(tree, build_tree(device, verts_dev, count, serial_max=0, sah_lanes=1))


def test_a_level_past_the_element_budget_makes_its_large_children_leaves(device, monkeypatch):
    """Where a level's children would hold more elements than the budget,
    every large child of the level becomes a leaf: fewer levels and larger leaves, every
    triangle still listed in every leaf it reaches into, and the same tree
    from both builders."""
    tris = random_soup(3000, seed=14, size=0.3)
    verts_dev, count = device_verts(device, tris)
    free = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0)
    monkeypatch.setattr(kdtree_build, "ELEMENT_BUDGET", 1)
    monkeypatch.setattr(kdtree_build, "ELEMENT_SLACK", 0)
    launched = build_tree(device, verts_dev, count, sah_lanes=1, serial_max=0)
    assert launched.stats["large_levels"] < free.stats["large_levels"]
    assert launched.stats["max_leaf_size"] > SMALL
    assert_same_tree(launched, build_tree(device, verts_dev, count, sah_lanes=1, serial_max=1 << 30))
    monkeypatch.setattr(kdtree_build, "SERIAL_MAX", 0)
    tree = kdtree.build(device, tris, blocks=False)
    nodes, lo, hi, _, reached = walk(tree)
    assert np.all(reached == 1)
    assert not unlisted_overlaps(tris, nodes, tree.nodes_host()[1], lo, hi, scene_margin(tree))


def test_only_a_cpu_device_builds_small_meshes_in_one_work_item(device):
    tris = random_soup(kdtree_build.SERIAL_MAX + 1, seed=10, size=0.001)
    assert ("serial" in kdtree.build(device, tris[:-1]).stats["ms"]) == device.is_cpu
    assert "serial" not in kdtree.build(device, tris).stats["ms"]


def clip_polygon(poly: list, axis: int, plane: float, keep_below: bool) -> list:
    """Sutherland-Hodgman in float64: the part of ``poly`` with x[axis] <=
    plane (keep_below) or >= plane."""
    out = []
    for i, a in enumerate(poly):
        b = poly[(i + 1) % len(poly)]
        da, db = (plane - a[axis], plane - b[axis]) if keep_below else (a[axis] - plane, b[axis] - plane)
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + da / (da - db) * (b - a))
    return out


def test_a_straddling_triangle_gets_the_bounds_of_its_clipped_part_on_each_side(device):
    """KdBuild_large_classify against float64 clipping: each side's bounds
    are those of the triangle inside its element's box and past the plane
    widened by eps (then widened by eps), and a side it does not reach is
    dropped."""
    rng = np.random.default_rng(5)
    n, eps = 400, 1e-4
    tris = rng.uniform(-1.0, 1.0, (n, 3, 3))
    # each element's box: a random box overlapping its triangle's bounds
    t_lo, t_hi = tris.min(axis=1), tris.max(axis=1)
    lo = t_lo + rng.uniform(0.0, 0.4, (n, 3)) * (t_hi - t_lo)
    hi = t_hi - rng.uniform(0.0, 0.4, (n, 3)) * (t_hi - t_lo)
    axis = rng.integers(0, 3, n)
    rows = np.arange(n)
    plane = lo[rows, axis] + rng.uniform(0.2, 0.8, n) * (hi[rows, axis] - lo[rows, axis])
    verts_dev, _ = device_verts(device, tris.astype(np.float32))
    float4 = lambda a: device.to_device(np.concatenate([a, np.zeros((n, 1))], 1).astype(np.float32))
    out = [device.empty(16 * n) for _ in range(4)]
    flags, run_sums = device.empty(8 * n), device.empty(8 * n)
    config = kdtree_build._Config(device, None)
    runs = -(-n // config.run)
    device.kernel(kdtree_build.PROGRAM, "KdBuild_large_classify", config.defines)(
        runs, verts_dev.data, device.to_device(rows.astype(np.int32)), float4(lo), float4(hi),
        device.to_device(rows.astype(np.int32)), device.to_device(plane.astype(np.float32)),
        device.to_device(axis.astype(np.int32)), np.int32(n), np.float32(eps), flags, run_sums, *out)
    below_lo, below_hi, above_lo, above_hi = (device.read(b, (n, 4), np.float32)[:, :3] for b in out)
    sides = device.read(flags, n, np.int64)
    # each work-item's run of elements: their flags summed for the scan
    np.testing.assert_array_equal(device.read(run_sums, runs, np.int64),
                                  np.add.reduceat(sides, np.arange(0, n, config.run)))
    checked = 0
    for e in range(n):
        cell = [v for v in tris[e]]
        for a in range(3):
            cell = clip_polygon(clip_polygon(cell, a, lo[e, a], False), a, hi[e, a], True)
        parts = [clip_polygon(cell, axis[e], plane[e] + eps, True), clip_polygon(cell, axis[e], plane[e] - eps, False)]
        # how far each side's part reaches from its cut: a sliver, float32 may see either way
        depth = [plane[e] + eps - min(p[axis[e]] for p in parts[0]) if parts[0] else 1.0,
                 max(p[axis[e]] for p in parts[1]) - (plane[e] - eps) if parts[1] else 1.0]
        if not cell or min(depth) < 1e-3:
            continue
        assert sides[e] == (1 if parts[0] else 0) + ((1 << 32) if parts[1] else 0)
        side_box = [(lo[e], np.where(np.arange(3) == axis[e], plane[e] + eps, hi[e])),
                    (np.where(np.arange(3) == axis[e], plane[e] - eps, lo[e]), hi[e])]
        got = [(below_lo, below_hi), (above_lo, above_hi)]
        for part, (box_lo, box_hi), (got_lo, got_hi) in zip(parts, side_box, got):
            if part:
                want_lo = np.maximum(np.min(part, axis=0) - eps, box_lo)
                want_hi = np.minimum(np.max(part, axis=0) + eps, box_hi)
                np.testing.assert_allclose(got_lo[e], want_lo, atol=2e-5)
                np.testing.assert_allclose(got_hi[e], want_hi, atol=2e-5)
        checked += 1
    assert checked > n // 2
    assert 0 < np.count_nonzero(sides != 1 + (1 << 32)) < n // 4  # some keep one side only
