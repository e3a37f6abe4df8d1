"""Device scan, stable radix sort and group-by-key (kernels/cache_sort.cl).

The irradiance cache groups points by quadtree cell, by cluster, by grid
cell and by hash bucket. Each grouping is a stable sort of (key, index)
pairs followed by the run of every key, so a group lists its members in
index order and any sum over a group comes out the same on every run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .cache_kernels import kernel
from .device import Device

_PROGRAM = "cache_sort.cl"
_SERIAL_MAX = 4096  # arrays up to this length are scanned by one work item
_CHUNK = 256  # elements per work item in chunked passes
_DIGIT_BITS = 4  # matches CACHE_RADIX in cache_sort.cl


def _k(device: Device, name: str) -> cl.Kernel:
    return kernel(device, _PROGRAM, name)


def _chunks(n: int) -> int:
    return (n + _CHUNK - 1) // _CHUNK


def iota(device: Device, n: int) -> cl.Buffer:
    """A device buffer holding 0, 1, ..., n - 1 (int32)."""
    out = device.empty(4 * n)
    if n:
        _k(device, "Cache_iota")(device.queue, (n,), None, out, np.int32(n))
    return out


def zeros(device: Device, nbytes: int) -> cl.Buffer:
    """A device buffer of ``nbytes`` zero bytes."""
    buf = device.empty(nbytes)
    cl.enqueue_fill_buffer(device.queue, buf, np.zeros(1, np.int32), 0, max(int(nbytes), 16) // 4 * 4)
    return buf


def scan(device: Device, data: cl.Buffer, n: int, total: cl.Buffer | None = None) -> None:
    """Exclusive prefix sum of ``n`` int32 in place; the sum goes to ``total[0]``."""
    if total is None:
        total = device.empty(4)
    if n <= _SERIAL_MAX:
        _k(device, "Cache_scan_serial")(device.queue, (1,), None, data, np.int32(n), total)
        return
    chunks = _chunks(n)
    sums = device.empty(4 * chunks)
    args = (np.int32(n), np.int32(_CHUNK))
    _k(device, "Cache_scan_reduce")(device.queue, (chunks,), None, data, *args, sums, np.int32(chunks))
    scan(device, sums, chunks, total)
    _k(device, "Cache_scan_apply")(device.queue, (chunks,), None, data, *args, sums, np.int32(chunks))


def scan_total(device: Device, data: cl.Buffer, n: int) -> int:
    """Exclusive prefix sum in place; returns the sum."""
    total = device.empty(4)
    scan(device, data, n, total)
    out = np.zeros(1, np.int32)
    cl.enqueue_copy(device.queue, out, total)
    return int(out[0])


def sort_pairs(device: Device, keys: cl.Buffer, values: cl.Buffer, n: int, key_bound: int):
    """Stable sort of ``n`` (uint32 key < key_bound, int32 value) pairs.

    Returns new ``(keys, values)`` buffers; the inputs are left as they are
    (or returned themselves when every key is 0).
    """
    bits = max(int(key_bound) - 1, 0).bit_length()
    passes = (bits + _DIGIT_BITS - 1) // _DIGIT_BITS
    if n <= 1 or passes == 0:
        return keys, values
    chunks = _chunks(n)
    table = device.empty(4 * 16 * chunks)
    spare = [(device.empty(4 * n), device.empty(4 * n)), (device.empty(4 * n), device.empty(4 * n))]
    src = (keys, values)
    count, scatter = _k(device, "Cache_radix_count"), _k(device, "Cache_radix_scatter")
    for p in range(passes):
        shift = np.int32(p * _DIGIT_BITS)
        dst = spare[p % 2]
        count(device.queue, (chunks,), None, src[0], np.int32(n), shift, np.int32(_CHUNK), table, np.int32(chunks))
        scan(device, table, 16 * chunks)
        scatter(device.queue, (chunks,), None, src[0], src[1], dst[0], dst[1], np.int32(n), shift,
                np.int32(_CHUNK), table, np.int32(chunks))
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
    sorted_keys, order = sort_pairs(device, keys, iota(device, n), n, key_count)
    start, end = zeros(device, 4 * key_count), zeros(device, 4 * key_count)
    if n:
        _k(device, "Cache_group_ranges")(device.queue, (n,), None, sorted_keys, np.int32(n), start, end)
    return Groups(order=order, keys=sorted_keys, start=start, end=end, key_count=key_count)
