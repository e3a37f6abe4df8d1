"""Device faults in the middle of a render: an allocation that fails, a
kernel launch on a lost device, a program that does not build. Each is a
DeviceError with a message the user can act on, and the next render of the
same renderer is the image of a fresh one."""

from __future__ import annotations

import itertools

import numpy as np
import pyopencl as cl
import pytest
from test_threads import GI, scene

import gpu_core.plan as plan_module
from gpu_core.device.device import Device
from gpu_core.device.kernels import Kernel
from gpu_core.errors import DeviceError
from gpu_core.renderer import Renderer


def _fail_at(monkeypatch, cls, name: str, at: int, error: Exception) -> None:
    """Make the ``at``-th call of ``cls.name`` (from now on) raise ``error``."""
    original, calls = getattr(cls, name), itertools.count()

    def failing(self, *args, **kwargs):
        if next(calls) == at:
            raise error
        return original(self, *args, **kwargs)
    monkeypatch.setattr(cls, name, failing)


@pytest.fixture
def expected(device):
    return Renderer(device).render(scene(True, 16), GI).passes["Combined"]


@pytest.mark.parametrize("at", [0, 7, 40, 120])
def test_a_failed_allocation_says_the_device_ran_out_and_the_next_render_is_whole(device, monkeypatch, expected, at):
    renderer = Renderer(device)
    renderer.render(scene(True, 16), GI)  # something held, to be forgotten
    with monkeypatch.context() as patch:
        _fail_at(patch, Device, "empty", at,
                 cl.MemoryError("clCreateBuffer", cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE, "simulated"))
        with pytest.raises(DeviceError, match="ran out of memory or resources.*Lower the resolution"):
            renderer.render(scene(True, 16), GI, edits={"lights"})
    np.testing.assert_array_equal(renderer.render(scene(True, 16), GI).passes["Combined"], expected)


@pytest.mark.parametrize("at", [0, 5, 30])
def test_a_lost_device_during_a_launch_is_a_clear_error_and_the_next_render_is_whole(device, monkeypatch, expected,
                                                                                    at):
    renderer = Renderer(device)
    with monkeypatch.context() as patch:
        _fail_at(patch, Kernel, "__call__", at,
                 cl.LogicError("clEnqueueNDRangeKernel", cl.status_code.DEVICE_NOT_AVAILABLE, "simulated"))
        with pytest.raises(DeviceError, match="failed during the render.*choose another device"):
            renderer.render(scene(True, 16), GI)
    np.testing.assert_array_equal(renderer.render(scene(True, 16), GI).passes["Combined"], expected)


def test_a_program_that_does_not_build_names_itself_and_the_next_render_is_whole(device, monkeypatch, expected):
    renderer = Renderer(device)
    original = plan_module.image_programs
    with monkeypatch.context() as patch:
        patch.setattr(plan_module, "image_programs", lambda defines: [(name, {**d, "IMAGE_STRIP": "("})
                                                                      for name, d in original(defines)])
        with pytest.raises(DeviceError, match="image.cl.*failed to build"):
            renderer.render(scene(True, 16), GI)
    np.testing.assert_array_equal(renderer.render(scene(True, 16), GI).passes["Combined"], expected)
