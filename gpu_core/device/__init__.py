"""The OpenCL device layer: device choice, programs, the launch helper,
transfers, device primitives and the structs and constants shared with the
kernels."""

from .device import Device, Transfers
from .programs import kernel_cache_dir, load_source
from .select import DeviceInfo, describe_devices, free_held_memory, get_device, list_devices, load_pip_drivers

__all__ = ["Device", "DeviceInfo", "Transfers", "describe_devices", "free_held_memory", "get_device",
           "kernel_cache_dir", "list_devices", "load_pip_drivers", "load_source"]
