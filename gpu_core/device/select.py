"""Which OpenCL device renders: chosen by a spec string (argument, or the
``GPUGI_DEVICE`` environment variable):

* ``""`` or ``"cpu"``: PoCL's CPU device from PyPI (the default) or, where
  its compiler does not know the CPU, the first other CPU device (Intel's
  CPU runtime from PyPI, made visible by pip_drivers);
* ``"gpu"``: the first GPU device of any platform;
* ``"P"`` or ``"P:D"``: platform whose name contains ``P`` (case-insensitive)
  or whose index is ``P``, and its device number ``D`` (default 0).

When the asked-for device is missing, the CPU device is used and
``Device.fallback_message`` says why, so the add-on can show it.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

import pyopencl as cl

from ..errors import DeviceError
from . import pip_drivers
from .device import Device
from .programs import POCL_PLATFORM, kernel_cache_dir


def load_pip_drivers() -> None:
    """Make OpenCL drivers installed by pip visible (pip_drivers); once per
    process, before the OpenCL loader's first call and before ``bpy`` is imported."""
    pip_drivers.register(kernel_cache_dir())


def _all_devices() -> list[tuple[int, cl.Platform, list[cl.Device]]]:
    load_pip_drivers()
    out = []
    try:
        platforms = cl.get_platforms()
    except cl.Error:  # no OpenCL driver at all
        return out
    for index, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            devices = []
        if devices:  # platforms without devices (e.g. rusticl with none) are skipped
            out.append((index, platform, devices))
    return out


@dataclass(frozen=True)
class DeviceInfo:
    """What a user picking a device wants to know of it (no context is opened)."""

    spec: str  # "P:D", a spec get_device takes
    platform: str
    name: str
    kind: str  # "CPU", "GPU" or "other"
    opencl: str  # the device's OpenCL version string
    driver: str  # the driver's version string

    @property
    def label(self) -> str:
        """``"P:D  platform / device"``."""
        return f"{self.spec}  {self.platform} / {self.name}"


def describe_devices() -> list[DeviceInfo]:
    """Every device of every platform, with its kind and versions."""
    return [DeviceInfo(f"{index}:{number}", _text(platform, "name"), _text(dev, "name"), _kind(dev),
                       _text(dev, "version"), _text(dev, "driver_version"))
            for index, platform, devices in _all_devices() for number, dev in enumerate(devices)]


def _text(obj, attribute: str) -> str:
    """An info string of a platform or device; a driver that cannot say gives 'unknown'."""
    try:
        return str(getattr(obj, attribute)).strip()
    except cl.Error:
        return "unknown"


def _kind(dev: cl.Device) -> str:
    if dev.type & cl.device_type.GPU:
        return "GPU"
    return "CPU" if dev.type & cl.device_type.CPU else "other"


def list_devices() -> list[str]:
    """``"P:D  platform / device"`` lines for every device, for UI and errors."""
    return [info.label for info in describe_devices()]


# OpenCL platforms that check kernels rather than run them fast: never chosen automatically
SIMULATORS = ("oclgrind",)


def is_pocl(dev: cl.Device) -> bool:
    return dev.platform.name.strip() == POCL_PLATFORM


def compiles_here(dev: cl.Device) -> bool:
    """False for a PoCL device whose LLVM does not know this CPU: it names
    it "generic" (the end of its version string) and refuses every program."""
    return not (is_pocl(dev) and _text(dev, "version").endswith("-generic"))


def _match(spec: str, found) -> cl.Device | None:
    spec = spec.strip()
    lowered = spec.lower()
    if lowered in ("", "cpu", "gpu"):
        wanted = cl.device_type.GPU if lowered == "gpu" else cl.device_type.CPU
        candidates = [dev for _, platform, devices in found
                      if not any(name in platform.name.lower() for name in SIMULATORS)  # only when named
                      for dev in devices if dev.type & wanted and compiles_here(dev)]
        candidates.sort(key=lambda dev: not is_pocl(dev))  # PoCL first: the device measured
        return candidates[0] if candidates else None
    platform_part, _, device_part = spec.partition(":")
    try:
        device_number = int(device_part) if device_part else 0
    except ValueError:
        return None
    for index, platform, devices in found:
        if platform_part.isdigit():
            hit = int(platform_part) == index
        else:
            hit = platform_part.lower() in platform.name.lower()
        if hit and 0 <= device_number < len(devices):
            return devices[device_number]
    return None


def no_device_message(found, available: str) -> str:
    """What to install when no CPU device can render."""
    if any(is_pocl(dev) and not compiles_here(dev) for _, _, devices in found for dev in devices):
        intel = (f"Intel's CPU runtime is installed but could not be loaded ({pip_drivers.problem}). "
                 if pip_drivers.problem else "Install Intel's CPU runtime for OpenCL (intel-opencl-rt on PyPI) ")
        return ("No OpenCL device can compile kernels here: PoCL 3.0's compiler (LLVM 14) does not know "
                f"this CPU model. {intel}or a GPU vendor's OpenCL driver. Devices seen: {available}.")
    return ("No OpenCL device found. Install a GPU vendor's OpenCL driver, or the CPU device "
            "(pip install pocl-binary-distribution; in Blender on Linux x64, the extension build "
            f"that bundles it). Devices seen: {available}.")


_DEVICES: dict[str, Device] = {}
_DEVICES_LOCK = threading.Lock()


def free_held_memory(keep_host_memory: bool = False) -> None:
    """Give the unused pooled buffers of every device opened so far back to
    its driver; with ``keep_host_memory``, those of CPU devices (host memory,
    whose fresh pages cost their first touch) stay for the next render."""
    with _DEVICES_LOCK:
        devices = list(_DEVICES.values())
    for device in devices:
        if not (keep_host_memory and device.is_cpu):
            device.free_held()


def get_device(spec: str | None = None) -> Device:
    """The device for ``spec`` (or ``GPUGI_DEVICE``), created once per process."""
    if spec is None:
        spec = os.environ.get("GPUGI_DEVICE", "")
    with _DEVICES_LOCK:
        if spec not in _DEVICES:
            _DEVICES[spec] = _create(spec)
        return _DEVICES[spec]


def _create(spec: str) -> Device:
    found = _all_devices()
    chosen = _match(spec, found)
    message = ""
    if chosen is None:
        chosen = _match("cpu", found)
        available = "; ".join(list_devices()) or "none"
        if chosen is None:
            raise DeviceError(no_device_message(found, available))
        message = (
            f"OpenCL device {spec!r} not found (devices: {available}); "
            f"using {chosen.platform.name.strip()} / {chosen.name.strip()} instead."
        )
    try:
        context = cl.Context([chosen])
        queue = cl.CommandQueue(context)
    except cl.Error as err:
        raise DeviceError(f"Could not open OpenCL device {chosen.name.strip()}: {err}") from err
    return Device(context=context, queue=queue, device=chosen, fallback_message=message)
