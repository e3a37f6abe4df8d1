"""Point kd-tree of the photon maps: kNN against brute force, node payloads,
density estimation against analytic irradiance."""

import numpy as np
import pytest

from layout_probe import host_layout, probe
from gpu_core.accel import point_tree_build
from gpu_core.device import kernels
from gpu_core.accel.point_tree import PointTree, knn_capacity, query_programs


def brute_knn(points, queries, k, max_radius=None):
    """Squared distances of the k nearest points (float64), padded with inf."""
    d2 = ((queries[:, None, :].astype(np.float64) - points[None, :, :].astype(np.float64)) ** 2).sum(-1)
    if max_radius is not None:
        d2[d2 > max_radius**2] = np.inf
    d2 = np.sort(d2, axis=1)[:, :k]
    return np.pad(d2, ((0, 0), (0, k - d2.shape[1])), constant_values=np.inf)


def check_knn(tree, points, queries, k, max_radius=None):
    """Distances equal brute force; indices point at points at those distances."""
    idx, d2 = tree.knn(queries, k, max_radius)
    want = brute_knn(points, queries, k, max_radius)
    assert idx.shape == d2.shape == (len(queries), k)
    found = idx >= 0
    assert np.array_equal(found, np.isfinite(want))
    np.testing.assert_allclose(d2[found], want[found], rtol=1e-5, atol=1e-9)
    assert np.all(np.isinf(d2[~found]))
    # each index is a real point at the reported distance, none repeated in a row
    rows = np.nonzero(found)[0]
    real = ((points[idx[found]].astype(np.float64) - queries[rows].astype(np.float64)) ** 2).sum(-1)
    np.testing.assert_allclose(real, d2[found], rtol=1e-5, atol=1e-9)
    for row in idx:
        kept = row[row >= 0]
        assert len(np.unique(kept)) == len(kept)


RNG = np.random.default_rng(7)
CLOUDS = {
    "uniform": RNG.random((4000, 3)),
    "clustered": np.concatenate([RNG.normal(c, 0.003, (300, 3)) for c in RNG.random((8, 3))]),
    "duplicated": np.repeat(RNG.random((60, 3)), 40, axis=0),
    "planar": np.c_[RNG.random((3000, 2)), np.zeros(3000)],
    "identical": np.full((500, 3), 0.25),
}


# the two builds: in one launch (small sets) and level by level
BUILDS = {"one launch": 1 << 20, "level by level": 0}


@pytest.mark.parametrize("build", sorted(BUILDS))
@pytest.mark.parametrize("name", sorted(CLOUDS))
def test_knn_matches_brute_force(device, name, build):
    points = CLOUDS[name].astype(np.float32)
    tree = PointTree.build(device, points, serial_max=BUILDS[build])
    assert ("serial" in tree.stats["ms"]) == (build == "one launch")
    queries = np.concatenate([RNG.random((150, 3)), points[:50]]).astype(np.float32)
    for k in (1, 8, 50):
        check_knn(tree, points, queries, k)


def test_searches_of_one_capacity_bucket_share_a_program_and_each_keeps_its_own_k(device):
    # k 17..32 take one program (a heap of 32), so a preset or a dragged slider compiles nothing new
    assert [knn_capacity(k) for k in (1, 16, 17, 20, 32, 33, 50, 64, 65, 1024)] == [16, 16, 32, 32, 32, 64, 64, 64,
                                                                                    128, 1024]
    assert query_programs(20) == query_programs(32) != query_programs(50)
    points = CLOUDS["uniform"].astype(np.float32)
    tree = PointTree.build(device, points)
    queries = RNG.random((100, 3)).astype(np.float32)
    for k in (17, 20, 31, 32):  # every k of the bucket, on the one program
        check_knn(tree, points, queries, k)
        assert tree.knn(queries, k)[0].shape == (100, k)


