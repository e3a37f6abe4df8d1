"""Data-parallel primitives on the device, one home for all of them:
prefix sums, reductions, compaction, gathers, bounding boxes, and a stable
radix sort with group-by-key (primitives.cl).

They are written here rather than taken from pyopencl because of what they
cost before the first image: on the CPU device each of pyopencl's generic
scan kernels took 3.4 s and each reduction kernel 1.3 s to compile (and a
render used twenty of them), where this one program compiles in about a
second. Every work item walks one chunk of consecutive elements in order,
so results are the same on every run.

The irradiance cache groups points by quadtree cell, by cluster, by grid
cell and by hash bucket: each grouping is a stable sort of (key, index)
pairs followed by the run of every key, so a group lists its members in
index order and any sum over a group comes out the same on every run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes

from .constants import PRIM_RADIX_BITS, PRIM_SORT_GROUP
from .device import Device

_PROGRAM = "device/primitives.cl"
CHUNK = 256  # elements per work item (primitives.cl PRIM_CHUNK)
_SERIAL_MAX = 4096  # prefix sums up to this length run in one work item
# pairs one work-group sorts at most (Prim_radix_sort_group). A CPU device's work-item sorts
# alone what two cores' chunked sort does in three launches a pass, and faster at every size
# measured on two cores (1k pairs 0.17 -> 0.07 ms, 27k 0.38 -> 0.28, 303k 6.9 -> 2.7, 1M 17.8 ->
# 12.5); the chunked sort's kernels share out over the cores and one work-item's do not, so the
# bound falls as cores are added. A GPU's work-group (its kernel's local size, at most
# PRIM_SORT_GROUP) walks runs of consecutive pairs at memory latency: short arrays only (not timed
# on a GPU: the launches it saves are what its frames wait on).
SORT_CPU_ELEMENTS = 1 << 20  # over the compute units
SORT_GPU_MAX = 4096
_SCAN_TYPES = {"int": np.dtype(np.int32), "long": np.dtype(np.int64), "int8": np.dtype((np.int32, 8))}


def programs() -> list[tuple[str, dict]]:
    """The program of the primitives (for building it up front)."""
    return [(_PROGRAM, {})]


def _k(device: Device, name: str):
    return device.kernel(_PROGRAM, name)


def _chunks(n: int) -> int:
    return -(-n // CHUNK)


def scan(device: Device, data: cl.Buffer, n: int, kind: str = "int", out: cl.Buffer | None = None,
         inclusive: bool = False, total: cl.Buffer | None = None) -> cl.Buffer:
    """Prefix sums of ``n`` values of ``kind`` ("int", "long" or "int8"
    vectors) from ``data`` into ``out`` (in place when None), exclusive
    unless ``inclusive``; the sum of all goes to ``total[0]`` (a new buffer
    when None), which is returned."""
    size = _SCAN_TYPES[kind].itemsize
    out = data if out is None else out
    total = device.empty(size) if total is None else total
    if n <= 0:
        device.fill(total, 0, size)
        return total
    flag = np.int32(inclusive)
    if n <= _SERIAL_MAX:
        _k(device, f"Prim_scan_serial_{kind}").groups(1, 1, data, out, np.int32(n), flag, total)
        return total
    chunks = _chunks(n)
    sums = device.empty(size * chunks)
    _k(device, f"Prim_scan_reduce_{kind}")(chunks, data, np.int32(n), sums, np.int32(chunks))
    scan(device, sums, chunks, kind, total=total)
    _k(device, f"Prim_scan_apply_{kind}")(chunks, data, out, np.int32(n), flag, sums, np.int32(chunks))
    return total


def exclusive_scan_total(device: Device, data: cl.Buffer, n: int) -> int:
    """Exclusive prefix sum of ``n`` int32 in place; returns the sum."""
    return int(device.scalar(scan(device, data, n)))


def _reduce(device: Device, name: str, values: cl.Buffer, n: int, dtype, again: str | None = None) -> np.ndarray:
    """One value of ``dtype``: ``values`` (n > 0 of them) reduced by
    Prim_reduce_<name>, its partials by Prim_reduce_<again> (the same by default)."""
    if n <= 0:
        raise ValueError("a reduction needs at least one value")
    kernel = _k(device, f"Prim_reduce_{name}")
    size = np.dtype(dtype).itemsize
    while True:
        chunks = _chunks(n)
        partial = device.empty(size * chunks)
        kernel(chunks, values, np.int32(n), partial, np.int32(chunks))
        if chunks == 1:
            return device.read(partial, 1, dtype)[0]
        values, n = partial, chunks
        kernel = _k(device, f"Prim_reduce_{again or name}")


def sum_int4(device: Device, values: cl.Buffer, n: int) -> np.ndarray:
    """Lane sums of ``n`` int4 values."""
    return _reduce(device, "sum_int4", values, n, np.dtype((np.int32, 4))) if n > 0 else np.zeros(4, np.int32)


def max_int4(device: Device, values: cl.Buffer, n: int) -> np.ndarray:
    """Lane maxima of ``n`` int4 values."""
    return _reduce(device, "max_int4", values, n, np.dtype((np.int32, 4))) if n > 0 else np.zeros(4, np.int32)


def sum_ints(device: Device, values: cl.Buffer, n: int) -> int:
    """The sum of ``n`` int values."""
    if n <= 0:
        return 0
    wide = device.empty(16 * n)
    _k(device, "Prim_int4_of")(n, values, np.int32(n), wide)
    return int(sum_int4(device, wide, n)[0])


def sum_float4(device: Device, values: cl.Buffer, n: int) -> np.ndarray:
    """Lane sums of ``n`` float4 values to float64 accuracy, as float64."""
    if n <= 0:
        return np.zeros(4)
    pairs = device.empty(32 * n)
    _k(device, "Prim_float8_of")(n, values, np.int32(n), pairs)
    total = _reduce(device, "sum_float8", pairs, n, np.dtype((np.float32, 8))).astype(np.float64)
    return total[:4] + total[4:]


def bounds(device: Device, points: cl.Buffer, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of ``n`` float4 points, reduced on the device (w included)
    in one pass over them and one read."""
    both = _reduce(device, "bounds_float4", points, n, np.dtype((np.float32, 8)), again="bounds_float8")
    return both[:4], both[4:]


