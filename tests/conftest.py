"""Shared fixtures: the OpenCL device, and bpy with the add-on registered."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="session")
def device():
    from gpu_core.device import get_device

    return get_device("cpu")


@pytest.fixture(scope="session")
def bpy_module():
    import bpy

    import blender_addon

    blender_addon.register()
    return bpy


@pytest.fixture
def bpy_empty(bpy_module):
    """bpy with an empty file loaded (the add-on stays registered)."""
    bpy_module.ops.wm.read_homefile(use_empty=True)
    return bpy_module


def render_to_array(bpy, scene, engine: str, path: str) -> np.ndarray:
    """Render ``scene`` with ``engine`` to a float EXR and read it back (H, W, 4), rows from the bottom."""
    scene.render.engine = engine
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    scene.render.use_file_extension = False
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True, scene=scene.name)
    img = bpy.data.images.load(path)
    try:
        return np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)
    finally:
        bpy.data.images.remove(img)
