"""One OpenCL device: its context and queue, its programs and kernels, and
every byte that crosses between the host and it.

All host <-> device copies go through ``to_device`` / ``to_host`` (and the
array helpers), which count the bytes of the calling thread, so a render can
report what it moved (``transfers()``). One in-order queue per device keeps
the work of every thread ordered; kernels are shared by every thread and
launched under their own locks (kernels.py).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from pyopencl.tools import ImmediateAllocator, MemoryPool

from .kernels import Kernel
from .programs import Programs


@dataclass
class PendingRead:
    """A read queued without waiting (Device.read_later)."""

    values: np.ndarray
    event: cl.Event

    def wait(self) -> np.ndarray:
        """The values, once the read is done."""
        self.event.wait()
        return self.values


@dataclass
class Transfers:
    """Bytes moved by one thread: host to device and device to host."""

    to_device: int = 0
    to_host: int = 0

    def since(self, earlier: "Transfers") -> "Transfers":
        return Transfers(self.to_device - earlier.to_device, self.to_host - earlier.to_host)


@dataclass
class Device:
    """An OpenCL context and in-order queue on one device."""

    context: cl.Context
    queue: cl.CommandQueue
    device: cl.Device
    fallback_message: str = ""
    _kernels: dict = field(default_factory=dict)
    _memo: dict = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _moved: threading.local = field(default_factory=threading.local)
    _pool: MemoryPool | None = None
    _pool_lock: threading.Lock = field(default_factory=threading.Lock)

    def __post_init__(self):
        self.programs = Programs(self.context, self.device)

    # -- what it is -------------------------------------------------------------

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def is_cpu(self) -> bool:
        return bool(self.device.type & cl.device_type.CPU)

    @property
    def compute_units(self) -> int:
        return int(self.device.max_compute_units)

    @property
    def max_alloc_bytes(self) -> int:
        return int(self.device.max_mem_alloc_size)

    @property
    def global_mem_bytes(self) -> int:
        return int(self.device.global_mem_size)

    @property
    def builds(self):
        """Every program build of this process (BuildRecord)."""
        return self.programs.builds

    # -- programs and kernels ---------------------------------------------------

    def program(self, name: str, defines: dict | None = None) -> cl.Program:
        """The built program ``name`` (relative to the include root)."""
        return self.programs.get(name, defines)

    def kernel(self, program: str, name: str, defines: dict | None = None) -> Kernel:
        """Kernel ``name`` of ``program`` built with ``defines``: one object per
        device, made on first use."""
        key = (program, name) if not defines else (program, tuple(sorted(defines.items())), name)
        found = self._kernels.get(key)  # a dict read needs no lock; making one does
        if found is None:
            made = Kernel(self.queue, cl.Kernel(self.program(program, defines), name), self.device)
            with self._lock:
                found = self._kernels.setdefault(key, made)
        return found

    def memo(self, key, make: Callable[[], object]):
        """A per-device object (a pyopencl scan kernel, say) made once by ``make``."""
        with self._lock:
            found = self._memo.get(key)
        if found is None:
            made = make()
            with self._lock:
                found = self._memo.setdefault(key, made)
        return found

    # -- memory -----------------------------------------------------------------

    def empty(self, nbytes: int) -> cl.Buffer:
        """An uninitialised read-write buffer of at least 16 bytes, from the
        device's pool (pyopencl's MemoryPool): a buffer a render let go is
        handed to the next one that fits instead of a new allocation (a
        Preview frame makes ~1,860; on NVIDIA's driver reuse made it a
        fifth faster). Safe on the one in-order queue: work queued on the
        old owner runs first. Where the driver is out of memory the pool
        gives its unused buffers back and tries again."""
        with self._pool_lock:
            if self._pool is None:
                self._pool = MemoryPool(ImmediateAllocator(self.queue))
            return self._pool.allocate(max(int(nbytes), 16))

    def free_held(self) -> None:
        """Give the pool's unused buffers back to the driver."""
        with self._pool_lock:
            if self._pool is not None:
                self._pool.free_held()

    def zeros(self, nbytes: int) -> cl.Buffer:
        """A buffer of ``nbytes`` zero bytes (at least 16)."""
        buf = self.empty(nbytes)
        self.fill(buf, 0, max(int(nbytes), 16))
        return buf

    def fill(self, buf: cl.Buffer, value: int, nbytes: int, dtype=np.int32) -> None:
        """Set ``nbytes`` of ``buf`` (a multiple of 4) to ``value`` repeated."""
        cl.enqueue_fill_buffer(self.queue, buf, np.full(1, value, dtype), 0, int(nbytes) // 4 * 4)

    def copy(self, dst: cl.Buffer, src: cl.Buffer, nbytes: int, dst_offset: int = 0, src_offset: int = 0) -> None:
        """A device-to-device copy (moves nothing across the host)."""
        if nbytes > 0:
            cl.enqueue_copy(self.queue, dst, src, byte_count=int(nbytes), dst_offset=int(dst_offset),
                            src_offset=int(src_offset))

    def to_device(self, array: np.ndarray, writable: bool = False) -> cl.Buffer:
        """A new device buffer holding ``array`` (at least 16 bytes)."""
        array = np.ascontiguousarray(array)
        flags = cl.mem_flags.READ_WRITE if writable else cl.mem_flags.READ_ONLY
        self._count("to_device", array.nbytes)
        if array.nbytes == 0:
            return cl.Buffer(self.context, flags, size=16)
        return cl.Buffer(self.context, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)

    def write(self, buf: cl.Buffer, array: np.ndarray, offset: int = 0) -> None:
        """Copy ``array`` into ``buf`` at byte ``offset``."""
        array = np.ascontiguousarray(array)
        if array.nbytes:
            self._count("to_device", array.nbytes)
            cl.enqueue_copy(self.queue, buf, array, dst_offset=int(offset))

    def to_host(self, buf: cl.Buffer, out: np.ndarray, offset: int = 0) -> np.ndarray:
        """Fill ``out`` from ``buf`` (byte ``offset``), waiting for the copy."""
        if out.nbytes:
            self._count("to_host", out.nbytes)
            cl.enqueue_copy(self.queue, out, buf, src_offset=int(offset))
        return out

    def read(self, buf: cl.Buffer, shape, dtype, offset: int = 0) -> np.ndarray:
        """A new host array of ``shape`` and ``dtype`` read from ``buf``."""
        return self.to_host(buf, np.empty(shape, dtype), offset)

    def read_later(self, buf: cl.Buffer, shape, dtype) -> "PendingRead":
        """A read of ``buf`` queued behind the work queued so far and not
        waited for: the host queues more work, then waits on the result
        (``PendingRead.wait``) while the device runs it."""
        out = np.empty(shape, dtype)
        self._count("to_host", out.nbytes)
        return PendingRead(out, cl.enqueue_copy(self.queue, out, buf, is_blocking=False))

    def read_xyz(self, buf: cl.Buffer, count: int) -> np.ndarray:
        """(count, 3) float32: the xyz of ``count`` float4 rows of ``buf``."""
        return self.read(buf, (count, 4), np.float32)[:, :3].copy()

    def scalar(self, buf: cl.Buffer, dtype=np.int32, index: int = 0):
        """One value of ``buf``."""
        return self.read(buf, 1, dtype, index * np.dtype(dtype).itemsize)[0]

    # -- pyopencl arrays (for pyopencl's scan, reduction and sort) --------------

    def array(self, n: int, dtype) -> cla.Array:
        """An uninitialised device array of ``n`` elements (at least one)."""
        dtype = np.dtype(dtype)
        n = max(int(n), 1)
        return self._wrap(self.empty(n * dtype.itemsize), n, dtype)

    def array_from(self, values: np.ndarray) -> cla.Array:
        """A device array holding ``values``, in a buffer from the pool: a
        fresh buffer's pages are touched first by the copy (a 636k-triangle
        mesh's corners took 20-93 ms to upload that way, 12-14 ms pooled)."""
        values = np.ascontiguousarray(values)
        self._count("to_device", values.nbytes)
        if values.ndim != 1 or not values.size:
            return cla.to_device(self.queue, values)
        buf = self.empty(values.nbytes)
        cl.enqueue_copy(self.queue, buf, values)
        return self._wrap(buf, len(values), values.dtype)

    def get(self, array: cla.Array) -> np.ndarray:
        """A device array's values on the host."""
        self._count("to_host", array.nbytes)
        return array.get()

    def view(self, buf: cl.Buffer, n: int, dtype) -> cla.Array:
        """``n`` elements of ``buf`` seen as a device array (no copy)."""
        return self._wrap(buf, max(int(n), 1), np.dtype(dtype))

    def _wrap(self, buf: cl.Buffer, n: int, dtype: np.dtype) -> cla.Array:
        """A one-dimensional device array of ``n`` elements over ``buf``.
        pyopencl's fast constructor (the one its own slicing uses): the
        checked one spends ~50 us in numpy on the shape, a third of a small
        point tree's build, which makes dozens of arrays per level."""
        return cla.Array(None, (n,), dtype, data=buf, strides=(dtype.itemsize,), _fast=True, _size=n,
                         _context=self.context, _queue=self.queue)

    # -- transfer accounting ----------------------------------------------------

    def transfers(self) -> Transfers:
        """Bytes the calling thread has moved so far."""
        return Transfers(getattr(self._moved, "to_device", 0), getattr(self._moved, "to_host", 0))

    def _count(self, direction: str, nbytes: int) -> None:
        setattr(self._moved, direction, getattr(self._moved, direction, 0) + int(nbytes))
