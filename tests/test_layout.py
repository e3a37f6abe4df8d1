"""The numpy twins in gpu_core/layout.py match the device structs byte for byte."""

import numpy as np
import pyopencl as cl

from gpu_core import layout

# (struct dtype, field) in the order Layout_probe writes them; None = sizeof
EXPECTED = [
    (layout.KDNODE_DTYPE, None), (layout.KDNODE_DTYPE, "axis"), (layout.KDNODE_DTYPE, "child"), (layout.KDNODE_DTYPE, "count"),
    (layout.MATERIAL_DTYPE, None), (layout.MATERIAL_DTYPE, "emission"), (layout.MATERIAL_DTYPE, "metallic"),
    (layout.MATERIAL_DTYPE, "ior"), (layout.MATERIAL_DTYPE, "texture"),
    (layout.LIGHT_DTYPE, None), (layout.LIGHT_DTYPE, "direction"), (layout.LIGHT_DTYPE, "power"),
    (layout.LIGHT_DTYPE, "kind"), (layout.LIGHT_DTYPE, "shape"), (layout.LIGHT_DTYPE, "pick_pdf"),
    (layout.CAMERA_DTYPE, None), (layout.CAMERA_DTYPE, "window"), (layout.CAMERA_DTYPE, "kind"),
    (layout.CAMERA_DTYPE, "width"), (layout.CAMERA_DTYPE, "clip_start"), (layout.CAMERA_DTYPE, "clip_end"),
    (layout.TEXTURE_INFO_DTYPE, None),
]


def test_struct_sizes_and_offsets_match_on_the_device(device):
    out = np.zeros(len(EXPECTED) + 1, np.int32)
    buf = device.empty(out.nbytes)
    device.program("layout_probe.cl").Layout_probe(device.queue, (1,), None, buf)
    cl.enqueue_copy(device.queue, out, buf)
    host = [dt.itemsize if field is None else dt.fields[field][1] for dt, field in EXPECTED]
    assert list(out[:-1]) == host
    assert out[-1] == 16  # float3 occupies 16 bytes, which is why the host twins use float4
