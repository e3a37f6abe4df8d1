"""Irradiance-cache sample selection (gpu_core.cache.select_samples) against
numpy brute force: quadtree means and errors, seed budgets, k-means
assignments, per-cluster sample points, degenerate inputs and scale."""

import numpy as np
import pytest
from cache_shapes import shading_points

from gpu_core.gi.cache import clusters
from gpu_core.gi.cache import seeding as cache_seeding
from gpu_core.gi.cache.samples import ALPHA0, WARM_ITERATIONS, HeldSamples, select_samples
from gpu_core.device.layout import float4_rows as float4
from gpu_core.gi.cache.frame import Frame

SIZE = 64
TIE = 1e-6  # CACHE_TIE: errors this close to the smallest count as ties, lowest index wins


def eps(alpha, x, n, c, nc):
    """eps between rows of (x, n) and rows of (c, nc), float64, broadcasting;
    sqrt(2 - 2 n . nc) as the chord |n - nc|, equal for unit normals."""
    x, n, c, nc = (np.asarray(a, np.float64) for a in (x, n, c, nc))
    return alpha * np.linalg.norm(x - c, axis=-1) + np.linalg.norm(n - nc, axis=-1)


def all_eps(samples, pos, nrm):
    """(N, M) eps of every point to every cluster centre."""
    return eps(samples.stats["alpha"], pos[:, None], nrm[:, None], samples.centre_positions[None],
               samples.centre_normals[None])


def tie_choice(errors):
    """Per row, the lowest column whose error is within the tie window of the
    row's smallest (gpu_core/kernels/cache_common.h), and whether that choice
    is clear of float rounding: no error lies near the window's edge."""
    smallest = errors.min(axis=-1, keepdims=True)
    window = smallest + TIE * (1.0 + smallest)
    inside = errors <= window
    clear = ~(np.abs(errors - window) < 5e-7).any(axis=-1)
    return inside.argmax(axis=-1), clear


def check_finite(samples):
    for arr in (samples.positions, samples.normals, samples.centre_positions, samples.centre_normals):
        assert np.isfinite(arr).all()


# -- quadtree -----------------------------------------------------------------


def quadtree(device, shape, width=SIZE, height=SIZE, repeat=1):
    pos, nrm, pix = shading_points(shape, width, height)
    pos, nrm, pix = np.tile(pos, (repeat, 1)), np.tile(nrm, (repeat, 1)), np.tile(pix, (repeat, 1))
    frame = Frame.around(pos)
    pos4 = frame.to_device(pos)
    tree = cache_seeding.build(device, device.to_device(pos4), device.to_device(float4(nrm)), device.to_device(pix),
                               len(pos), width, height, ALPHA0)
    return tree, pos4[:, :3].astype(np.float64), nrm.astype(np.float64), pix


