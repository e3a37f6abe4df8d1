"""Rendering a .blend through the bpy module for the benchmarks: our engine
or Cycles, to a float image, timed."""

from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def load_bpy():
    """bpy with the add-on registered."""
    from gpu_core.device import load_pip_drivers

    load_pip_drivers()  # before bpy: see gpu_core/device/pip_drivers.py
    import bpy

    import blender_addon

    blender_addon.register()
    return bpy


def open_scene(bpy, name: str, size: int):
    """Open blend_scenes/NAME.blend at size x size pixels; returns its scene."""
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", f"{name}.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.use_border = False
    return scene


def render(bpy, scene, engine: str) -> tuple[np.ndarray, float]:
    """Render ``scene`` with ``engine``: linear RGB (H, W, 3) float64 and
    the wall time of the render call in seconds."""
    scene.render.engine = engine
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    scene.render.use_file_extension = False
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "image.exr")
        scene.render.filepath = path
        began = time.perf_counter()
        bpy.ops.render.render(write_still=True, scene=scene.name)
        seconds = time.perf_counter() - began
        img = bpy.data.images.load(path)
        try:
            pixels = np.array(img.pixels[:], np.float64).reshape(img.size[1], img.size[0], 4)
        finally:
            bpy.data.images.remove(img)
    return pixels[..., :3], seconds
