"""`python -m blender_addon render FILE.blend -o OUT`, run as a separate process."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT
from exr_channels import exr_channel_types


@pytest.fixture(scope="module")
def small_blend(tmp_path_factory, bpy_module):
    """A plane, a sphere, a sun and a camera at 40x30 pixels, saved as a .blend."""
    bpy = bpy_module
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=20)
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0, 0, 1))
    bpy.ops.object.light_add(type="SUN", rotation=(0.4, 0.2, 0))
    bpy.ops.object.camera_add(location=(0, -6, 4), rotation=(1.0, 0, 0))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    scene.frame_end = 5
    path = tmp_path_factory.mktemp("cli") / "small.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _cli(*args, env=None):
    return subprocess.run(
        [sys.executable, "-m", "blender_addon", "render", *map(str, args)],
        cwd=ROOT, capture_output=True, text=True, timeout=300, env=env,
    )


def test_cli_writes_a_png_and_prints_its_path_and_stage_times(small_blend, tmp_path, bpy_module):
    out = tmp_path / "nested" / "out.png"
    run = _cli(small_blend, "-o", out, "--samples", "2", "--frame", "3")
    assert run.returncode == 0, run.stderr
    assert out.is_file()
    assert f"image: {out}" in run.stdout
    stages = next(line for line in run.stdout.splitlines() if line.startswith("stages:"))
    assert "export" in stages and "render" in stages and "ms" in stages
    plan = next(line for line in run.stdout.splitlines() if line.startswith("plan:"))
    assert plan.endswith(", denoise") and "denoise" in stages  # on by default, as in Cycles
    assert "samples: 2 per pixel" in run.stdout.splitlines()
    image = bpy_module.data.images.load(str(out))
    try:
        assert tuple(image.size) == (40, 30)
    finally:
        bpy_module.data.images.remove(image)


def test_cli_counts_the_kernels_it_compiles_and_compiles_none_the_second_time(small_blend, tmp_path):
    env = dict(os.environ, GPUGI_KERNEL_CACHE=str(tmp_path / "kernels"))
    first = _cli(small_blend, "-o", tmp_path / "first.png", "--samples", "1", env=env)
    assert first.returncode == 0, first.stderr
    counts = [line.split()[-1] for line in first.stderr.splitlines() if line.startswith("compiling kernels")]
    assert counts, first.stderr
    total = counts[-1].split("/")[1]
    assert counts[-1] == f"{total}/{total}" and int(total) >= 3  # primitives, kd-tree, image at least
    second = _cli(small_blend, "-o", tmp_path / "second.png", "--samples", "1", env=env)
    assert second.returncode == 0, second.stderr
    assert "compiling kernels" not in second.stderr


def test_cli_writes_a_float_exr_at_the_asked_percentage(small_blend, tmp_path, bpy_module):
    out = tmp_path / "out.exr"
    run = _cli(small_blend, "-o", out, "--samples", "1", "--resolution-percentage", "50", "--device", "cpu",
               "--no-denoise")
    assert run.returncode == 0, run.stderr
    assert "denoise" not in next(line for line in run.stdout.splitlines() if line.startswith("plan:"))
    assert set(exr_channel_types(out).values()) == {np.dtype("<f4")}  # 32-bit float channels
    image = bpy_module.data.images.load(str(out))
    try:
        assert tuple(image.size) == (20, 15) and image.is_float
        pixels = np.empty(20 * 15 * 4, np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy_module.data.images.remove(image)
    assert np.isfinite(pixels).all() and pixels.max() > 0


def test_cli_errors_are_one_line_and_non_zero(small_blend, tmp_path):
    missing = _cli(tmp_path / "missing.blend", "-o", tmp_path / "x.png")
    assert missing.returncode != 0
    assert missing.stderr.strip().count("\n") == 0 and "does not exist" in missing.stderr
    bad_format = _cli(small_blend, "-o", tmp_path / "x.gif")
    assert bad_format.returncode != 0 and "unsupported output extension" in bad_format.stderr
    assert not (tmp_path / "x.gif").exists()


def test_cli_preset_and_mode_options(small_blend, tmp_path):
    run = _cli(small_blend, "-o", tmp_path / "gi.png", "--preset", "draft", "--mode", "gi", "--samples", "1")
    assert run.returncode == 0, run.stderr
    assert "mode: gi" in run.stdout and "warning" not in run.stdout
    assert "photons" in run.stdout and "gather" in run.stdout  # the GI stages' times
    plain = _cli(small_blend, "-o", tmp_path / "ref.png", "--preset", "draft", "--mode", "reference")
    assert plain.returncode == 0, plain.stderr
    assert "mode: reference" in plain.stdout and "warning" not in plain.stdout
    assert "photons" not in plain.stdout
    bad = _cli(small_blend, "-o", tmp_path / "x.png", "--preset", "ultra")
    assert bad.returncode != 0 and "invalid choice" in bad.stderr