def numpy_levels(pos, nrm, pix, width, height):
    """Per level, root first: (count, mean, unit mean normal, mean eps) by brute force."""
    depth = max(max(width, height) - 1, 0).bit_length()
    out = []
    for level in range(depth + 1):
        up = depth - level
        w, h = -(-width // (1 << up)), -(-height // (1 << up))
        node = (pix[:, 1] >> up) * w + (pix[:, 0] >> up)
        count = np.bincount(node, minlength=w * h)
        psum, nsum = np.zeros((w * h, 3)), np.zeros((w * h, 3))
        np.add.at(psum, node, pos)
        np.add.at(nsum, node, nrm)
        mean = psum / np.maximum(count, 1)[:, None]
        normal = nsum / np.maximum(np.linalg.norm(nsum, axis=1, keepdims=True), 1e-300)
        errors = np.bincount(node, eps(ALPHA0, pos, nrm, mean[node], normal[node]), minlength=w * h)
        out.append((count.reshape(h, w), mean.reshape(h, w, 3), normal.reshape(h, w, 3),
                    (errors / np.maximum(count, 1)).reshape(h, w)))
    return out


@pytest.mark.parametrize("shape, width, height, repeat", [
    ("plane", SIZE, SIZE, 1), ("two_planes", SIZE, SIZE, 1), ("sphere", SIZE, SIZE, 1),
    ("two_planes", 48, 27, 3),  # not a power of two, three points per pixel
])
def test_quadtree_node_means_and_errors_equal_numpy(device, shape, width, height, repeat):
    tree, pos, nrm, pix = quadtree(device, shape, width, height, repeat)
    got = cache_seeding.read(device, tree)
    want = numpy_levels(pos, nrm, pix, width, height)
    assert len(got) == len(want)
    for level, (g, (count, mean, normal, error)) in enumerate(zip(got, want)):
        np.testing.assert_array_equal(g["count"], count, err_msg=f"level {level}")
        filled = count > 0
        np.testing.assert_allclose(g["mean"][filled], mean[filled], atol=2e-6, err_msg=f"level {level}")
        np.testing.assert_allclose(g["normal"][filled], normal[filled], atol=2e-6, err_msg=f"level {level}")
        np.testing.assert_allclose(g["error"][filled], error[filled], rtol=1e-4, atol=1e-6, err_msg=f"level {level}")
        assert (g["error"][filled] > 0).any() or level == len(got) - 1


def test_quadtree_launches_grow_by_two_a_level_not_with_the_square_of_the_depth(device, monkeypatch):
    """The errors of every level come from one pass over the leaves and one
    launch a level upwards, as the sums do: each level more adds two launches
    (a per-level error pass, summed up to its level, added depth + 2)."""
    from gpu_core.device.kernels import Kernel
    names = []
    call = Kernel.__call__
    monkeypatch.setattr(Kernel, "__call__", lambda self, *a: (names.append(self.name), call(self, *a))[1])
    launches = {}
    for size in (16, 64):
        names.clear()
        tree, *_ = quadtree(device, "two_planes", size, size)
        launches[len(tree.levels)] = [n for n in names if n.startswith("Cache_")]
    (short, few), (deep, many) = sorted(launches.items())
    assert deep == short + 2
    assert len(many) == len(few) + 4
    assert many.count("Cache_leaf_errors") == 1 and many.count("Cache_pyramid_errors") == deep - 1


def water_filled_shares(budget, weight, cap):
    """Real-valued shares of ``budget`` in proportion to ``weight``, capped."""
    weight = weight.astype(np.float64).copy()
    share = np.zeros(len(cap))
    open_ = cap > 0
    left = float(budget)
    while open_.any() and left > 0:
        total = weight[open_].sum()
        if total <= 0:
            weight = cap.astype(np.float64)
            total = weight[open_].sum()
        hit = open_ & (left * weight >= cap * total)
        if not hit.any():
            share[open_] = left * weight[open_] / total
            break
        share[hit] = cap[hit]
        open_ &= ~hit
        left = budget - share[~open_].sum()
    return share


@pytest.mark.parametrize("shape, count", [("two_planes", 300), ("sphere", 1000), ("plane", 4000)])
def test_seed_budgets_follow_node_error_within_rounding_and_respect_point_counts(device, shape, count):
    tree, pos, nrm, pix = quadtree(device, shape)
    seeds, total = cache_seeding.seed(device, tree, device.to_device(float4(pos)), device.to_device(float4(nrm)),
                                      count, ALPHA0, 7)
    levels = cache_seeding.read(device, tree)
    assert total == min(count, len(pos))
    assert levels[0]["budget"][0, 0] == total
    for parent, child in zip(levels[:-1], levels[1:]):
        assert (child["budget"] <= child["count"]).all()
        assert child["budget"].sum() == total
        h, w = parent["budget"].shape
        for y in range(h):
            for x in range(w):
                kids = child["budget"][2 * y:2 * y + 2, 2 * x:2 * x + 2].ravel()
                caps = child["count"][2 * y:2 * y + 2, 2 * x:2 * x + 2].ravel()
                weight = (child["error"] * child["count"])[2 * y:2 * y + 2, 2 * x:2 * x + 2].ravel()
                share = water_filled_shares(parent["budget"][y, x], weight, caps)
                assert kids.sum() == parent["budget"][y, x]
                # each child gets the floor or the ceiling of its share
                assert (np.abs(kids - share) < 1.0 + 1e-4).all(), (kids, share)


# -- selection ------------------------------------------------------------------


@pytest.mark.parametrize("shape", ["plane", "two_planes", "sphere", "box"])
@pytest.mark.parametrize("count", [1, 37, 400])
def test_sample_count_equals_the_requested_count(device, shape, count):
    pos, nrm, pix = shading_points(shape, SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, count)
    assert len(samples.indices) == count
    assert len(np.unique(samples.indices)) == count
    assert samples.stats["seeds"] == count
    np.testing.assert_array_equal(np.sort(np.unique(samples.cluster_of)), np.arange(count))
    check_finite(samples)


@pytest.mark.parametrize("shape", ["two_planes", "sphere", "box"])
def test_every_sample_is_the_member_of_its_cluster_with_smallest_eps(device, shape):
    pos, nrm, pix = shading_points(shape, SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 300)
    to_centre = all_eps(samples, pos, nrm)
    unclear = 0
    for j, index in enumerate(samples.indices):
        members = np.flatnonzero(samples.cluster_of == j)
        assert index in members
        pick, clear = tie_choice(to_centre[members, j])
        assert to_centre[index, j] <= to_centre[members, j].min() + 2e-6
        if clear:
            assert index == members[pick]
        unclear += not clear
    assert unclear <= len(samples.indices) // 100
    np.testing.assert_array_equal(samples.positions, pos[samples.indices])
    np.testing.assert_array_equal(samples.normals, nrm[samples.indices])


@pytest.mark.parametrize("shape", ["plane", "two_planes", "sphere", "box"])
@pytest.mark.parametrize("alpha", [None, 0.0, 50.0])
def test_assignments_equal_brute_force_nearest_centre_under_eps(device, shape, alpha):
    pos, nrm, pix = shading_points(shape, SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 250, alpha=alpha)
    to_centre = all_eps(samples, pos, nrm)
    rows = np.arange(len(pos))
    assert (to_centre[rows, samples.cluster_of] <= to_centre.min(axis=1) + 2e-6).all()
    nearest, clear = tie_choice(to_centre)
    np.testing.assert_array_equal(samples.cluster_of[clear], nearest[clear])
    assert clear.mean() > 0.99


@pytest.mark.parametrize("shape", ["two_planes", "box"])
def test_assignments_through_centre_trees_built_again_each_iteration_equal_brute_force(device, shape, monkeypatch):
    """The tree over the centres may be built again between iterations
    (when its refit boxes cost more than a fresh tree): the search stays exact."""
    built = []
    original = clusters._CentreTree.__init__
    monkeypatch.setattr(clusters._CentreTree, "__init__", lambda self, *a: (built.append(1), original(self, *a))[1])
    monkeypatch.setattr(clusters, "_needs_new_tree", lambda work, fresh: True)
    pos, nrm, pix = shading_points(shape, SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 250, max_iterations=4, converge_fraction=0.0)
    assert len(built) == samples.stats["iterations"]
    to_centre = all_eps(samples, pos, nrm)
    nearest, clear = tie_choice(to_centre)
    np.testing.assert_array_equal(samples.cluster_of[clear], nearest[clear])
    assert clear.mean() > 0.99


def test_a_new_centre_tree_is_built_only_once_the_refit_one_costs_more():
    assert clusters._needs_new_tree(1300, 1000)
    assert not clusters._needs_new_tree(900, 1000)
    assert not clusters._needs_new_tree(1000, 1000)


def test_kmeans_stops_at_the_iteration_cap(device):
    pos, nrm, pix = shading_points("box", SIZE, SIZE)
    for cap in (1, 2, 3):
        samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 200, max_iterations=cap, converge_fraction=0.0)
        assert samples.stats["iterations"] == cap
        assert not samples.stats["converged"]


