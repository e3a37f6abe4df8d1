"""Blender's Persistent Data: F12 renders of a scene (an animation's frames)
keep one renderer, so a frame reuses what did not change since the last one."""

import os

import numpy as np
import pytest
from conftest import ROOT, render_to_array

from blender_addon import device_memory, final
from blender_addon.final import LAST_RUN
from gpu_core.device import select


def _box_torus(bpy, persistent: bool):
    final.release_held()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", "box_torus.blend"))
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.resolution_percentage = 100
    scene.gpugi.mode, scene.gpugi.preset = "GI", "DRAFT"
    scene.gpugi.denoise = False
    scene.render.use_persistent_data = persistent
    return scene


def _frame(bpy, scene, path) -> tuple[np.ndarray, list[str]]:
    image = render_to_array(bpy, scene, "GPUGI", str(path))
    assert not LAST_RUN.get("error")
    return image, LAST_RUN["stats"]["plan"]


@pytest.mark.parametrize("persistent", [True, False])
def test_a_camera_move_reuses_the_kdtree_and_photons_only_with_persistent_data(bpy_module, tmp_path, persistent):
    scene = _box_torus(bpy_module, persistent)
    first, plan = _frame(bpy_module, scene, tmp_path / "1.exr")
    assert {"kdtree", "global_photons"} <= set(plan)
    scene.camera.location.x += 0.2
    second, plan = _frame(bpy_module, scene, tmp_path / "2.exr")
    reused = {"kdtree_reused", "global_photons_reused"}
    assert reused <= set(plan) if persistent else not reused & set(plan)
    assert not np.allclose(first, second)  # the new view, not the old image


def test_a_light_power_edit_reweights_the_photons_and_keeps_the_kdtree(bpy_module, tmp_path):
    scene = _box_torus(bpy_module, True)
    first, _ = _frame(bpy_module, scene, tmp_path / "1.exr")
    light = next(obj for obj in scene.objects if obj.type == "LIGHT")
    light.data.energy *= 2.0
    second, plan = _frame(bpy_module, scene, tmp_path / "2.exr")
    assert "kdtree_reused" in plan and "global_photons_reweighted" in plan
    # one light, all light scales with it (the same random streams)
    np.testing.assert_allclose(second[..., :3].mean(), 2.0 * first[..., :3].mean(), rtol=1e-3)


def test_turning_persistent_data_off_gives_the_held_renderer_back(bpy_module, tmp_path):
    scene = _box_torus(bpy_module, True)
    _frame(bpy_module, scene, tmp_path / "1.exr")
    assert final._HELD
    scene.render.use_persistent_data = False
    _frame(bpy_module, scene, tmp_path / "2.exr")
    assert not final._HELD


def test_an_animation_keeps_its_renderer_across_frames_without_persistent_data(bpy_module, tmp_path):
    scene = _box_torus(bpy_module, False)
    camera = scene.camera
    camera.keyframe_insert("location", frame=1)
    camera.location.x += 0.2
    camera.keyframe_insert("location", frame=2)
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.engine = "GPUGI"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "frame_")
    plans = []
    listener = lambda scene, depsgraph=None: plans.append(list(LAST_RUN.get("stats", {}).get("plan", [])))  # noqa: E731
    bpy_module.app.handlers.render_post.append(listener)
    try:
        bpy_module.ops.render.render(animation=True, scene=scene.name)
    finally:
        bpy_module.app.handlers.render_post.remove(listener)
    assert len(plans) == 2 and not LAST_RUN.get("error")
    assert {"kdtree", "global_photons"} <= set(plans[0])
    assert {"kdtree_reused", "global_photons_reused"} <= set(plans[1])  # only the camera moved
    assert final._JOB is None and not final._HELD  # the job's renderer is given back when it ends
    # and the memory it let go: a GPU's at once, a CPU device's (host memory) once the release comes
    assert all(pool.held_blocks == 0 for pool, cpu in _pools() if not cpu)
    device_memory._release_if_idle(device_memory._RENDERS_STARTED)
    assert _pools() and all(pool.held_blocks == 0 for pool, _ in _pools())
    assert sorted(os.listdir(tmp_path)) == ["frame_0001.exr", "frame_0002.exr"]


def _pools() -> list:
    """Each opened device's memory pool and whether the device is a CPU."""
    return [(device._pool, device.is_cpu) for device in select._DEVICES.values() if device._pool is not None]


def test_a_cpu_devices_memory_waits_for_the_next_render_and_goes_back_when_none_comes(bpy_module, tmp_path):
    scene = _box_torus(bpy_module, False)
    _frame(bpy_module, scene, tmp_path / "1.exr")
    ended = device_memory._RENDERS_STARTED

    def held(cpu: bool) -> int:
        return sum(pool.held_blocks for pool, is_cpu in _pools() if is_cpu == cpu)

    assert held(cpu=False) == 0  # a GPU's memory goes back when the job ends
    assert held(cpu=True) > 0 or not any(is_cpu for _, is_cpu in _pools())  # a CPU's waits
    first = held(cpu=True)
    _frame(bpy_module, scene, tmp_path / "2.exr")
    second = held(cpu=True)
    assert second <= first + 16  # the next render took those buffers again: no growth
    device_memory._release_if_idle(ended)  # the first job's release: another job started since, it keeps them
    assert held(cpu=True) == second
    device_memory._release_if_idle(device_memory._RENDERS_STARTED)  # the last job's release, nothing started since
    assert held(cpu=True) == 0 and held(cpu=False) == 0