def test_knn_within_a_radius(device):
    points = CLOUDS["uniform"].astype(np.float32)
    tree = PointTree.build(device, points)
    check_knn(tree, points, RNG.random((200, 3)).astype(np.float32), 30, max_radius=0.05)


def test_k_larger_than_the_point_count_pads_the_rows(device):
    points = RNG.random((7, 3)).astype(np.float32)
    tree = PointTree.build(device, points)
    queries = RNG.random((20, 3)).astype(np.float32)
    idx, d2 = tree.knn(queries, 12)
    assert np.all(idx[:, 7:] == -1) and np.all(np.isinf(d2[:, 7:]))
    assert sorted(idx[0, :7]) == list(range(7))
    check_knn(tree, points, queries, 12)


def test_empty_tree_finds_nothing(device):
    tree = PointTree.build(device, np.zeros((0, 3), np.float32))
    idx, d2 = tree.knn(np.zeros((5, 3), np.float32), 4)
    assert np.all(idx == -1) and np.all(np.isinf(d2))


def test_queries_far_outside_the_points(device):
    points = RNG.random((2000, 3)).astype(np.float32)
    tree = PointTree.build(device, points)
    queries = np.array([[1e4, 0, 0], [-3e3, 2e3, 5e2], [0.5, 0.5, -1e5]], np.float32)
    check_knn(tree, points, queries, 20)


def test_bad_arguments_raise(device):
    tree = PointTree.build(device, RNG.random((10, 3)).astype(np.float32))
    with pytest.raises(ValueError):
        tree.knn(np.zeros((1, 3), np.float32), 0)
    with pytest.raises(ValueError):
        PointTree.build(device, np.array([[0, 0, np.nan]], np.float32))


def count_reads(device, monkeypatch) -> list:
    """A list that grows by one at every read from the device."""
    reads = []
    for name in ("to_host", "get"):
        original = getattr(type(device), name)
        monkeypatch.setattr(type(device), name, lambda self, *a, _f=original, **k: (reads.append(1), _f(self, *a, **k))[1])
    return reads


def test_the_build_waits_on_one_read_per_small_level_and_none_in_the_large_stage(device, monkeypatch):
    """The large stage's levels queue their counts' reads without waiting
    (one a level, and one for the last level queued, which finds no node);
    the host waits on small levels' reads alone, plus one for the VVH
    radius estimates and one for the node count (the node table has unused
    slots)."""
    reads = count_reads(device, monkeypatch)
    queued = []
    read_later = type(device).read_later
    monkeypatch.setattr(type(device), "read_later", lambda self, *a: (queued.append(1), read_later(self, *a))[1])
    points = CLOUDS["clustered"].astype(np.float32)
    tree = PointTree.build(device, points, serial_max=0)
    assert tree.stats["large_levels"] >= 3
    assert len(queued) == tree.stats["large_levels"] + 1
    assert len(reads) <= tree.stats["small_levels"] + 2
    check_knn(tree, points, RNG.random((50, 3)).astype(np.float32), 8)


def test_the_host_waits_on_a_large_level_s_counts_only_once_the_next_level_is_queued(device, monkeypatch):
    """Between a level's queued read and the wait on it the host queues
    the next level, so the device has work while the host waits."""
    log = []
    launch = point_tree_build._Build.launch
    monkeypatch.setattr(point_tree_build._Build, "launch",
                        lambda self, name, *a: (log.append(name), launch(self, name, *a)))
    read_later = type(device).read_later

    def logged_read(self, *args):
        pending = read_later(self, *args)
        log.append("read")
        wait = pending.wait
        monkeypatch.setattr(pending, "wait", lambda: (log.append("wait"), wait())[1])
        return pending

    monkeypatch.setattr(type(device), "read_later", logged_read)
    tree = PointTree.build(device, CLOUDS["clustered"].astype(np.float32), serial_max=0)
    large = log[: log.index("PointBuild_small_roots")]
    reads = [i for i, entry in enumerate(large) if entry == "read"]
    waits = [i for i, entry in enumerate(large) if entry == "wait"]
    assert len(reads) == len(waits) == tree.stats["large_levels"] + 1
    for read, wait in zip(reads[:-1], waits[:-1]):
        assert "PointBuild_chunk_bounds" in large[read:wait]