def test_kmeans_stops_once_few_points_change_cluster(device):
    pos, nrm, pix = shading_points("sphere", SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 200, max_iterations=100, converge_fraction=0.02)
    assert samples.stats["converged"]
    assert 1 < samples.stats["iterations"] < 100
    assert samples.stats["changed_fraction"] <= 0.02


def test_more_iterations_lower_the_total_error_to_the_centres(device):
    pos, nrm, pix = shading_points("two_planes", SIZE, SIZE)
    totals = []
    for cap in (1, 4):
        samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 150, max_iterations=cap, converge_fraction=0.0)
        totals.append(all_eps(samples, pos, nrm)[np.arange(len(pos)), samples.cluster_of].sum())
    assert totals[1] < totals[0]


# -- cache points kept from one render to the next --------------------------------


def held_select(device, held, pos, nrm, pix, count, warm=True):
    """HeldSamples.select on host arrays (alpha ALPHA0)."""
    buffers = (device.to_device(float4(pos)), device.to_device(float4(nrm)), device.to_device(pix))
    return held.select(device, *buffers, len(pos), SIZE, SIZE, count, ALPHA0, 0, warm=warm)


def test_the_same_points_get_the_same_samples_back(device):
    held = HeldSamples()
    pos, nrm, pix = shading_points("box", SIZE, SIZE)
    first, reused = held_select(device, held, pos, nrm, pix, 150)
    again, reused_again = held_select(device, held, pos.copy(), nrm.copy(), pix.copy(), 150)
    assert not reused and reused_again and again is first
    nudged = pos.copy()
    nudged[7, 0] = np.nextafter(nudged[7, 0], np.float32(np.inf))  # one bit of one point
    assert not held_select(device, held, nudged, nrm, pix, 150, warm=False)[1]


@pytest.mark.parametrize("shape", ["two_planes", "box"])
def test_a_warm_start_from_moved_points_assigns_each_to_its_nearest_centre(device, shape):
    held = HeldSamples()
    held_select(device, held, *shading_points(shape, SIZE, SIZE), 200)
    # the same view of the scene moved: a new frame, every point changed
    pos, nrm, pix = shading_points(shape, SIZE, SIZE, offset=(0.03, -0.02, 0.05))
    samples, reused = held_select(device, held, pos, nrm, pix, 200)
    assert not reused and samples.stats["warm_start"] and samples.stats["iterations"] <= WARM_ITERATIONS
    assert samples.count == 200
    to_centre = all_eps(samples, pos, nrm)
    nearest, clear = tie_choice(to_centre)
    np.testing.assert_array_equal(samples.cluster_of[clear], nearest[clear])
    assert clear.mean() > 0.99


