"""The OpenCL devices this computer offers, with their OpenCL and driver
versions, for the preferences and for a clear message when there is none.

Only names and versions are read (gpu_core.device.describe_devices): no
context is opened, no kernel runs. Devices are numbered as gpu_core numbers
them ("P:D"), so a choice made here is a device spec gpu_core understands.
"""

from __future__ import annotations

import platform
import sys
from dataclasses import dataclass
from functools import lru_cache


@dataclass(frozen=True)
class Survey:
    devices: tuple  # gpu_core.device.DeviceInfo, in order
    problem: str = ""  # with no device: one line saying what to install


def install_hint() -> str:
    """What to install to get an OpenCL device on this computer."""
    if sys.platform.startswith("linux") and platform.machine().lower() in ("x86_64", "amd64"):
        return "Install your GPU's OpenCL driver, or the Linux x64 GPU GI extension, which bundles a CPU device."
    return "Install your GPU vendor's driver with OpenCL support."


@lru_cache(maxsize=1)
def survey() -> Survey:
    """The devices found (asked once: the OpenCL loader lists its platforms once per process)."""
    try:
        from gpu_core.device import describe_devices
    except ImportError as err:  # pyopencl missing, or its library failed to load
        return Survey((), f"pyopencl cannot be imported ({err}). Install GPU GI as an extension: it bundles pyopencl.")
    devices = tuple(describe_devices())
    if not devices:
        return Survey((), f"No OpenCL device found. {install_hint()}")
    return Survey(devices)
