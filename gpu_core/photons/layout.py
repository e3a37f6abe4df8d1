"""numpy twins of the photon-map structs in kernels/point_tree.h,
kernels/point_tree_build.cl and kernels/photon_emit.h (checked on the
device by tests/test_point_tree.py through kernels/point_tree_layout.cl)."""

from __future__ import annotations

import numpy as np

F4 = (np.float32, 4)

POINT_NODE_DTYPE = np.dtype(
    [
        ("lo", F4),  # w = r_p
        ("hi", F4),
        ("power", F4),
        ("irradiance", F4),
        ("normal", F4),
        ("first", np.int32),
        ("count", np.int32),
        ("depth", np.int32),
        ("pad", np.int32),
    ]
)

BUILD_NODE_DTYPE = np.dtype(
    [
        ("lo", F4),
        ("hi", F4),
        ("start", np.int32),
        ("count", np.int32),
        ("mask", np.uint32),
        ("root", np.int32),
        ("left", np.int32),
        ("axis", np.int32),
        ("split", np.float32),
        ("depth", np.int32),
    ]
)

CHUNK_DTYPE = np.dtype([("slot", np.int32), ("start", np.int32), ("count", np.int32), ("rank", np.int32)])

BUILD_SUMS_DTYPE = np.dtype([("lo", F4), ("hi", F4), ("power", F4), ("normal", F4), ("moment", np.float32, (3, 4))])

EMITTER_DTYPE = np.dtype(
    [("power", F4), ("light", np.int32), ("first", np.int32), ("count", np.int32), ("pad", np.int32)]
)

# struct name -> (kernel file declaring it, numpy twin), in the probe's order
STRUCTS = {
    "PointNode": ("point_tree.h", POINT_NODE_DTYPE),
    "BuildNode": ("point_tree_build.cl", BUILD_NODE_DTYPE),
    "Chunk": ("point_tree_build.cl", CHUNK_DTYPE),
    "BuildSums": ("point_tree_build.cl", BUILD_SUMS_DTYPE),
    "PhotonEmitter": ("photon_emit.h", EMITTER_DTYPE),
}