def float4_rows(device: Device, vectors: np.ndarray) -> cla.Array:
    """(N, 3) float32 ``vectors`` as a device array of N float4 (w = 0),
    uploaded as they are and widened on the device: widened on the host
    they fill a fresh array a third larger first (a 636k-triangle mesh's
    corners: 7 ms)."""
    packed = np.ascontiguousarray(vectors, np.float32).reshape(-1)
    n = len(packed) // 3
    out = device.empty(16 * max(n, 1))
    if n:
        _k(device, "Prim_float4_of_float3")(n, device.array_from(packed).data, np.int32(n), out)
    return device.view(out, n, cltypes.float4)


def same_ints(device: Device, pairs: list[tuple[cl.Buffer, cl.Buffer, int]]) -> bool:
    """Whether, for every ``(a, b, n)`` of ``pairs``, the first ``n`` ints
    of ``a`` and ``b`` are equal, bit for bit (floats compared as their
    bits: NaNs alike, 0 and -0 not); one flag and one read for them all."""
    flag = device.zeros(4)
    for a, b, n in pairs:
        if n > 0:
            _k(device, "Prim_flag_difference")(_chunks(n), a, b, np.int32(n), flag, np.int32(_chunks(n)))
    return not int(device.scalar(flag))


def compact(device: Device, flags: cl.Buffer, n: int, base: int = 0) -> tuple[cl.Buffer, int]:
    """``base + i`` for every ``i`` whose int flag is set, in order, and how many."""
    if n <= 0:
        return device.empty(4), 0
    scanned = device.empty(4 * n)
    count = int(device.scalar(scan(device, flags, n, out=scanned)))
    out = device.empty(4 * count)
    _k(device, "Prim_compact")(n, flags, scanned, np.int32(n), np.int32(base), out)
    return out, count


def gather_rows(device: Device, values: cl.Buffer, index: cl.Buffer, n: int) -> cl.Buffer:
    """A new buffer of the float4 rows ``values[index[i]]``, i < n."""
    out = device.empty(16 * n)
    _k(device, "Prim_gather_float4")(n, values, index, np.int32(n), out)
    return out


def gather_ints(device: Device, values: cl.Buffer, index: cl.Buffer, n: int) -> cl.Buffer:
    """A new buffer of the ints ``values[index[i]]``, i < n."""
    out = device.empty(4 * max(n, 1))
    _k(device, "Prim_gather_int")(n, values, index, np.int32(n), out)
    return out


def scatter_rows(device: Device, values: cl.Buffer, index: cl.Buffer, n: int, out: cl.Buffer) -> None:
    """``out[index[i]] = values[i]`` for the float4 rows i < n."""
    _k(device, "Prim_scatter_float4")(n, values, index, np.int32(n), out)


