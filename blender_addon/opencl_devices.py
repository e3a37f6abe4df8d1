"""The OpenCL devices this computer offers, with their OpenCL and driver
versions, for the preferences.

Only names and versions are read: no context is opened, no kernel runs.
Devices are numbered as gpu_core numbers them ("P:D", the platform's index
and the device's index in it; platforms without devices are skipped), so a
choice made here is a device spec gpu_core understands.
"""

from __future__ import annotations

import platform
import sys
from dataclasses import dataclass
from functools import lru_cache


@dataclass(frozen=True)
class DeviceInfo:
    spec: str  # "P:D"
    platform: str
    name: str
    kind: str  # "CPU", "GPU" or "other"
    opencl: str  # the device's OpenCL version string
    driver: str  # the driver's version string

    @property
    def label(self) -> str:
        """``"P:D  platform / device"``, as gpu_core.device.list_devices() writes it."""
        return f"{self.spec}  {self.platform} / {self.name}"


@dataclass(frozen=True)
class Survey:
    devices: tuple[DeviceInfo, ...]
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
        import pyopencl as cl
    except Exception as err:  # missing, or its library failed to load
        return Survey((), f"pyopencl cannot be imported ({err}). Install GPU GI as an extension: it bundles pyopencl.")
    try:
        platforms = cl.get_platforms()
    except Exception:  # no OpenCL driver at all
        platforms = []
    devices = []
    for p_index, cl_platform in enumerate(platforms):
        try:
            found = cl_platform.get_devices()
        except Exception:  # a platform without devices
            continue
        for d_index, device in enumerate(found):
            devices.append(DeviceInfo(
                spec=f"{p_index}:{d_index}",
                platform=_text(cl_platform, "name"),
                name=_text(device, "name"),
                kind=_kind(cl, device),
                opencl=_text(device, "version"),
                driver=_text(device, "driver_version"),
            ))
    if not devices:
        return Survey((), f"No OpenCL device found. {install_hint()}")
    return Survey(tuple(devices))


def _text(obj, attribute: str) -> str:
    """An info string of a platform or device; a driver that cannot say gives 'unknown'."""
    try:
        return str(getattr(obj, attribute)).strip()
    except Exception:
        return "unknown"


def _kind(cl, device) -> str:
    try:
        device_type = device.type
    except Exception:
        return "other"
    if device_type & cl.device_type.GPU:
        return "GPU"
    return "CPU" if device_type & cl.device_type.CPU else "other"
