"""GPU GI: a render engine computing global illumination in OpenCL kernels."""

bl_info = {
    "name": "GPU GI",
    "author": "GPU GI developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Render Properties > Render Engine > GPU GI",
    "description": "Interactive global illumination computed with OpenCL kernels",
    "category": "Render",
}

import os
import sys

# gpu_core lives beside this package in the source tree (also when Blender
# loads the add-on through a link to this folder)
_ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
if _ROOT not in sys.path:
    sys.path.append(_ROOT)

import bpy  # noqa: E402

from . import properties, ui  # noqa: E402
from .engine import GpuGiRenderEngine  # noqa: E402

_registered = False


def register():
    """Register settings, engine and panels (a second call does nothing)."""
    global _registered
    if _registered:
        return
    properties.register()
    bpy.utils.register_class(GpuGiRenderEngine)
    ui.register()
    _registered = True


def unregister():
    """Remove panels, engine and settings (a second call does nothing)."""
    global _registered
    if not _registered:
        return
    ui.unregister()
    bpy.utils.unregister_class(GpuGiRenderEngine)
    properties.unregister()
    _registered = False
