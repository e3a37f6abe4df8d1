"""Kernel objects of the irradiance-cache programs, created once per device."""

from __future__ import annotations

import threading

import pyopencl as cl

from .device import Device

_KERNELS: dict[int, tuple[Device, dict]] = {}
_LOCK = threading.Lock()


def kernel(device: Device, program: str, name: str, defines: dict | None = None) -> cl.Kernel:
    """The kernel ``name`` of ``kernels/<program>`` built with ``defines``."""
    key = (program, tuple(sorted((defines or {}).items())), name, threading.get_ident())
    with _LOCK:
        _, table = _KERNELS.setdefault(id(device), (device, {}))
        found = table.get(key)
    if found is None:
        # one object per thread: launching sets its arguments, which is not thread-safe
        found = cl.Kernel(device.program(program, defines), name)
        with _LOCK:
            table[key] = found
    return found
