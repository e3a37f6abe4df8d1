"""Device scan, stable radix sort, group-by-key, bounds and float4 widening
(gpu_core/device/primitives.py) against numpy."""

import numpy as np
import pytest

from gpu_core.device import primitives


def read(device, buf, n, dtype=np.int32):
    return device.to_host(buf, np.empty(n, dtype))


@pytest.mark.parametrize("n", [0, 1, 7, 4096, 4097, 70000])
def test_exclusive_scan_equals_numpy_cumsum(device, n):
    values = np.random.default_rng(n).integers(0, 50, n).astype(np.int32)
    buf = device.to_device(values, writable=True)
    total = primitives.exclusive_scan_total(device, buf, n)
    assert total == values.sum()
    np.testing.assert_array_equal(read(device, buf, n), np.cumsum(values) - values)


@pytest.mark.parametrize("n", [1, 255, 256, 257, 70000])
def test_bounds_in_one_pass_equal_numpy_minima_and_maxima(device, n):
    points = np.random.default_rng(n).normal(0, 1e3, (n, 4)).astype(np.float32)
    points[n // 2] = [-1e30, 3e30, 0, -2]  # a far point in the middle of a chunk
    lo, hi = primitives.bounds(device, device.to_device(points), n)
    np.testing.assert_array_equal(lo, points.min(axis=0))
    np.testing.assert_array_equal(hi, points.max(axis=0))


@pytest.mark.parametrize("n", [0, 1, 3, 70001])
def test_float4_rows_widen_packed_vectors_with_w_zero(device, n):
    vectors = np.random.default_rng(n).normal(0, 1, (n, 3)).astype(np.float32)
    rows = device.get(primitives.float4_rows(device, vectors)).view(np.float32).reshape(-1, 4)[:n]
    np.testing.assert_array_equal(rows[:, :3], vectors)
    assert not rows[:, 3].any()


@pytest.mark.parametrize("n, key_count", [(0, 5), (1, 1), (300, 1), (300, 3), (5000, 16384), (40000, 1 << 21)])
def test_grouping_equals_a_stable_numpy_sort(device, n, key_count):
    keys = np.random.default_rng(key_count).integers(0, key_count, n).astype(np.uint32)
    groups = primitives.group(device, device.to_device(keys), n, key_count)
    order = read(device, groups.order, n)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
    np.testing.assert_array_equal(read(device, groups.keys, n, np.uint32), np.sort(keys))
    start, end = read(device, groups.start, key_count), read(device, groups.end, key_count)
    counts = np.bincount(keys, minlength=key_count)
    np.testing.assert_array_equal(end - start, counts)
    filled = counts > 0
    np.testing.assert_array_equal(start[filled], np.searchsorted(np.sort(keys), np.flatnonzero(filled)))


@pytest.mark.parametrize("gpu_group", [False, True])
@pytest.mark.parametrize("n, key_bound", [(2, 2), (63, 1 << 5), (64, 1 << 9), (65, 3), (1000, 1 << 10),
                                          (5000, 1 << 16), (32768, 1 << 20), (70000, 1 << 20)])
def test_a_short_sort_is_one_launch_of_one_work_group_with_the_chunked_sort_s_order(device, monkeypatch, n, key_bound,
                                                                                   gpu_group):
    """A sort by one work-group is one launch (of one work-item on a CPU
    device, of the kernel's local size on a GPU: both run here), with the
    stable order the chunked sort gives, given values or indices."""
    from gpu_core.device.kernels import Kernel
    if gpu_group:
        monkeypatch.setattr(type(device), "is_cpu", property(lambda self: False))
    rng = np.random.default_rng(n)
    keys = rng.integers(0, key_bound, n).astype(np.uint32)
    values = rng.integers(-1000, 1000, n).astype(np.int32)
    chunked = primitives.sort_pairs(device, device.to_device(keys), device.to_device(values), n, key_bound, group_max=0)
    names = []
    launch, groups = Kernel.__call__, Kernel.groups
    monkeypatch.setattr(Kernel, "__call__", lambda self, *a: (names.append(self.name), launch(self, *a))[1])
    monkeypatch.setattr(Kernel, "groups", lambda self, *a: (names.append(self.name), groups(self, *a))[1])
    given = primitives.sort_pairs(device, device.to_device(keys), device.to_device(values), n, key_bound, group_max=n)
    indexed = primitives.sort_pairs(device, device.to_device(keys), None, n, key_bound, group_max=n)
    assert names == ["Prim_radix_sort_group"] * 2
    order = np.argsort(keys, kind="stable")
    for got_keys, got_values, want in ((*chunked, values[order]), (*given, values[order]), (*indexed, order)):
        np.testing.assert_array_equal(read(device, got_keys, n, np.uint32), keys[order])
        np.testing.assert_array_equal(read(device, got_values, n), want)


def test_a_cpu_device_sorts_more_pairs_by_one_work_item_the_fewer_its_cores_and_a_gpu_short_arrays_only(device,
                                                                                                      monkeypatch):
    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: True))
    bounds = []
    for cores in (2, 16):
        monkeypatch.setattr(type(device), "compute_units", property(lambda self, c=cores: c))
        bounds.append(primitives.sort_group_max(device))
    assert bounds[0] > bounds[1] >= primitives.SORT_GPU_MAX
    monkeypatch.setattr(type(device), "is_cpu", property(lambda self: False))
    assert primitives.sort_group_max(device) == primitives.SORT_GPU_MAX