def test_samples_fewer_than_asked_or_warm_off_start_from_new_seeds(device):
    held = HeldSamples()
    pos, nrm, pix = shading_points("plane", SIZE, SIZE)
    coinciding = (np.repeat(pos[:10], 8, axis=0), np.repeat(nrm[:10], 8, axis=0), np.repeat(pix[:10], 8, axis=0))
    first, _ = held_select(device, held, *coinciding, 20)
    assert first.count < 20  # ten distinct points make ten clusters at most
    assert not held_select(device, held, pos[:80], nrm[:80], pix[:80], 20)[0].stats["warm_start"]
    assert not held_select(device, held, pos[:90], nrm[:90], pix[:90], 20, warm=False)[0].stats["warm_start"]


# -- degenerate inputs ----------------------------------------------------------------


def test_one_shading_point_gives_one_sample(device):
    pos, nrm, pix = np.array([[0.3, -2.0, 5.0]], np.float32), np.array([[0, 0, 1]], np.float32), np.array([[3, 4]])
    for count in (1, 10):
        samples = select_samples(device, pos, nrm, pix, 8, 8, count)
        np.testing.assert_array_equal(samples.indices, [0])
        np.testing.assert_array_equal(samples.cluster_of, [0])
        np.testing.assert_array_equal(samples.centre_positions, pos)
        check_finite(samples)


def test_identical_points_collapse_to_one_sample(device):
    n = 300
    pos = np.tile(np.array([[1.0, 2.0, 3.0]], np.float32), (n, 1))
    nrm = np.tile(np.array([[0.0, 1.0, 0.0]], np.float32), (n, 1))
    pix = np.stack([np.arange(n) % 20, np.arange(n) // 20], axis=1)
    samples = select_samples(device, pos, nrm, pix, 20, 15, 40)
    assert samples.stats["seeds"] == 40
    assert len(samples.indices) == 1
    assert (samples.cluster_of == 0).all()
    check_finite(samples)


def test_one_seed_makes_one_cluster_whose_sample_is_nearest_the_centre(device):
    pos, nrm, pix = shading_points("sphere", SIZE, SIZE)
    samples = select_samples(device, pos, nrm, pix, SIZE, SIZE, 1)
    assert (samples.cluster_of == 0).all()
    to_centre = all_eps(samples, pos, nrm)[:, 0]
    assert to_centre[samples.indices[0]] <= to_centre.min() + 1e-6
    # one cluster's centre is the mean of every point
    np.testing.assert_allclose(samples.centre_positions[0], pos.astype(np.float64).mean(axis=0), atol=1e-5)


def test_one_seed_per_point_makes_every_point_its_own_sample(device):
    pos, nrm, pix = shading_points("two_planes", 24, 24)
    samples = select_samples(device, pos, nrm, pix, 24, 24, len(pos))
    assert len(samples.indices) == len(pos)
    np.testing.assert_array_equal(samples.indices[samples.cluster_of], np.arange(len(pos)))
    samples = select_samples(device, pos, nrm, pix, 24, 24, 10 * len(pos))
    assert len(samples.indices) == len(pos)


def test_zero_points_give_an_empty_sample_set(device):
    none = np.zeros((0, 3), np.float32)
    samples = select_samples(device, none, none, np.zeros((0, 2), np.int32), 16, 16, 100)
    assert len(samples.indices) == 0 and len(samples.cluster_of) == 0
    assert samples.stats["clusters"] == 0


def test_pixels_outside_the_image_are_refused(device):
    pos, nrm, pix = shading_points("plane", 16, 16)
    with pytest.raises(ValueError, match="outside"):
        select_samples(device, pos, nrm, pix, 8, 16, 10)


# -- scale ------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", ["two_planes", "box"])
def test_scaled_scenes_select_the_same_samples(device, shape):
    unit = select_samples(device, *shading_points(shape, SIZE, SIZE), SIZE, SIZE, 300)
    for scale in (1e-3, 1e4):
        pos, nrm, pix = shading_points(shape, SIZE, SIZE, scale=scale)
        scaled = select_samples(device, pos, nrm, pix, SIZE, SIZE, 300)
        np.testing.assert_array_equal(scaled.indices, unit.indices)
        np.testing.assert_array_equal(scaled.cluster_of, unit.cluster_of)
        assert scaled.stats["alpha"] == pytest.approx(unit.stats["alpha"] / scale, rel=1e-6)
