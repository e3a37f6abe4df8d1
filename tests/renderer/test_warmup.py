"""The helper process that compiles a first render's kernels ahead
(gpu_core/warmup.py): when it starts, what it renders, and that the render
it helps computes what it computes without it."""

from __future__ import annotations

import dataclasses
import os
import pickle
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ROOT
from test_threads import GI, scene

from gpu_core import warmup
from gpu_core.device import Device
from gpu_core.device import programs as programs_module
from gpu_core.errors import DeviceError
from gpu_core.scene import Lights
from gpu_core.plan import plan
from gpu_core.renderer import Renderer
from gpu_core.scene.validate import validate


def test_the_small_copy_needs_the_programs_of_the_render():
    # the same programs (and defines): the kernels the helper compiles are the render's
    full = validate(scene(True, 48))
    small_scene, small_settings = warmup.small_copy(full, GI)
    assert (small_scene.camera.width, small_scene.camera.height) == (warmup.SIDE, warmup.SIDE)
    assert small_settings.global_photons < GI.global_photons and not small_settings.denoise
    assert plan(validate(small_scene), small_settings).programs == plan(full, GI).programs


def test_the_viewports_edits_of_a_copy_each_change_only_the_parts_they_name():
    # each edit is applied to the one before; a view change names no part (the camera is compared anyway)
    from gpu_core.scene.model import PARTS, part_digests

    before = scene(True, 24)
    copies = warmup.edited_copies(before)
    assert [edits for _, edits in copies] == [set(), {"lights"}, {"materials"}, {"geometry"}]
    for edited, edits in copies:
        old, new = part_digests(before), part_digests(edited)
        changed = {part for part in PARTS if old[part] != new[part]}
        assert changed == (edits or {"camera"})
        before = edited
    # the moved triangles stay inside the scene's box, so the device frame stays where it was
    lo, hi = copies[-2][0].bounds()
    moved_lo, moved_hi = copies[-1][0].bounds()
    assert (moved_lo >= lo).all() and (moved_hi <= hi).all()
    moved = np.flatnonzero((copies[-1][0].triangles != copies[-2][0].triangles).any(axis=(1, 2)))
    assert 1 <= len(moved) <= len(before.triangles) * warmup.MOVED_SHARE + 1


def test_a_scene_without_lights_gets_no_light_edit():
    bare = dataclasses.replace(scene(False, 24), lights=Lights.make([]))
    assert [edits for _, edits in warmup.edited_copies(bare)] == [set(), {"materials"}, {"geometry"}]


def test_warming_up_renders_every_edit_path_once_per_device(monkeypatch):
    # the viewport's warm-up (blender_addon/viewport.py) walks these copies through the viewport's passes
    from blender_addon import viewport

    monkeypatch.setattr(viewport, "_EDITS_WARMED", set())
    job = viewport.Job(scene=scene(True, 24), settings=dataclasses.replace(GI, samples=4), device_spec=None)
    assert viewport.warm_edit_kernels(job, lambda: True) == []  # told to stop before it began: not done
    plans = viewport.warm_edit_kernels(job, lambda: False)
    assert len(plans) == 5  # the open, then the view, light, material and move edits
    assert "kdtree" in plans[0] and "global_photons" in plans[0]
    assert "cache_records_reused" in plans[1] and "global_photons_reused" in plans[1]
    assert "global_photons_reweighted" in plans[2]
    assert "sample_points_reused" in plans[3]
    assert "kdtree_overlay" in plans[4]
    assert viewport.warm_edit_kernels(job, lambda: False) == []  # done for this device in this process


class _Recorder:
    """A stand-in for subprocess.Popen that records the command and input."""

    started: list = []

    def __init__(self, command, **kwargs):
        self.command, self.stdin, self.killed = command, SimpleNamespace(write=self._write, close=lambda: None), False
        self.data = b""
        _Recorder.started.append(self)

    def _write(self, data):
        self.data += data

    def poll(self):
        return None

    def kill(self):
        self.killed = True

    def wait(self):
        return 0


