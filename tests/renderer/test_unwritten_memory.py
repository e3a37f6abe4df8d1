"""A render reads only device memory it wrote. PoCL's fresh buffers mostly
hold zeros, a GPU driver's hold whatever was there before; here every buffer
the device's pool hands out is first filled with a pattern (all bits set: a
NaN and -1; then 0x7F7F7F7F: 3.4e38 and a huge index), and every pass must be
the plain render's, bit for bit, and every count in the stats the same."""

from __future__ import annotations

import numpy as np
import pytest
from test_threads import GI, REFERENCE, scene

from gpu_core.device.device import Device
from gpu_core.renderer import Renderer


def _counts(stats):
    """The stats without their timings."""
    if isinstance(stats, dict):
        return {key: _counts(value) for key, value in stats.items() if key != "ms"}
    return stats


@pytest.mark.parametrize("pattern", [0xFFFFFFFF, 0x7F7F7F7F], ids=["nan", "huge"])
@pytest.mark.parametrize("settings", [GI, REFERENCE], ids=["gi", "reference"])
def test_every_pass_is_the_same_when_fresh_buffers_hold_garbage(device, monkeypatch, settings, pattern):
    plain = Renderer(device).render(scene(True, 16), settings)
    handed_out = Device.empty

    def filled(self, nbytes):
        buf = handed_out(self, nbytes)
        self.fill(buf, pattern, max(int(nbytes), 16), np.uint32)
        return buf
    monkeypatch.setattr(Device, "empty", filled)
    garbage = Renderer(device).render(scene(True, 16), settings)
    assert garbage.passes.keys() == plain.passes.keys()
    for name, image in plain.passes.items():
        np.testing.assert_array_equal(garbage.passes[name], image, err_msg=name)
    assert _counts(garbage.stats) == _counts(plain.stats)
