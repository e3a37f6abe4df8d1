"""Launching kernels: the one launch helper, with the launch discipline.

Every kernel is launched with a fixed local size per device and kernel
(queried once: a multiple of the device's preferred multiple, 64 work-items
on a CPU, 128 on a GPU, never above what the kernel allows), its global size
padded to that (kernels guard their tail) and a zero offset, so a driver
that compiles per launch shape compiles each kernel once. Kernels with
barriers launch whole work-groups of their compile-time group size instead.
Every launch is a 2D grid of rows of at most ROW work-items (device/launch.h
gives a kernel its linear index): PoCL compiles another work-group function
of a kernel for a launch 65,536 work-items wide or wider.

Setting a kernel's arguments is not thread-safe in OpenCL: a launch sets
them and enqueues under the kernel's own lock (the arguments are captured at
enqueue), so the viewport worker and an F12 render can share kernels.
"""

from __future__ import annotations

import threading

import numpy as np
import pyopencl as cl

_TARGET = {"cpu": 64, "gpu": 128}
ROW = 1 << 15  # work-items in a row of a launch grid at most (device/launch.h)


def local_size(kernel: cl.Kernel, device: cl.Device) -> int:
    """The fixed local size of ``kernel`` on ``device``."""
    info = cl.kernel_work_group_info
    largest = int(kernel.get_work_group_info(info.WORK_GROUP_SIZE, device))
    multiple = max(1, int(kernel.get_work_group_info(info.PREFERRED_WORK_GROUP_SIZE_MULTIPLE, device)))
    target = _TARGET["cpu" if device.type & cl.device_type.CPU else "gpu"]
    size = max(multiple, target // multiple * multiple)
    while size > largest and size > multiple:
        size -= multiple
    if size > largest:  # the kernel allows less than one preferred multiple
        size = 1 << (largest.bit_length() - 1)
    return size


def grid(global_size: int, group: int) -> tuple[int, int]:
    """The 2D launch grid of ``global_size`` work-items in groups of
    ``group``: rows of at most ROW work-items, as even as whole groups allow
    (the last row pads by fewer groups than there are rows)."""
    groups = global_size // group
    rows = -(-groups // max(1, ROW // group))
    return -(-groups // rows) * group, rows


class Kernel:
    """One kernel of a built program, shared by every thread."""

    def __init__(self, queue: cl.CommandQueue, kernel: cl.Kernel, device: cl.Device):
        self.queue = queue
        self.kernel = kernel
        self.name = kernel.function_name
        self.local = local_size(kernel, device)
        self._lock = threading.Lock()
        self._typed = False

    def __call__(self, n: int, *args) -> cl.Event | None:
        """``n`` work-items (none when ``n`` <= 0), in groups of the fixed
        local size; the launch's event."""
        if n > 0:
            return self._enqueue(-(-int(n) // self.local) * self.local, self.local, args)
        return None

    def groups(self, count: int, group: int, *args) -> cl.Event | None:
        """``count`` work-groups of ``group`` work-items (kernels with barriers); the launch's event."""
        if count > 0:
            return self._enqueue(int(count) * group, group, args)
        return None

    def lone_group(self, cpu: bool, most: int | None = None) -> int:
        """Work-items of the one work-group of a launch that shares its work
        among them (``groups(1, ...)``): one on a CPU device, whose
        work-items run one after another (one does it all, with no barrier
        to wait at), else the fixed local size, at most ``most``."""
        return 1 if cpu else min(self.local, most or self.local)

    def _enqueue(self, global_size: int, group: int, args) -> cl.Event:
        with self._lock:
            if not self._typed:
                self._declare_scalars(args)
            self.kernel.set_args(*args)
            return cl.enqueue_nd_range_kernel(self.queue, self.kernel, grid(global_size, group), (group, 1))

    def _declare_scalars(self, args) -> None:
        """Tell pyopencl the types of the scalar arguments (numpy scalars on
        the first launch; buffers and structs stay untyped): it then packs
        them directly, where an untyped scalar costs ~15 us per argument and
        launch, a tenth of a small kernel's whole launch on a CPU device."""
        self.kernel.set_scalar_arg_dtypes([a.dtype if isinstance(a, np.generic) else None for a in args])
        self._typed = True
