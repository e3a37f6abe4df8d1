"""Scan and compaction on the device (pyopencl.scan), one kernel each per context."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl.scan import GenericScanKernel, InclusiveScanKernel

_KERNELS: dict = {}


def _kernels(context: cl.Context):
    """The inclusive int sum and the index compaction for ``context``, built once."""
    key = id(context)
    if key not in _KERNELS:
        inclusive = InclusiveScanKernel(context, np.int32, "a+b", neutral="0")
        compact = GenericScanKernel(
            context,
            np.int32,
            arguments="__global const int *cls, __global int *out, __global int *count, const int which, const int base",
            input_expr="cls[i] == which ? 1 : 0",
            scan_expr="a+b",
            neutral="0",
            output_statement="if (prev_item != item) out[item - 1] = base + i; if (i + 1 == N) *count = item;",
        )
        _KERNELS[key] = (context, inclusive, compact)
    return _KERNELS[key][1:]


def inclusive_sum(queue: cl.CommandQueue, values: cla.Array, out: cla.Array | None = None) -> cla.Array:
    """Inclusive prefix sum of an int32 array (into ``out``, else in place)."""
    inclusive, _ = _kernels(queue.context)
    if len(values) == 0:
        return values if out is None else out
    return inclusive(values, out, queue=queue)


def compact(queue: cl.CommandQueue, cls: cla.Array, which: int, base: int = 0) -> tuple[cla.Array, int]:
    """``base + i`` for every ``i`` with ``cls[i] == which``, in order, and how many."""
    _, kernel = _kernels(queue.context)
    n = len(cls)
    if n == 0:
        return cla.empty(queue, 1, np.int32), 0
    out = cla.empty(queue, n, np.int32)
    count = cla.empty(queue, 1, np.int32)
    kernel(cls, out, count, np.int32(which), np.int32(base), queue=queue)
    return out, int(count.get()[0])
