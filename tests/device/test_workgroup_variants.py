"""Launch discipline, counted in the kernel compiler's own cache: PoCL
compiles a work-group function per kernel and launch shape, so renders of
different sizes must add none, and a second process must compile nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from conftest import ROOT

SCENE = os.path.join(ROOT, "blend_scenes", "caustics.blend")  # every GI stage, the caustic map too


def _cpu_device_is_pocl() -> bool:
    from gpu_core.device import get_device
    from gpu_core.device.select import is_pocl

    return is_pocl(get_device("cpu").device)


# PoCL's cache is what these count; where PoCL's compiler does not know the CPU, the CPU device is another
counts_pocls_cache = pytest.mark.skipif(not _cpu_device_is_pocl(), reason="the CPU device here is not PoCL")


def _render(tmp_path: Path, percentage: int) -> subprocess.CompletedProcess:
    """The caustics scene, Draft, at ``percentage`` of its size, with this
    test's own PoCL and GPU GI kernel caches."""
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "pocl"), GPUGI_KERNEL_CACHE=str(tmp_path / "kernels"))
    env.pop("GPUGI_DEVICE", None)
    run = subprocess.run([sys.executable, "-m", "blender_addon", "render", SCENE, "-o", str(tmp_path / f"{percentage}.png"),
                          "--preset", "draft", "--resolution-percentage", str(percentage), "--device", "cpu"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return run


def _variants(pocl_cache: Path) -> Counter:
    """Work-group functions PoCL compiled, per (program, kernel): its cache
    holds XX/PROGRAM/KERNEL/LOCALSIZE-... folders."""
    return Counter((path.parent.parent.name, path.parent.name)
                   for path in pocl_cache.glob("*/*/*/*") if path.is_dir())


def _compiled_files(pocl_cache: Path) -> list[Path]:
    """Every file PoCL's cache holds but its access stamps and scratch files."""
    return sorted(path.relative_to(pocl_cache) for path in pocl_cache.rglob("*")
                  if path.is_file() and path.name != "last_accessed" and not path.name.startswith("tempfile"))


@pytest.mark.slow
@counts_pocls_cache
def test_renders_of_other_sizes_compile_no_kernel_and_no_work_group_variant(tmp_path):
    first = _render(tmp_path, 10)
    assert "compiling kernels" in first.stderr  # the caches started empty
    after_first = _variants(tmp_path / "pocl")
    files_after_first = _compiled_files(tmp_path / "pocl")
    assert len(after_first) >= 40  # every stage's kernels ran
    assert max(after_first.values()) == 1, [key for key, count in after_first.items() if count > 1]

    # another process, another size: every program from the disk cache, every
    # work-group function from PoCL's
    second = _render(tmp_path, 25)
    assert "compiling kernels" not in second.stderr
    assert _compiled_files(tmp_path / "pocl") == files_after_first


# a viewport session of a small box with a mirror (every GI stage): "open" opens the view and waits
# until it has settled and the session's warm-up (given as argv[2]: "warm" or "none") has ended;
# "edits" then makes the viewport's edits (gpu_core/warmup.py) one after the other, without a warm-up.
# Prints the programs this process compiled.
_VIEWPORT = """
import sys, time
sys.path[:0] = ["tests", "tests/renderer"]
from dataclasses import replace
from test_threads import GI, scene
from blender_addon.viewport import Job, ViewportSession, warm_edit_kernels
from gpu_core.device import get_device
from gpu_core.warmup import edited_copies

box = scene(True, 48)
settings = replace(GI, samples=4)
session = ViewportSession(lambda: None, warm_up=warm_edit_kernels if sys.argv[2] == "warm" else None)

def show(job, view):
    session.update_scene(job, ("view", view))
    deadline = time.time() + 300
    while (session.busy or session.warming) and time.time() < deadline:
        time.sleep(0.01)
    if session.error or session.busy or session.warming:
        sys.exit(f"the view did not settle: {session.error}")

show(Job(box, settings, "cpu"), 0)
if sys.argv[1] == "edits":
    for view, (edited, edits) in enumerate(edited_copies(box), 1):
        show(Job(edited, settings, "cpu", edits=edits), view)
session.stop()
print("compiled:", sorted(b.name for b in get_device("cpu").builds if not b.from_cache))
"""


def _viewport(tmp_path: Path, mode: str, warm_up: str) -> str:
    """What the session script printed of the programs its process compiled."""
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "pocl"), GPUGI_KERNEL_CACHE=str(tmp_path / "kernels"))
    env.pop("GPUGI_DEVICE", None)
    run = subprocess.run([sys.executable, "-c", _VIEWPORT, mode, warm_up], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    return run.stdout.split("compiled:", 1)[1].strip()


@pytest.mark.slow
@counts_pocls_cache
def test_after_a_settled_views_warm_up_a_later_process_compiles_nothing_for_the_viewports_edits(tmp_path):
    assert _viewport(tmp_path, "open", "warm") != "[]"  # the caches started empty
    files = _compiled_files(tmp_path / "pocl")
    # another process: the open and every edit kind, each work-group function from PoCL's cache
    assert _viewport(tmp_path, "edits", "none") == "[]"
    assert _compiled_files(tmp_path / "pocl") == files


_WIDE_LAUNCHES = """
import sys
import numpy as np
from gpu_core.device import get_device, primitives
device = get_device("cpu")
for n in (1000, 65536, 300001):
    got = device.read(primitives.iota(device, n), n, np.int32)
    if not np.array_equal(got, np.arange(n, dtype=np.int32)):
        sys.exit(f"iota of {n} wrong")
"""


def test_launches_past_65536_work_items_index_every_item_and_add_no_work_group_variant(tmp_path):
    # PoCL compiles a second work-group function of a kernel launched 65,536
    # work-items wide or wider: launches are grids of narrower rows
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "pocl"), GPUGI_KERNEL_CACHE=str(tmp_path / "kernels"))
    run = subprocess.run([sys.executable, "-c", _WIDE_LAUNCHES], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    if _cpu_device_is_pocl():
        iota = [path for path in (tmp_path / "pocl").glob("*/*/Prim_iota/*") if path.is_dir()]
        assert len(iota) == 1, iota