def concatenated(device: Device, parts: list[tuple[cl.Buffer, int]], row_bytes: int) -> cl.Buffer:
    """A new buffer of the first ``count`` rows of each (buffer, count), in order."""
    out = device.empty(row_bytes * max(sum(count for _, count in parts), 1))
    offset = 0
    for buffer, count in parts:
        if count:
            cl.enqueue_copy(device.queue, out, buffer, dst_offset=offset, byte_count=row_bytes * count)
        offset += row_bytes * count
    return out


def indexed_points(device: Device, points: cl.Buffer, n: int) -> cla.Array:
    """(n, 4) float32 device array of the float4 ``points`` with each one's
    index in w (int bits), as the point-tree builder takes them."""
    out = device.array(4 * n, np.float32).reshape(max(n, 1), 4)
    _k(device, "Prim_indexed_points")(n, points, np.int32(n), out.data)
    return out[:n]


def iota(device: Device, n: int) -> cl.Buffer:
    """A device buffer holding 0, 1, ..., n - 1 (int32)."""
    out = device.empty(4 * n)
    _k(device, "Prim_iota")(n, out, np.int32(n))
    return out


def sort_group_max(device: Device) -> int:
    """The most pairs the device sorts by one work-group."""
    return SORT_CPU_ELEMENTS // max(device.compute_units, 1) if device.is_cpu else SORT_GPU_MAX


def sort_pairs(device: Device, keys: cl.Buffer, values: cl.Buffer | None, n: int, key_bound: int,
               group_max: int | None = None):
    """Stable sort of ``n`` (uint32 key < key_bound, int32 value) pairs
    (``values`` None: the indices 0 .. n - 1).

    Returns new ``(keys, values)`` buffers; the inputs are left as they are
    (or returned themselves when every key is 0). Up to ``group_max`` pairs
    (None: sort_group_max) are sorted by one work-group in one launch
    (Prim_radix_sort_group), more by chunks, three launches a pass.
    """
    bits = max(int(key_bound) - 1, 0).bit_length()
    passes = (bits + PRIM_RADIX_BITS - 1) // PRIM_RADIX_BITS
    if n <= 1 or passes == 0:
        return keys, iota(device, n) if values is None else values
    spare = [(device.empty(4 * n), device.empty(4 * n)), (device.empty(4 * n), device.empty(4 * n))]
    if n <= (sort_group_max(device) if group_max is None else group_max):
        kernel = _k(device, "Prim_radix_sort_group")
        group = kernel.lone_group(device.is_cpu, PRIM_SORT_GROUP)
        kernel.groups(1, group, keys, values, np.int32(values is None), np.int32(n), np.int32(passes), *spare[0],
                      *spare[1])
        return spare[(passes - 1) % 2]
    values = iota(device, n) if values is None else values
    chunks = _chunks(n)
    radix = 1 << PRIM_RADIX_BITS
    table = device.empty(4 * radix * chunks)
    src = (keys, values)
    count, scatter = _k(device, "Prim_radix_count"), _k(device, "Prim_radix_scatter")
    for p in range(passes):
        shift = np.int32(p * PRIM_RADIX_BITS)
        dst = spare[p % 2]
        count(chunks, src[0], np.int32(n), shift, table, np.int32(chunks))
        scan(device, table, radix * chunks)
        scatter(chunks, src[0], src[1], dst[0], dst[1], np.int32(n), shift, table, np.int32(chunks))
        src = dst
    return src


@dataclass
class Groups:
    """Members of each key: ``order[start[k]:end[k]]`` in increasing index."""

    order: cl.Buffer  # int32 (n,): member indices sorted by key, then index
    keys: cl.Buffer  # uint32 (n,): the sorted keys
    start: cl.Buffer  # int32 (key_count,)
    end: cl.Buffer  # int32 (key_count,)
    key_count: int


def group(device: Device, keys: cl.Buffer, n: int, key_count: int) -> Groups:
    """Group ``n`` uint32 keys in ``[0, key_count)`` by key."""
    sorted_keys, order = sort_pairs(device, keys, None, n, key_count)
    start, end = device.zeros(4 * key_count), device.zeros(4 * key_count)
    _k(device, "Prim_group_ranges")(n, sorted_keys, np.int32(n), start, end)
    return Groups(order=order, keys=sorted_keys, start=start, end=end, key_count=key_count)