def test_a_helper_starts_only_where_the_compiler_is_serial_a_core_is_free_and_a_program_is_missing(
        device, tmp_path, monkeypatch):
    the_scene = validate(scene(True, 32))
    programs = plan(the_scene, GI, None, None, device).programs
    device.programs.build_all(programs)
    monkeypatch.setattr(warmup.subprocess, "Popen", _Recorder)
    monkeypatch.setattr(warmup.os, "cpu_count", lambda: 2)
    _Recorder.started = []
    assert warmup.start(device, the_scene, GI, programs) is None  # every program built already
    # a disk cache without them: a helper, where the compiler takes one program at a time
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "empty"))
    fresh = SimpleNamespace(device=device.device, programs=programs_module.Programs(device.context, device.device))
    process = warmup.start(fresh, the_scene, GI, programs)
    serial = programs_module.compile_helpers(device.device)
    assert (process is not None) == serial
    if serial:
        assert process.command[1:3] == ["-m", "gpu_core.warmup"]
        assert pickle.loads(process.data)[0].camera.width == warmup.SIDE
        warmup.stop(process)
        assert process.killed
    monkeypatch.setattr(warmup.os, "cpu_count", lambda: 1)
    assert warmup.start(fresh, the_scene, GI, programs) is None  # no core to spare


def test_a_program_that_never_reaches_the_disk_cache_is_an_error_when_waiting_for_it(device, tmp_path, monkeypatch):
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "empty"))
    waiting = programs_module.Programs(device.context, device.device)
    waiting.wait_for_cache(0.2)
    with pytest.raises(DeviceError, match="did not reach the disk cache"):
        waiting.get("device/primitives.cl")


def test_building_each_program_when_first_needed_renders_the_same_image(device):
    the_scene = scene(True, 24)
    lazily = Renderer(device, builds_up_front=False).render(the_scene, GI).passes["Combined"]
    np.testing.assert_array_equal(lazily, Renderer(device).render(the_scene, GI).passes["Combined"])


def test_the_helper_runs_the_stages_that_need_no_photon_map_before_its_render(device, monkeypatch):
    from gpu_core import renderer
    from gpu_core.gi import cut, shading_points
    from gpu_core.gi.cache import interpolation, samples

    events = []

    def recorded(module, name, event):
        original = getattr(module, name)

        def wrapper(*args, **kwargs):
            events.append(event(args, kwargs) if callable(event) else event)
            return original(*args, **kwargs)

        monkeypatch.setattr(module, name, wrapper)

    def image(args, kwargs):
        dev, field = args[0], args[5]  # render_image(device, buffers, scene, settings, defines, gi_field, ...)
        empty = not dev.read(field.positions, (warmup.SIDE ** 2, 4), np.float32).any()
        return "image, empty field" if empty else "image"

    recorded(renderer, "trace_maps", "photons")
    recorded(shading_points, "trace", "shading points")
    recorded(samples, "select", "cache points")
    recorded(interpolation, "interpolate_on_device", "interpolation")
    recorded(cut, "caustic_irradiance", "caustics")
    recorded(warmup, "render_image", image)
    recorded(renderer, "render_image", image)
    warmup.render_small_copy(device, *warmup.small_copy(scene(True, 32), GI))  # a mirror: caustics too
    assert events[:6] == ["shading points", "cache points", "image, empty field", "interpolation", "caustics",
                          "photons"]
    assert events[-1] == "image"


def test_the_helper_module_renders_a_pickled_small_copy(device):
    small = warmup.small_copy(scene(True, 32), GI)
    device.programs.build_all(plan(validate(small[0]), small[1], None, None, device).programs)  # it takes them from the disk cache
    spec = programs_module.device_spec(device.device)
    path = os.pathsep.join([str(ROOT), *(p for p in sys.path if p)])  # as start_helper: pyopencl may live elsewhere
    done = subprocess.run([sys.executable, "-m", "gpu_core.warmup", spec], input=pickle.dumps(small),
                          env=dict(os.environ, PYTHONPATH=path), capture_output=True, timeout=600)
    assert done.returncode == 0, done.stderr.decode()[-2000:]


def test_a_gi_render_builds_no_program_its_plan_does_not_list(device):
    # every program a render needs is built before its first stage: none is left to a stage to build
    the_scene = validate(scene(True, 24))  # a mirror: caustics seen directly and in the cut's nodes
    settings = dataclasses.replace(GI, caustic_k=GI.photon_k + 4)  # the two caustic estimates' k differ
    fresh = Device(context=device.context, queue=device.queue, device=device.device)
    fresh.programs.build_all(plan(the_scene, settings, None, None, fresh).programs)
    listed = len(fresh.builds)
    Renderer(fresh).render(the_scene, settings)
    assert [r.name for r in fresh.builds[listed:]] == []
