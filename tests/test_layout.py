"""The numpy twins in gpu_core/layout.py match the device structs byte for byte."""

import numpy as np
import pyopencl as cl

from gpu_core import kdtree, layout


def _host_layout() -> list[tuple[str, str, int]]:
    """(struct, field or 'sizeof', bytes) for every twin, padding skipped, in probe order."""
    rows = []
    for struct, dtype in layout.STRUCTS.items():
        rows.append((struct, "sizeof", dtype.itemsize))
        for name in dtype.names:
            if not name.startswith("pad"):
                rows.append((struct, name, dtype.fields[name][1]))
    return rows


def test_every_struct_field_offset_and_size_match_on_the_device(device):
    host = _host_layout()
    out = np.full(len(host) + 2, -1, np.int32)
    buf = device.empty(out.nbytes)
    cl.enqueue_copy(device.queue, buf, out)
    device.program("layout_probe.cl").Layout_probe(device.queue, (1,), None, buf)
    cl.enqueue_copy(device.queue, out, buf)
    device_rows = [(struct, field, int(value)) for (struct, field, _), value in zip(host, out)]
    assert device_rows == host
    # the probe reports sizeof(float3) right after the last field, and nothing more
    assert out[len(host)] == 16  # why the host twins use float4 for float3
    assert out[len(host) + 1] == -1


def test_structs_have_no_implicit_padding_on_the_host():
    for dtype in layout.STRUCTS.values():
        assert dtype.itemsize % 16 == 0 or dtype.itemsize < 16
        end = 0
        for name in dtype.names:
            fdtype, offset = dtype.fields[name][:2]
            assert offset == end, name
            end = offset + fdtype.itemsize
        assert end == dtype.itemsize


def test_kdtree_node_dtype_is_the_layout_twin():
    assert kdtree.NODE_DTYPE == layout.KDNODE_DTYPE
