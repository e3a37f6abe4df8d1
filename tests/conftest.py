"""Shared fixtures: the OpenCL device, and bpy with the add-on registered."""

from __future__ import annotations

import os
import sys
import threading

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from gpu_core.device import load_pip_drivers  # noqa: E402

load_pip_drivers()  # before any test module imports bpy: see gpu_core/device/pip_drivers.py


@pytest.fixture(scope="session")
def device():
    """The tests' OpenCL device: the CPU (PoCL), or GPUGI_TEST_DEVICE's spec
    (e.g. NVIDIA) to run the kernel tests on another driver."""
    from gpu_core.device import get_device

    return get_device(os.environ.get("GPUGI_TEST_DEVICE", "cpu"))


@pytest.fixture
def probe_program(tmp_path, monkeypatch):
    """write(name, source): a kernel source the device's programs build from
    a private folder, with a private kernel cache; returns ``name``."""
    import gpu_core.device.programs as programs_module

    monkeypatch.setattr(programs_module, "INCLUDE_ROOT", tmp_path)
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))

    def write(name: str, source: str) -> str:
        (tmp_path / name).write_text(source)
        return name

    return write


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


def render_multilayer(bpy, scene, engine: str, path) -> dict[str, np.ndarray]:
    """Render ``scene`` with ``engine`` to an uncompressed multilayer EXR and
    read every channel back: name -> (H, W) float32, rows from the bottom."""
    from exr_channels import read_exr_channels

    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format, settings.color_depth, settings.exr_codec = "OPEN_EXR_MULTILAYER", "32", "NONE"
    scene.render.engine = engine
    scene.render.filepath, scene.render.use_file_extension = str(path), False
    bpy.ops.render.render(write_still=True)
    return read_exr_channels(path)


def pass_rgb(channels: dict, name: str) -> np.ndarray:
    """A colour pass of a multilayer render as (H, W, 3) float64."""
    return np.stack([channels[f"ViewLayer.{name}.{c}"] for c in "RGB"], axis=-1).astype(np.float64)


def other_threads_cpu_ms() -> float:
    """CPU time (user and system) of this process's threads but the calling
    one, in ms: what a library's worker threads spent beside the caller."""
    me, ticks = threading.get_native_id(), 0
    for tid in os.listdir("/proc/self/task"):
        if int(tid) == me:
            continue
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except FileNotFoundError:  # the thread has ended
            continue
        ticks += int(fields[11]) + int(fields[12])
    return 1000.0 * ticks / os.sysconf("SC_CLK_TCK")
