"""Data-parallel primitives on the device, one home for all of them:
pyopencl's scan and reduction kernels (made once per device, called under a
lock so threads can share them), prefix sums, compaction, bounding boxes,
and a stable radix sort with group-by-key (primitives.cl).

The irradiance cache groups points by quadtree cell, by cluster, by grid
cell and by hash bucket; each grouping is a stable sort of (key, index)
pairs followed by the run of every key, so a group lists its members in
index order and any sum over a group comes out the same on every run.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl import cltypes
from pyopencl.reduction import ReductionKernel
from pyopencl.scan import GenericScanKernel
from pyopencl.tools import get_or_register_dtype

from .constants import PRIM_RADIX_BITS
from .device import Device
from .layout import STRUCTS, structs_header

_PROGRAM = "device/primitives.cl"
_CHUNK = 256  # elements per work item of the sort passes


class _Locked:
    """A pyopencl kernel object that one thread at a time may call."""

    def __init__(self, kernel):
        self._kernel = kernel
        self._lock = threading.Lock()

    def __call__(self, *args, **kwargs):
        with self._lock:
            return self._kernel(*args, **kwargs)


def _register_structs() -> None:
    """Make the shared structs known to pyopencl's code generators by their
    C names (so scan and reduction arguments may point to them)."""
    for struct in STRUCTS:
        get_or_register_dtype(struct.name, struct.dtype)


_register_structs()


def scan_kernel(device: Device, dtype, arguments: str, input_expr: str, output_statement: str,
                neutral: str = "0", scan_expr: str = "a + b") -> _Locked:
    """A pyopencl GenericScanKernel, made once per device and signature; the
    shared structs (device/structs.h) are declared for it."""
    key = ("scan", str(np.dtype(dtype).descr), arguments, input_expr, output_statement, neutral, scan_expr)
    return device.memo(key, lambda: _Locked(GenericScanKernel(
        device.context, dtype, arguments=arguments, input_expr=input_expr, scan_expr=scan_expr,
        neutral=neutral, output_statement=output_statement, preamble=structs_header())))


def reduction_kernel(device: Device, dtype, neutral: str, reduce_expr: str, map_expr: str, arguments: str,
                     preamble: str = "") -> _Locked:
    """A pyopencl ReductionKernel, made once per device and signature; the
    shared structs (device/structs.h) are declared before ``preamble``."""
    key = ("reduce", str(np.dtype(dtype).descr), neutral, reduce_expr, map_expr, arguments, preamble)
    return device.memo(key, lambda: _Locked(ReductionKernel(
        device.context, dtype, neutral=neutral, reduce_expr=reduce_expr, map_expr=map_expr, arguments=arguments,
        preamble=structs_header() + preamble)))


_WITH_TOTAL = "out[i] = prev_item; if (i + 1 == n) total[0] = item;"


def exclusive_scan(device: Device, data: cl.Buffer, n: int, total: cl.Buffer | None = None) -> cl.Buffer:
    """Exclusive prefix sum of ``n`` int32 in place; the sum goes to
    ``total[0]`` (a new one-int buffer if not given), which is returned."""
    total = total if total is not None else device.empty(4)
    if n <= 0:
        device.fill(total, 0, 4)
        return total
    kernel = scan_kernel(device, np.int32, "__global const int *in, __global int *out, __global int *total, const int n",
                         "in[i]", _WITH_TOTAL)
    view = device.view(data, n, np.int32)
    kernel(view, view, device.view(total, 1, np.int32), np.int32(n), size=n, queue=device.queue)
    return total


def exclusive_scan_total(device: Device, data: cl.Buffer, n: int) -> int:
    """Exclusive prefix sum in place; returns the sum."""
    return int(device.scalar(exclusive_scan(device, data, n)))


def inclusive_sum(device: Device, values: cla.Array, out: cla.Array | None = None) -> cla.Array:
    """Inclusive prefix sum of an int32 array (into ``out``, else in place)."""
    if len(values) == 0:
        return values if out is None else out
    out = values if out is None else out
    kernel = scan_kernel(device, np.int32, "__global const int *in, __global int *out", "in[i]", "out[i] = item;")
    kernel(values, out, size=len(values), queue=device.queue)
    return out


def compact(device: Device, classes: cla.Array, which: int, base: int = 0) -> tuple[cla.Array, int]:
    """``base + i`` for every ``i`` with ``classes[i] == which``, in order, and how many."""
    n = len(classes)
    if n == 0:
        return device.array(1, np.int32), 0
    kernel = scan_kernel(
        device, np.int32,
        "__global const int *cls, __global int *out, __global int *count, const int which, const int base",
        "cls[i] == which ? 1 : 0",
        "if (prev_item != item) out[item - 1] = base + i; if (i + 1 == N) *count = item;")
    out, count = device.array(n, np.int32), device.array(1, np.int32)
    kernel(classes, out, count, np.int32(which), np.int32(base), queue=device.queue)
    return out, int(device.get(count)[0])


def bounds(device: Device, points: cl.Buffer, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of ``n`` float4 points, reduced on the device (w included)."""
    view = device.view(points, n, cltypes.float4)
    lo = reduction_kernel(device, cltypes.float4, "(float4)(INFINITY)", "fmin(a, b)", "v[i]", "__global const float4 *v")
    hi = reduction_kernel(device, cltypes.float4, "(float4)(-INFINITY)", "fmax(a, b)", "v[i]", "__global const float4 *v")
    low = lo(view, range=slice(n), queue=device.queue)
    high = hi(view, range=slice(n), queue=device.queue)
    as_floats = [np.frombuffer(device.get(a).tobytes(), np.float32).copy() for a in (low, high)]
    return as_floats[0], as_floats[1]


