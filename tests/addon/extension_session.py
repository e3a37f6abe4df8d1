"""One Blender session with the GPU GI extension, run by test_addon_extension.py.

    python -I -S extension_session.py SITE ZIP OTHER_PYTHON_ZIP BLEND OUT_JSON

The process sees only the packages linked in SITE (bpy and numpy), so
pyopencl can come only from the extension's own wheels. Blender's user folder
is the one BLENDER_USER_RESOURCES names. The session tries to install the zip
built for another Python, installs and enables ZIP with Blender's extension
operators, renders BLEND small, uninstalls the extension, and writes what it
saw to OUT_JSON; the test judges it.
"""

import json
import os
import sys

SITE, ZIP, OTHER_PYTHON_ZIP, BLEND, OUT_JSON = sys.argv[1:6]
sys.path.append(SITE)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

PACKAGE = "bl_ext.user_default.gpugi"
seen = {}


def files_under(folder):
    """Every file below ``folder``, relative to it."""
    return sorted(
        os.path.relpath(os.path.join(parent, name), folder)
        for parent, _, names in os.walk(folder)
        for name in names
    )


def render_pixels(scene, path):
    """F12 into a float EXR, read back as (H, W, 4)."""
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    scene.render.filepath, scene.render.use_file_extension = path, False
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(path)
    return np.array(image.pixels[:], np.float32).reshape(image.size[1], image.size[0], 4)


# the zip for another Python first: this Blender must refuse it
extensions = bpy.utils.user_resource("EXTENSIONS")
bpy.ops.extensions.package_install_files(filepath=OTHER_PYTHON_ZIP, repo="user_default", enable_on_install=True)
seen["other_python_installed"] = os.path.isdir(os.path.join(extensions, "user_default", "gpugi"))

# install and enable, as Edit > Preferences > Get Extensions > Install from Disk does
seen["install"] = sorted(bpy.ops.extensions.package_install_files(
    filepath=ZIP, repo="user_default", enable_on_install=True))
seen["enabled"] = PACKAGE in bpy.context.preferences.addons

# where the add-on's Python packages came from, and where it caches kernels
import gpu_core  # noqa: E402
import pyopencl  # noqa: E402

seen["pyopencl"] = pyopencl.__file__
seen["gpu_core"] = gpu_core.__file__
seen["kernel_cache"] = os.environ.get("GPUGI_KERNEL_CACHE", "")
seen["pocl_cache"] = os.environ.get("POCL_CACHE_DIR", "")
seen["extensions"] = extensions

# the preferences Blender shows for it, and the devices they list
preferences = bpy.context.preferences.addons[PACKAGE].preferences
seen["preferences"] = type(preferences).__name__
seen["devices"] = [device.label for device in sys.modules[PACKAGE + ".opencl_devices"].survey().devices]

# F12 on the Cornell box, about 48 px wide, 2 samples of the path tracer, denoised
bpy.ops.wm.open_mainfile(filepath=BLEND)
scene = bpy.context.scene
scene.render.engine = "GPUGI"
scene.render.resolution_percentage = max(1, round(100 * 48 / scene.render.resolution_x))
seen["asked_width"] = scene.render.resolution_x * scene.render.resolution_percentage // 100
scene.gpugi.mode = "REFERENCE"
scene.gpugi.samples, scene.gpugi.diffuse_bounces = 2, 1
# (a CPU newer than the bundled PoCL's compiler, with no GPU: no device can render, and F12 says why)
select = sys.modules["gpu_core.device.select"]
seen["cpu_compiles"] = any(select.compiles_here(dev) for _, _, devices in select._all_devices() for dev in devices)
try:
    rgba = render_pixels(scene, os.path.join(os.path.dirname(OUT_JSON), "render.exr"))
except RuntimeError as err:
    rgba = np.full((1, 1, 4), np.nan, np.float32)
    seen["render_raised"] = str(err)
last_run = sys.modules[PACKAGE + ".final"].LAST_RUN
seen["render_error"] = last_run.get("error", "")
seen["render_warnings"] = last_run.get("warnings", [])
seen["denoised"] = bool(last_run.get("stats", {}).get("denoised"))  # Denoise is on by default, as in Cycles
seen["pyoidn"] = getattr(sys.modules.get("pyoidn"), "__file__", "")
seen["image_shape"] = list(rgba.shape)
seen["image_finite"] = bool(np.isfinite(rgba).all())
seen["image_mean_rgb"] = float(rgba[..., :3].mean())
seen["kernel_cache_files"] = len(files_under(seen["kernel_cache"])) if seen["kernel_cache"] else 0
seen["pocl_cache_files"] = len(files_under(seen["pocl_cache"])) if seen["pocl_cache"] else 0

# uninstall, then list what is left of it
seen["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(
    repo_directory=os.path.join(extensions, "user_default"), pkg_id="gpugi"))
seen["enabled_after_uninstall"] = PACKAGE in bpy.context.preferences.addons
seen["left_in_repo"] = files_under(os.path.join(extensions, "user_default"))
seen["left_in_user_data"] = files_under(os.path.join(extensions, ".user"))
seen["left_in_site_packages"] = files_under(os.path.join(extensions, ".local"))

with open(OUT_JSON, "w") as f:
    json.dump(seen, f, indent=1)
