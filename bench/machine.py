"""The machine a benchmark ran on, in one line for its report."""

from __future__ import annotations

import os
import platform


def describe(device=None) -> str:
    """CPU model, core count, current load and, given a gpu_core Device,
    the OpenCL device."""
    model = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            model = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    load = ", load average %.2f" % os.getloadavg()[0] if hasattr(os, "getloadavg") else ""
    text = f"{model}, {os.cpu_count()} cores{load}"
    if device is not None:
        d = device.device
        text += f"; OpenCL: {d.name.strip()} ({d.max_compute_units} compute units)"
    return text
