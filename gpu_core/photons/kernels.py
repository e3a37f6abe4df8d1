"""Kernel objects retrieved once per built program (retrieval costs a
kernel creation each time in pyopencl)."""

from __future__ import annotations

import threading

import pyopencl as cl

_CACHE: dict = {}
_LOCK = threading.Lock()


def kernel(program: cl.Program, name: str) -> cl.Kernel:
    """The kernel ``name`` of ``program``, created on first use."""
    key = (id(program), name)
    with _LOCK:
        if key not in _CACHE:
            # the program is kept alive with its kernel, so its id stays unique
            _CACHE[key] = (program, cl.Kernel(program, name))
        return _CACHE[key][1]


class Kernels:
    """Attribute access to the cached kernels of one program."""

    def __init__(self, program: cl.Program):
        self._program = program

    def __getattr__(self, name: str) -> cl.Kernel:
        return kernel(self._program, name)
