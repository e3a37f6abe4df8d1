"""numpy twins of the device structs in kernels/types.h (checked on the device by a test)."""

from __future__ import annotations

import numpy as np

F4 = (np.float32, 4)

KDNODE_DTYPE = np.dtype([("split", np.float32), ("axis", np.int32), ("child", np.int32), ("count", np.int32)])

MATERIAL_DTYPE = np.dtype(
    [
        ("base_color", F4),
        ("emission", F4),
        ("metallic", np.float32),
        ("roughness", np.float32),
        ("transmission", np.float32),
        ("ior", np.float32),
        ("texture", np.int32),
        ("pad", np.int32, 3),
    ]
)

LIGHT_DTYPE = np.dtype(
    [
        ("position", F4),
        ("direction", F4),
        ("axis_u", F4),
        ("axis_v", F4),
        ("power", F4),
        ("radiance", F4),
        ("radius", np.float32),
        ("cos_half", np.float32),
        ("spot_smooth", np.float32),
        ("sun_norm", np.float32),
        ("kind", np.int32),
        ("shape", np.int32),
        ("pad", np.int32, 2),
    ]
)

CAMERA_DTYPE = np.dtype(
    [
        ("right", F4),
        ("up", F4),
        ("back", F4),
        ("origin", F4),
        ("window", F4),
        ("kind", np.int32),
        ("width", np.int32),
        ("height", np.int32),
        ("pad0", np.int32),
        ("clip_start", np.float32),
        ("clip_end", np.float32),
        ("pad1", np.float32, 2),
    ]
)

TEXTURE_INFO_DTYPE = np.dtype([("offset", np.int32), ("width", np.int32), ("height", np.int32), ("pad", np.int32)])

# struct name in types.h -> numpy twin, for the layout test
STRUCTS = {
    "KdNode": KDNODE_DTYPE,
    "Material": MATERIAL_DTYPE,
    "Light": LIGHT_DTYPE,
    "Camera": CAMERA_DTYPE,
    "TextureInfo": TEXTURE_INFO_DTYPE,
}