def test_a_kernel_typed_on_its_first_launch_takes_any_integer_after(device):
    """The launch helper declares a kernel's scalar types from its first
    launch (numpy scalars); later launches may pass Python or other numpy ints."""
    kernel = device.kernel("device/primitives.cl", "Prim_iota")
    for n in (np.int32(5), 9, np.int64(12)):
        out = device.to_device(np.full(16, -1, np.int32), writable=True)
        kernel(int(n), out, n)
        np.testing.assert_array_equal(read(device, out, 16), np.where(np.arange(16) < n, np.arange(16), -1))


def test_device_arrays_are_one_dimensional_views_of_their_buffers(device):
    values = np.arange(10, dtype=np.int64)
    array = device.array_from(values)
    assert array.shape == (10,) and array.dtype == np.int64 and array.nbytes == 80
    np.testing.assert_array_equal(device.get(array), values)
    np.testing.assert_array_equal(device.get(array[3:7]), values[3:7])
    view = device.view(array.data, 4, np.int32)
    np.testing.assert_array_equal(device.get(view), values[:2].view(np.int32))
    assert len(device.array(0, np.float32)) == 1


@pytest.mark.parametrize("n, at", [(1, 0), (255, 254), (256, 255), (257, 256), (70000, 69999), (70000, 12345)])
def test_same_ints_finds_one_differing_bit_anywhere(device, n, at):
    a = np.random.default_rng(n).integers(-2**31, 2**31, n, dtype=np.int64).astype(np.int32)
    b = a.copy()
    assert primitives.same_ints(device, [(device.to_device(a), device.to_device(b), n)])
    b[at] ^= 1 << 17
    assert not primitives.same_ints(device, [(device.to_device(a), device.to_device(b), n)])
    # only the first n count
    assert primitives.same_ints(device, [(device.to_device(a), device.to_device(b), at)])


def test_same_ints_of_several_pairs_finds_a_difference_in_any(device):
    a = np.arange(300, dtype=np.int32)
    same = (device.to_device(a), device.to_device(a.copy()), 300)
    b = a.copy()
    b[7] += 1
    differs = (device.to_device(a), device.to_device(b), 300)
    assert primitives.same_ints(device, [same, same])
    assert not primitives.same_ints(device, [same, differs])
    assert not primitives.same_ints(device, [differs, same])


def test_same_ints_compares_float_bits_not_values(device):
    a = np.array([np.nan, 0.0, 1.0], np.float32)
    assert primitives.same_ints(device, [(device.to_device(a), device.to_device(a.copy()), 3)])  # NaN is itself
    assert not primitives.same_ints(device, [(device.to_device(a), device.to_device(np.array([np.nan, -0.0, 1.0],
                                                                                        np.float32)), 3)])
    assert primitives.same_ints(device, [(device.empty(4), device.empty(4), 0)])
