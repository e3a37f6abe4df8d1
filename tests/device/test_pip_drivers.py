"""OpenCL drivers from pip and the automatic CPU choice: PoCL where its
compiler knows the CPU, else Intel's CPU runtime, made visible to the loader."""

import json
import os
import subprocess
import sys
from types import SimpleNamespace

import pyopencl as cl
import pytest
from conftest import ROOT

from gpu_core.device import pip_drivers
from gpu_core.device.select import _match, compiles_here, no_device_message

POCL_KNOWN = "OpenCL 3.0 PoCL HSTR: pthread-x86_64-unknown-linux-gnu-znver3"
POCL_GENERIC = "OpenCL 3.0 PoCL HSTR: pthread-x86_64-unknown-linux-gnu-generic"


def fake(platform: str, version: str, kind=cl.device_type.CPU):
    """A platform entry of _all_devices with one device of ``version``."""
    platform = SimpleNamespace(name=platform)
    return platform, SimpleNamespace(name=f"{platform.name} CPU", type=kind, version=version, platform=platform)


def found(*entries):
    return [(index, platform, [dev]) for index, (platform, dev) in enumerate(entries)]


def test_only_a_pocl_device_that_names_the_cpu_generic_cannot_compile():
    assert compiles_here(fake("Portable Computing Language", POCL_KNOWN)[1])
    assert not compiles_here(fake("Portable Computing Language", POCL_GENERIC)[1])
    assert compiles_here(fake("Intel(R) OpenCL", "OpenCL 3.0 (Build 0)")[1])
    assert compiles_here(fake("NVIDIA CUDA", "OpenCL 3.0 CUDA generic", cl.device_type.GPU)[1])


def test_the_automatic_cpu_choice_prefers_pocl_and_passes_over_one_that_cannot_compile():
    intel, pocl = fake("Intel(R) OpenCL", "OpenCL 3.0 (Build 0)"), fake("Portable Computing Language", POCL_KNOWN)
    generic = fake("Portable Computing Language", POCL_GENERIC)
    assert _match("", found(intel, pocl)) is pocl[1]  # listed second, still first choice
    assert _match("cpu", found(generic, intel)) is intel[1]
    assert _match("", found(generic)) is None
    assert _match("portable", found(generic, intel)) is generic[1]  # named, it is used


def test_with_only_an_unusable_pocl_the_error_says_what_to_install(monkeypatch):
    monkeypatch.setattr(pip_drivers, "problem", "")
    message = no_device_message(found(fake("Portable Computing Language", POCL_GENERIC)), "0:0  PoCL")
    assert "does not know this CPU model" in message and "intel-opencl-rt" in message
    monkeypatch.setattr(pip_drivers, "problem", "libintelocl.so: undefined symbol: x")
    message = no_device_message(found(fake("Portable Computing Language", POCL_GENERIC)), "0:0  PoCL")
    assert "installed but could not be loaded (libintelocl.so: undefined symbol: x)" in message


def test_the_vendors_folder_holds_the_system_drivers_and_the_pip_runtime(tmp_path, monkeypatch):
    system = tmp_path / "system"
    system.mkdir()
    (system / "nvidia.icd").write_text("libnvidia-opencl.so.1\n")
    (system / "readme.txt").write_text("not a driver")
    monkeypatch.setenv("OPENCL_VENDOR_PATH", str(system))
    library = tmp_path / "lib" / "libintelocl.so"
    folder = pip_drivers._vendors_folder(tmp_path / "cache", library)
    assert sorted(p.name for p in folder.iterdir()) == ["gpugi-intel-cpu.icd", "nvidia.icd"]
    assert (folder / "nvidia.icd").read_text() == "libnvidia-opencl.so.1\n"
    assert (folder / "gpugi-intel-cpu.icd").read_text().strip() == str(library)
    assert pip_drivers._vendors_folder(tmp_path / "cache", library) == folder  # made once
    (system / "amd.icd").write_text("libamdocl64.so\n")
    changed = pip_drivers._vendors_folder(tmp_path / "cache", library)
    assert changed != folder and (changed / "amd.icd").is_file()


def test_register_leaves_a_users_own_vendors_setting_alone(tmp_path, monkeypatch):
    monkeypatch.setattr(pip_drivers, "_DONE", False)
    monkeypatch.setenv("OCL_ICD_VENDORS", "/users/own/vendors")
    monkeypatch.delenv(pip_drivers.MARK, raising=False)
    monkeypatch.setenv("CL_CONFIG_USE_VECTORIZER", "True")  # the user's, kept
    pip_drivers.register(tmp_path)
    assert os.environ["OCL_ICD_VENDORS"] == "/users/own/vendors"
    assert os.environ["CL_CONFIG_USE_VECTORIZER"] == "True"
    assert not (tmp_path / "opencl-vendors").exists()


# a fresh process (the loader lists its drivers once per process): lists the
# platforms after bpy is imported, then runs a kNN batch on Intel's device
_INTEL_KNN = """
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from gpu_core.device import get_device, list_devices, load_pip_drivers
load_pip_drivers()
import bpy  # after the drivers: Blender's older TBB library must not come first
from gpu_core.accel.point_tree import PointTree
device = get_device("Intel")
rng = np.random.default_rng(3)
points = rng.random((400, 3)).astype(np.float32)
queries = rng.random((64, 3)).astype(np.float32)
ids, d2 = PointTree.build(device, points).knn(queries, 8)
want = np.sort(((queries[:, None].astype(np.float64) - points[None]) ** 2).sum(-1), axis=1)[:, :8]
print(json.dumps({"devices": list_devices(), "chosen": device.name, "fallback": device.fallback_message,
                  "rows_right": int(np.isclose(d2, want, rtol=1e-5).all(1).sum())}))
"""


@pytest.mark.slow
@pytest.mark.skipif(pip_drivers.intel_cpu_library() is None, reason="Intel's CPU runtime is not installed here")
def test_the_pip_installed_intel_runtime_is_listed_and_finds_each_query_its_own_neighbours(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("OCL_ICD_VENDORS", pip_drivers.MARK,
                                                            "CL_CONFIG_USE_VECTORIZER")}
    env["GPUGI_KERNEL_CACHE"] = str(tmp_path / "cache")
    env["PYOPENCL_NO_CACHE"] = "1"  # pyopencl's cache does not tell the vectorizer's setting apart
    out = subprocess.run([sys.executable, "-c", _INTEL_KNN, ROOT], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert any("Intel(R) OpenCL" in line for line in result["devices"]), result
    assert result["chosen"].startswith("Intel(R) OpenCL") and result["fallback"] == ""
    assert result["rows_right"] == 64  # with Intel's vectorizer on, rows trade places
