"""Device choice, fallback and the on-disk program cache."""

import json
import subprocess
import sys

import pytest
from conftest import ROOT

from gpu_core.device import get_device, list_devices, load_source
from gpu_core.errors import DeviceError

_PROBE = """
import json, sys
from gpu_core.device import get_device
d = get_device('cpu')
d.program('kdtree_query.cl')
print(json.dumps([b.from_cache for b in d.builds]))
"""


def test_default_device_is_the_pocl_cpu_device(device):
    assert device.is_cpu
    assert "portable computing language" in device.device.platform.name.lower()
    assert any("Portable Computing Language" in line for line in list_devices())


def test_missing_platform_falls_back_to_cpu_with_a_message():
    dev = get_device("no-such-platform-anywhere")
    assert dev.is_cpu
    assert "no-such-platform-anywhere" in dev.fallback_message
    assert "not found" in dev.fallback_message


def test_environment_variable_picks_the_device(monkeypatch):
    monkeypatch.setenv("GPUGI_DEVICE", "Portable:0")
    dev = get_device()
    assert dev.is_cpu and dev.fallback_message == ""


def test_second_process_loads_programs_from_the_disk_cache(tmp_path):
    env = {"GPUGI_KERNEL_CACHE": str(tmp_path), "PATH": "/usr/bin:/bin"}
    runs = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", _PROBE], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert runs == [[False], [True]]
    assert len(list(tmp_path.glob("kdtree_query-*.bin"))) == 1


def test_missing_kernel_source_raises_device_error(device):
    with pytest.raises(DeviceError, match="missing"):
        device.program("no_such_kernel.cl")
    with pytest.raises(DeviceError):
        load_source("nope.h")