def iota(device: Device, n: int) -> cl.Buffer:
    """A device buffer holding 0, 1, ..., n - 1 (int32)."""
    out = device.empty(4 * n)
    device.kernel(_PROGRAM, "Prim_iota")(n, out, np.int32(n))
    return out


def sort_pairs(device: Device, keys: cl.Buffer, values: cl.Buffer, n: int, key_bound: int):
    """Stable sort of ``n`` (uint32 key < key_bound, int32 value) pairs.

    Returns new ``(keys, values)`` buffers; the inputs are left as they are
    (or returned themselves when every key is 0).
    """
    bits = max(int(key_bound) - 1, 0).bit_length()
    passes = (bits + PRIM_RADIX_BITS - 1) // PRIM_RADIX_BITS
    if n <= 1 or passes == 0:
        return keys, values
    chunks = -(-n // _CHUNK)
    radix = 1 << PRIM_RADIX_BITS
    table = device.empty(4 * radix * chunks)
    spare = [(device.empty(4 * n), device.empty(4 * n)), (device.empty(4 * n), device.empty(4 * n))]
    src = (keys, values)
    count = device.kernel(_PROGRAM, "Prim_radix_count")
    scatter = device.kernel(_PROGRAM, "Prim_radix_scatter")
    for p in range(passes):
        shift = np.int32(p * PRIM_RADIX_BITS)
        dst = spare[p % 2]
        count(chunks, src[0], np.int32(n), shift, np.int32(_CHUNK), table, np.int32(chunks))
        exclusive_scan(device, table, radix * chunks)
        scatter(chunks, src[0], src[1], dst[0], dst[1], np.int32(n), shift, np.int32(_CHUNK), table, np.int32(chunks))
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
    start, end = device.zeros(4 * key_count), device.zeros(4 * key_count)
    device.kernel(_PROGRAM, "Prim_group_ranges")(n, sorted_keys, np.int32(n), start, end)
    return Groups(order=order, keys=sorted_keys, start=start, end=end, key_count=key_count)


def gather_rows(device: Device, values: cl.Buffer, index: cl.Buffer, n: int) -> cl.Buffer:
    """A new buffer of the float4 rows ``values[index[i]]``, i < n."""
    out = device.empty(16 * n)
    device.kernel(_PROGRAM, "Prim_gather_float4")(n, values, index, np.int32(n), out)
    return out


def indexed_points(device: Device, points: cl.Buffer, n: int) -> cla.Array:
    """(n, 4) float32 device array of the float4 ``points`` with each one's
    index in w (int bits), as the point-tree builder takes them."""
    out = device.array(4 * n, np.float32).reshape(max(n, 1), 4)
    device.kernel(_PROGRAM, "Prim_indexed_points")(n, points, np.int32(n), out.data)
    return out[:n]
