"""Esc during F12: test_break is polled between kernel batches and stops the render early.

Counted in batches (one progress report of a fraction above 0 per finished
batch; compiling kernels reports 0), never in seconds.
"""

from __future__ import annotations

import pytest

from blender_addon.engine import GpuGiRenderEngine
from blender_addon.final import LAST_RUN, render_final


class BreakAfter:
    """The real engine, except that test_break answers True once ``batches``
    kernel batches have reported progress."""

    def __init__(self, engine, batches: int):
        self._engine = engine
        self._batches = batches
        self.fractions: list[float] = []

    def update_progress(self, fraction):
        if fraction > 0.0:
            self.fractions.append(fraction)
        self._engine.update_progress(fraction)

    def test_break(self):
        return len(self.fractions) >= self._batches

    def __getattr__(self, name):
        return getattr(self._engine, name)

    def release(self):
        """Forget the engine: it must not outlive the render."""
        self._engine = None


PROBES: list[BreakAfter] = []


def _render_with_break(engine, depsgraph):
    """GpuGiRenderEngine.render with Esc pressed after scene["break_after"] batches."""
    probe = BreakAfter(engine, int(depsgraph.scene.get("break_after", 1)))
    PROBES.append(probe)
    try:
        render_final(probe, depsgraph)
    finally:
        probe.release()


@pytest.fixture
def probe_scene(bpy_empty, monkeypatch):
    # the registered engine's render is swapped for the probe's; registering a
    # second engine class instead leaves Blender's engine list unstable
    monkeypatch.setattr(GpuGiRenderEngine, "render", _render_with_break)
    bpy = bpy_empty
    bpy.ops.mesh.primitive_plane_add(size=20)
    bpy.ops.mesh.primitive_monkey_add(location=(0, 0, 1))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 4))
    bpy.ops.object.camera_add(location=(0, -6, 4), rotation=(1.0, 0, 0))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    # many more pixels than one kernel batch holds
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.gpugi.samples = 2
    scene.gpugi.mode = "REFERENCE"  # progress is counted in kernel batches only
    scene.gpugi.denoise = False  # (the denoiser reports its own step after them)
    scene.render.engine = GpuGiRenderEngine.bl_idname
    PROBES.clear()
    return scene


def test_render_runs_several_batches_when_not_cancelled(bpy_empty, probe_scene):
    probe_scene["break_after"] = 10_000
    bpy_empty.ops.render.render()
    assert LAST_RUN["stats"]["batches"] >= 2
    assert len(PROBES[-1].fractions) == LAST_RUN["stats"]["batches"]
    assert PROBES[-1].fractions[-1] == pytest.approx(1.0)


def test_break_after_the_first_batch_stops_the_render_there(bpy_empty, probe_scene):
    probe_scene["break_after"] = 1
    bpy_empty.ops.render.render()
    probe = PROBES[-1]
    assert len(probe.fractions) == 1 and probe.fractions[0] < 0.5  # one batch ran, most pixels did not
    assert LAST_RUN.get("cancelled") is True
    assert "passes" not in LAST_RUN and not LAST_RUN.get("error")


def test_break_before_rendering_skips_the_kernels(bpy_empty, probe_scene):
    probe_scene["break_after"] = 0
    bpy_empty.ops.render.render()
    assert PROBES[-1].fractions == []
    assert LAST_RUN.get("cancelled") is True
