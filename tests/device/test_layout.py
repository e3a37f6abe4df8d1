"""The numpy twins of gpu_core/device/layout.py match the device structs
(the generated header) byte for byte, as the generated probe kernel sees them."""

from layout_probe import host_layout, probe

from gpu_core.accel import kdtree
from gpu_core.device import layout


def test_every_struct_field_offset_and_size_match_on_the_device(device):
    host = host_layout()
    out = probe(device, len(host) + 2)
    device_rows = [(struct, field, int(value)) for (struct, field, _), value in zip(host, out)]
    assert device_rows == host
    # the probe reports sizeof(float3) right after the last field, and nothing more
    assert out[len(host)] == 16  # why the host twins use float4 for float3
    assert out[len(host) + 1] == -1


def test_structs_have_no_implicit_padding_on_the_host():
    for dtype in (struct.dtype for struct in layout.STRUCTS):
        assert dtype.itemsize % 16 == 0 or dtype.itemsize < 16
        end = 0
        for name in dtype.names:
            fdtype, offset = dtype.fields[name][:2]
            assert offset == end, name
            end = offset + fdtype.itemsize
        assert end == dtype.itemsize


def test_kdtree_node_dtype_is_the_layout_twin():
    assert kdtree.NODE_DTYPE == layout.KDNODE_DTYPE
