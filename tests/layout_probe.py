"""The generated layout probe (gpu_core/device/layout.py) run on the device,
and what it must report when the host twins match."""

import numpy as np

from gpu_core.device import layout


def host_layout() -> list[tuple[str, str, int]]:
    """(struct, field or 'sizeof', bytes) for every twin, in probe order."""
    rows = []
    for struct in layout.STRUCTS:
        dtype = struct.dtype
        rows.append((struct.name, "sizeof", dtype.itemsize))
        rows += [(struct.name, name, dtype.fields[name][1]) for name in dtype.names]
    return rows


def probe(device, count: int) -> np.ndarray:
    """What the generated probe kernel writes, in ``count`` ints (-1 beyond)."""
    out = np.full(count, -1, np.int32)
    buf = device.to_device(out, writable=True)
    device.kernel("device/layout_probe.cl", "Layout_probe")(1, buf)
    return device.to_host(buf, out)
