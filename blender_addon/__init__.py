"""GPU GI: a render engine computing global illumination in OpenCL kernels.

The same folder works as an extension (Blender 4.2+, installed from a zip
that carries gpu_core and pyopencl's wheels) and as a legacy add-on folder
beside gpu_core (the repository, also when Blender reaches it through a link).
"""

bl_info = {
    "name": "GPU GI",
    "author": "GPU GI developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Render Properties > Render Engine > GPU GI",
    "description": "Interactive global illumination computed with OpenCL kernels",
    "category": "Render",
}

import importlib.util
import os
import sys

_HERE = os.path.dirname(os.path.realpath(__file__))


def _import_gpu_core() -> None:
    """Make ``import gpu_core`` find the gpu_core this add-on came with."""
    bundled = os.path.join(_HERE, "gpu_core")
    if not os.path.isdir(bundled):
        # the repository: gpu_core is beside this folder
        root = os.path.dirname(_HERE)
        if root not in sys.path:
            sys.path.append(root)
        return
    # the extension: gpu_core is inside this folder; load it as the top-level
    # package without putting this folder's module names on sys.path (once:
    # Blender re-runs this file, but not the modules it imported, after an update)
    if "gpu_core" in sys.modules:
        return
    init = os.path.join(bundled, "__init__.py")
    spec = importlib.util.spec_from_file_location("gpu_core", init, submodule_search_locations=[bundled])
    module = importlib.util.module_from_spec(spec)
    sys.modules["gpu_core"] = module
    spec.loader.exec_module(module)


_import_gpu_core()

# The modules that need Blender are imported in register(): building the
# extension zips (python -m blender_addon build-extension) needs neither
# Blender nor OpenCL.
_registered = False


def register():
    """Point the kernel caches, register settings, engine, panels and preferences (a second call does nothing)."""
    global _registered
    if _registered:
        return
    import bpy

    from . import cache_dirs, preferences, properties, ui
    from .engine import GpuGiRenderEngine

    cache_dirs.configure(__package__)
    properties.register()
    bpy.utils.register_class(GpuGiRenderEngine)
    ui.register()
    preferences.register()
    _job_handlers(bpy, add=True)
    _registered = True


def unregister():
    """Remove preferences, panels, engine and settings (a second call does nothing)."""
    global _registered
    if not _registered:
        return
    import bpy

    from . import cache_dirs, final, preferences, properties, ui
    from .engine import GpuGiRenderEngine

    _job_handlers(bpy, add=False)
    final.release_held()
    preferences.unregister()
    ui.unregister()
    bpy.utils.unregister_class(GpuGiRenderEngine)
    properties.unregister()
    cache_dirs.restore()
    _registered = False


def _job_handlers(bpy, add: bool) -> None:
    """Blender's render-job handlers that keep a renderer across an animation's frames."""
    from . import final

    for handlers, function in ((bpy.app.handlers.render_init, final.job_started),
                               (bpy.app.handlers.render_complete, final.job_ended),
                               (bpy.app.handlers.render_cancel, final.job_ended)):
        if add and function not in handlers:
            handlers.append(bpy.app.handlers.persistent(function))  # kept when another file is opened
        elif not add and function in handlers:
            handlers.remove(function)