def test_the_one_launch_build_reads_back_once(device, monkeypatch):
    reads = count_reads(device, monkeypatch)
    tree = PointTree.build(device, CLOUDS["clustered"].astype(np.float32), serial_max=1 << 20)
    assert tree.stats["large_levels"] >= 3 and len(reads) == 1


def photon_cloud(kind: str, n: int) -> tuple:
    """n points of a kind with photon power, directions and normals."""
    rng = np.random.default_rng(n)
    points = rng.random((n, 3))
    if kind == "walls":  # photons on the six walls of a box
        points[np.arange(n), rng.integers(0, 3, n)] = rng.integers(0, 2, n)
    elif kind == "repeated":
        points[: n * 9 // 10] = points[0]
    elif kind == "clusters":
        points = rng.normal(size=(n, 3)) * 1e-4 + rng.integers(0, 50, (n, 1))
    directions = rng.normal(size=(n, 3))
    return tuple(a.astype(np.float32) for a in (points, rng.random((n, 3)), directions, -directions))


def built_arrays(tree: PointTree) -> dict:
    """Everything a build leaves on the device, as host arrays."""
    built = tree._built
    names = ("nodes", "info", "points", "power", "direction", "normal")
    return {name: getattr(built, name).get() for name in names if getattr(built, name) is not None}


def assert_same_tree(a: PointTree, b: PointTree) -> None:
    """The same nodes, payloads, point order and build statistics, bit for bit."""
    keys = ("nodes", "large_levels", "small_levels", "small_roots", "radius")
    assert {k: a.stats[k] for k in keys} == {k: b.stats[k] for k in keys}
    arrays_a, arrays_b = built_arrays(a), built_arrays(b)
    assert arrays_a.keys() == arrays_b.keys()
    for name in arrays_a:
        assert arrays_a[name].tobytes() == arrays_b[name].tobytes(), name


@pytest.mark.parametrize("group", [1, 64], ids=["one_work_item", "work_group_of_64"])
@pytest.mark.parametrize("kind", ["walls", "repeated", "clusters"])
@pytest.mark.parametrize("n", [2, 32, 33, 1000, 5000])
def test_the_one_launch_build_makes_the_level_by_level_tree(device, kind, n, group):
    """The same steps in the same order, by one work-item or shared among a
    work-group: the same tree bit for bit, with and without photons, with
    the radius estimated or given."""
    points, power, directions, normals = photon_cloud(kind, n)
    for photons, radius in (((power, directions, normals), None), ((None, None, None), 0.05)):
        trees = [PointTree.build(device, points, *photons, k_hint=20, radius=radius, serial_max=m, serial_group=group)
                 for m in (1 << 20, 0)]
        assert "serial" in trees[0].stats["ms"] and "serial" not in trees[1].stats["ms"]
        assert_same_tree(*trees)


def test_the_one_launch_build_falls_back_when_its_node_table_is_full(device, monkeypatch):
    points, power, directions, normals = photon_cloud("walls", 3000)
    wanted = PointTree.build(device, points, power, directions, normals, serial_max=0)
    monkeypatch.setattr(point_tree_build, "SERIAL_ROOM", 0.0)
    monkeypatch.setattr(point_tree_build, "SERIAL_SLACK", 40)
    tree = PointTree.build(device, points, power, directions, normals, serial_max=1 << 20)
    assert "serial" not in tree.stats["ms"]
    assert_same_tree(tree, wanted)


def test_small_sets_are_built_in_one_launch_by_one_work_item_on_a_cpu_and_a_work_group_elsewhere(device, monkeypatch):
    groups = []
    original = kernels.Kernel.groups
    monkeypatch.setattr(kernels.Kernel, "groups", lambda self, count, group, *args: (
        groups.append((self.name, count, group)), original(self, count, group, *args))[1])
    points = photon_cloud("walls", point_tree_build.SERIAL_MAX + 1)[0]
    assert "serial" in PointTree.build(device, points[:-1]).stats["ms"]
    serial = device.kernel(point_tree_build.PROGRAM, "PointBuild_serial")
    assert groups == [("PointBuild_serial", 1, 1 if device.is_cpu else serial.local)]
    assert "serial" not in PointTree.build(device, points).stats["ms"]


def test_node_payloads_sum_their_photons(device):
    n = 3000
    points = RNG.random((n, 3)).astype(np.float32)
    power = RNG.random((n, 3)).astype(np.float32)
    up = np.tile([0.0, 0.0, 1.0], (n, 1)).astype(np.float32)
    tree = PointTree.build(device, points, power=power, directions=up, normals=up)
    info = tree.node_info()
    order = tree.leaf_order()
    assert sorted(order) == list(range(n))
    root = info[0]
    assert root["count"] == n and root["depth"] == 0
    np.testing.assert_allclose(root["power"][:3], power.sum(0), rtol=1e-4)
    np.testing.assert_allclose(root["lo"][:3], points.min(0))
    np.testing.assert_allclose(root["normal"][:3], [0, 0, 1], atol=1e-6)
    # every node: its photons are [first, first + count) of the leaf order
    for node in info[:: max(1, len(info) // 200)]:
        if node["count"] == 0:  # the empty side of an empty-space cut
            continue
        mine = order[node["first"] : node["first"] + node["count"]]
        np.testing.assert_allclose(node["power"][:3], power[mine].sum(0), rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(node["lo"][:3], points[mine].min(0))
        np.testing.assert_allclose(node["hi"][:3], points[mine].max(0))
        # E~_p = sum (w_i . n_p) Phi_i / r_p^2, all photons arriving along n_p here
        r_p = node["lo"][3]
        np.testing.assert_allclose(node["irradiance"][:3], power[mine].sum(0) / r_p**2, rtol=1e-4)


@pytest.mark.parametrize("filter", ["box", "cone", "epanechnikov"])
def test_density_estimate_of_a_uniform_flux(device, filter):
    """Photons of equal power spread evenly on the unit square: E = total power."""
    n = 40000
    points = np.c_[RNG.random((n, 2)), np.zeros(n)].astype(np.float32)
    power = np.full((n, 3), 2.0 / n, np.float32)
    up = np.tile([0.0, 0.0, 1.0], (n, 1)).astype(np.float32)
    tree = PointTree.build(device, points, power=power, directions=up, normals=up)
    queries = np.c_[0.2 + 0.6 * RNG.random((400, 2)), np.zeros(400)].astype(np.float32)
    normals = np.tile([0.0, 0.0, 1.0], (400, 1))
    e = tree.irradiance(queries, normals, k=100, filter=filter)
    assert abs(e.mean() - 2.0) < 0.05 * 2.0
    # photons arriving from behind the surface do not count
    assert np.all(tree.irradiance(queries, -normals, k=100, filter=filter) == 0)
    radiance = tree.radiance(queries, normals, np.full((400, 3), 0.5), k=100, filter=filter)
    np.testing.assert_allclose(radiance, e * 0.5 / np.pi, rtol=1e-5)


def test_struct_twins_match_the_device_layout(device):
    rows = host_layout()
    out = probe(device, len(rows) + 2)
    ours = {"PointNode", "BuildNode", "Chunk", "BuildSums", "PhotonEmitter"}
    host = [row for row in rows if row[0] in ours]
    assert [(s, f, int(v)) for (s, f, _), v in zip(rows, out) if s in ours] == host
    assert out[-1] == -1  # the probe reports nothing more
