"""Device choice, fallback and kernel programs: built once, cached on disk, clear errors."""

import json
import os
import subprocess
import sys

import numpy as np
import pyopencl as cl
import pytest
from conftest import ROOT

import gpu_core.device.programs as programs_module
from gpu_core.gi.cache import interpolation, neighbours
from gpu_core.device import get_device, list_devices, load_source
from gpu_core.device.select import compiles_here
from gpu_core.errors import DeviceError

POCL = "portable computing language"

_KERNEL = """
#include "probe.h"
/* out[i] = Probe_value(i) */
__kernel void Probe_fill(__global float *out) {
    int i = get_global_id(0);
    out[i] = Probe_value(i);
}
"""
_HEADER = "inline float Probe_value(int i) { return %s; }\n"

# a second process: builds probe.cl from the folder argv[1], runs it, prints what happened
_PROBE = """
import json, sys, pathlib
import numpy as np, pyopencl as cl
import gpu_core.device.programs as programs_module
from gpu_core.gi.cache import interpolation, neighbours
from gpu_core.device import get_device
programs_module.INCLUDE_ROOT = pathlib.Path(sys.argv[1])
dev = get_device()
program = dev.program("probe.cl")
out = np.zeros(4, np.float32)
buf = dev.empty(out.nbytes)
program.Probe_fill(dev.queue, out.shape, None, buf)
cl.enqueue_copy(dev.queue, out, buf)
print(json.dumps({"from_cache": [b.from_cache for b in dev.builds], "values": out.tolist()}))
"""


def _kernel_dir(path, expression="2.0f * (float)i + 1.0f", kernel=_KERNEL):
    """A kernel folder holding probe.cl and the probe.h it includes."""
    path.mkdir(parents=True, exist_ok=True)
    (path / "probe.cl").write_text(kernel)
    (path / "probe.h").write_text(_HEADER % expression)
    return path


# a process that builds probe.cl from argv[1] whole, the way any other program would
_FULL_BUILD = """
import sys, pathlib
import numpy as np
import pyopencl as cl
import gpu_core.device.programs as programs_module
from gpu_core.gi.cache import interpolation, neighbours
from gpu_core.device import get_device
programs_module.INCLUDE_ROOT = pathlib.Path(sys.argv[1])
dev = get_device()
source = programs_module.load_source("probe.cl")
cl.Program(dev.context, source).build(options=list(programs_module.build_options()))
"""


def _run_probe(kernels, cache, script=_PROBE, pocl_cache=None):
    """Run ``script`` in a fresh process with its own kernel cache folder
    (and its own PoCL cache folder, given one)."""
    env = dict(os.environ, GPUGI_KERNEL_CACHE=str(cache))
    env.pop("GPUGI_DEVICE", None)
    if pocl_cache is not None:
        env["POCL_CACHE_DIR"] = str(pocl_cache)
    out = subprocess.run([sys.executable, "-c", script, str(kernels)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    return json.loads(lines[-1]) if lines else None


# -- device choice ------------------------------------------------------------------


def test_default_device_is_the_pocl_cpu_device_where_its_compiler_knows_the_cpu(monkeypatch):
    monkeypatch.delenv("GPUGI_DEVICE", raising=False)
    dev = get_device()
    assert dev.is_cpu and compiles_here(dev.device)
    pocl = [d for p in cl.get_platforms() for d in p.get_devices() if POCL in p.name.lower()]
    if any(compiles_here(d) for d in pocl):
        assert POCL in dev.device.platform.name.lower()
    else:  # a CPU newer than PoCL's LLVM: Intel's CPU runtime from PyPI
        assert dev.device.platform.name.startswith("Intel(R) OpenCL")
    assert dev.fallback_message == ""
    assert dev is get_device()  # one device per process


def test_an_automatic_choice_skips_a_simulator_platform_listed_first():
    from types import SimpleNamespace

    from gpu_core.device.select import _match

    oclgrind, pocl = SimpleNamespace(name="Oclgrind"), SimpleNamespace(name="Portable Computing Language")
    simulator = SimpleNamespace(name="Oclgrind Simulator", type=cl.device_type.CPU, version="OpenCL 1.2 (Oclgrind)",
                                platform=oclgrind)
    cpu = SimpleNamespace(name="pthread CPU", type=cl.device_type.CPU, version="OpenCL 3.0 PoCL HSTR: pthread-znver3",
                          platform=pocl)
    found = [(0, oclgrind, [simulator]), (1, pocl, [cpu])]
    assert _match("", found) is cpu and _match("cpu", found) is cpu
    assert _match("oclgrind", found) is simulator  # named, it is used


def test_gpugi_device_naming_a_missing_platform_falls_back_to_cpu(monkeypatch):
    monkeypatch.setenv("GPUGI_DEVICE", "no-such-platform-anywhere")
    dev = get_device()
    assert dev.is_cpu and dev.device == get_device("cpu").device
    assert "'no-such-platform-anywhere'" in dev.fallback_message
    assert "not found" in dev.fallback_message
    assert dev.device.platform.name.strip() in dev.fallback_message  # what it uses instead


def test_missing_device_number_on_a_present_platform_falls_back_with_a_message():
    dev = get_device("Portable:99")
    assert dev.is_cpu
    assert "'Portable:99'" in dev.fallback_message


def test_gpugi_device_picks_a_present_device_without_a_message(monkeypatch):
    monkeypatch.setenv("GPUGI_DEVICE", "Portable:0")
    dev = get_device()
    assert dev.is_cpu and dev.fallback_message == ""


def test_an_explicit_device_argument_wins_over_the_environment(monkeypatch):
    monkeypatch.setenv("GPUGI_DEVICE", "no-such-platform-anywhere")
    assert get_device("cpu").fallback_message == ""


def test_list_devices_lists_the_cpu_device_and_its_spec_selects_it(device):
    lines = list_devices()
    cpu_lines = [line for line in lines if device.device.platform.name.strip() in line]
    assert cpu_lines, lines
    assert any(device.device.name.strip() in line for line in cpu_lines)
    spec = cpu_lines[0].split()[0]  # "P:D"
    chosen = get_device(spec)
    assert chosen.fallback_message == ""
    assert chosen.device.int_ptr == device.device.int_ptr


# -- programs and the disk cache ----------------------------------------------------


def test_program_is_built_once_per_process_and_per_define_set(device, tmp_path, monkeypatch):
    kernels = _kernel_dir(tmp_path / "kernels")
    (kernels / "probe_once.cl").write_text(_KERNEL)
    monkeypatch.setattr(programs_module, "INCLUDE_ROOT", kernels)
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))
    before = len(device.builds)
    first = device.program("probe_once.cl")
    assert device.program("probe_once.cl") is first
    assert len(device.builds) == before + 1
    assert device.builds[-1].name == "probe_once.cl" and not device.builds[-1].from_cache
    other = device.program("probe_once.cl", {"PROBE_UNUSED": 1})
    assert other is not first and len(device.builds) == before + 2
    assert len(list((tmp_path / "cache").glob("probe_once-*.bin"))) == 2


def test_programs_without_defines_of_their_own_are_built_as_one_bundle(device, tmp_path, monkeypatch):
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))
    programs = programs_module.Programs(device.context, device.device)
    programs.build_all([(name, {}) for name in programs_module.BUNDLED])
    assert [r.name for r in programs.builds] == [programs_module.BUNDLE]
    bundle = programs.get("gi/cache/grid.cl")
    assert all(programs.get(name) is bundle for name in programs_module.BUNDLED)
    assert {"Prim_iota", "Cache_grid_keys", "Cache_normalise"} <= {k.function_name for k in bundle.all_kernels()}
    # with defines of its own a bundled program is built alone
    alone = programs.get("gi/cache/grid.cl", {"GRID_UNUSED": 1})
    assert alone is not bundle and [k.function_name for k in alone.all_kernels()] == ["Cache_grid_keys"]


def test_the_tracing_programs_asked_for_with_the_same_scene_defines_are_built_as_one(device, tmp_path, monkeypatch):
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))
    programs = programs_module.Programs(device.context, device.device)
    scene = {"SCENE_HAS_MIX": 1}
    programs.build_all([(name, scene) for name in programs_module.SCENE_BUNDLED])
    assert [r.name for r in programs.builds] == [programs_module.SCENE_BUNDLE]
    bundle = programs.get("gi/shading_points.cl", scene)
    assert programs.get("photons/photon_trace.cl", scene) is bundle
    assert {"Photon_trace", "ShadingPoints_trace"} <= {k.function_name for k in bundle.all_kernels()}
    # another scene's defines: another build of the bundle, both programs again
    other = programs.get("photons/photon_trace.cl", {})
    assert other is not bundle and "ShadingPoints_trace" in {k.function_name for k in other.all_kernels()}
    assert [r.name for r in programs.builds] == [programs_module.SCENE_BUNDLE] * 2


def test_second_process_loads_the_program_from_the_disk_cache(tmp_path):
    kernels = _kernel_dir(tmp_path / "kernels")
    cache = tmp_path / "cache"
    first = _run_probe(kernels, cache)
    second = _run_probe(kernels, cache)
    assert first == {"from_cache": [False], "values": [1.0, 3.0, 5.0, 7.0]}
    assert second == {"from_cache": [True], "values": [1.0, 3.0, 5.0, 7.0]}
    assert len(list(cache.glob("probe-*.bin"))) == 1


def test_a_whole_build_of_the_same_source_elsewhere_does_not_spoil_the_cached_one(tmp_path):
    # the driver's own cache may key a whole build and a compiled object alike
    kernels = _kernel_dir(tmp_path / "kernels")
    pocl_cache = tmp_path / "pocl"
    _run_probe(kernels, tmp_path / "unused", script=_FULL_BUILD, pocl_cache=pocl_cache)
    for cache_state in ("cold", "warm"):
        result = _run_probe(kernels, tmp_path / "cache", pocl_cache=pocl_cache)
        assert result["values"] == [1.0, 3.0, 5.0, 7.0], cache_state


def test_editing_an_included_header_invalidates_the_cached_program(tmp_path):
    kernels = _kernel_dir(tmp_path / "kernels")
    cache = tmp_path / "cache"
    assert _run_probe(kernels, cache)["from_cache"] == [False]
    _kernel_dir(kernels, expression="(float)(i * i)")
    edited = _run_probe(kernels, cache)
    assert edited == {"from_cache": [False], "values": [0.0, 1.0, 4.0, 9.0]}
    assert len(list(cache.glob("probe-*.bin"))) == 2


@pytest.mark.parametrize("damage", [b"", b"\x7fELF not a program binary" * 40], ids=["empty", "garbage"])
def test_damaged_cache_file_is_rebuilt_and_replaced(tmp_path, damage):
    kernels = _kernel_dir(tmp_path / "kernels")
    cache = tmp_path / "cache"
    _run_probe(kernels, cache)
    (binary,) = cache.glob("probe-*.bin")
    binary.write_bytes(damage)
    rebuilt = _run_probe(kernels, cache)
    assert rebuilt == {"from_cache": [False], "values": [1.0, 3.0, 5.0, 7.0]}
    assert _run_probe(kernels, cache)["from_cache"] == [True]


# programs of no scene features, none of them bundled, each compiling in about a second
_PROGRAMS = [("photons/photon_reweight.cl", {}), ("accel/kdtree_overlay.cl", {}), *neighbours.programs(),
             *interpolation.programs()[:1]]


def _fresh_build(device, tmp_path, monkeypatch):
    """build_all of _PROGRAMS into an empty disk cache, as if on four cores."""
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(programs_module.os, "cpu_count", lambda: 4)
    programs = programs_module.Programs(device.context, device.device)
    programs.build_all(_PROGRAMS)
    assert len(list((tmp_path / "cache").glob("*.bin"))) == len(_PROGRAMS)
    assert sorted(r.name for r in programs.builds) == sorted(name for name, _ in _PROGRAMS)
    return {r.name for r in programs.builds if r.from_cache}


def test_programs_missing_from_the_disk_cache_are_compiled_by_helper_processes_where_the_compiler_is_serial(
        device, tmp_path, monkeypatch):
    # this process keeps the first of four shares; the helpers' programs are loaded from the disk cache
    loaded = _fresh_build(device, tmp_path, monkeypatch)
    serial = programs_module.compile_helpers(device.device)
    kept = {name for name, _ in programs_module.shares(_PROGRAMS, 4)[0]}
    assert kept and loaded == ({name for name, _ in _PROGRAMS} - kept if serial else set())


def test_shares_of_builds_balance_their_cost_and_part_the_costliest():
    wanted = [(name, {}) for name in ("device/bundle.cl", "accel/kdtree_build.cl", "device/scene_bundle.cl",
                                      "gi/cut.cl", "gi/gather.cl", "gi/cache/neighbours.cl",
                                      "gi/cache/interpolation.cl", "accel/point_tree_query.cl", "image.cl")]
    cost = {name: programs_module.build_cost(name) for name, _ in wanted}
    for count in (2, 3, 4):
        parts = programs_module.shares(wanted, count)
        assert sorted(item for part in parts for item in part) == sorted(wanted)  # each program once
        totals = [sum(cost[name] for name, _ in part) for part in parts]
        assert max(totals) - min(totals) <= max(cost.values())
    # the four costliest programs built in four processes, one each
    costliest = sorted(cost, key=cost.get)[-4:]
    assert sorted(sum(name in costliest for name, _ in part) for part in programs_module.shares(wanted, 4)) == [1] * 4


def test_compile_helpers_are_off_when_the_environment_says_so(device, tmp_path, monkeypatch):
    monkeypatch.setenv("GPUGI_COMPILE_HELPERS", "0")
    assert not programs_module.compile_helpers(device.device)
    assert _fresh_build(device, tmp_path, monkeypatch) == set()


@pytest.mark.parametrize("interpreter", ["/bin/false", "/no/such/python"])
def test_a_helper_that_fails_or_cannot_start_leaves_its_programs_to_this_process(device, tmp_path, monkeypatch,
                                                                              interpreter):
    monkeypatch.setattr(programs_module.sys, "executable", interpreter)
    assert _fresh_build(device, tmp_path, monkeypatch) == set()


# -- errors -------------------------------------------------------------------------


def test_missing_kernel_source_raises_device_error(device):
    with pytest.raises(DeviceError, match="no_such_kernel.cl.*missing"):
        device.program("no_such_kernel.cl")
    with pytest.raises(DeviceError, match="missing"):
        load_source("nope.h")


def test_missing_included_header_raises_device_error_naming_it(device, tmp_path, monkeypatch):
    (tmp_path / "needs_header.cl").write_text('#include "absent_header.h"\n__kernel void k(void) {}\n')
    monkeypatch.setattr(programs_module, "INCLUDE_ROOT", tmp_path)
    with pytest.raises(DeviceError, match="absent_header.h"):
        device.program("needs_header.cl")


def test_kernel_that_does_not_compile_raises_device_error_naming_it(device, tmp_path, monkeypatch):
    (tmp_path / "broken_probe.cl").write_text("__kernel void Broken_probe(__global float *out) { out[0] = ; }\n")
    monkeypatch.setattr(programs_module, "INCLUDE_ROOT", tmp_path)
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path / "cache"))
    with pytest.raises(DeviceError, match="broken_probe.cl.*failed to build"):
        device.program("broken_probe.cl")


def test_load_source_inlines_each_included_header_once(tmp_path, monkeypatch):
    kernels = _kernel_dir(tmp_path)
    (kernels / "twice.cl").write_text('#include "probe.h"\n#include "probe.h"\n__kernel void k(void) {}\n')
    monkeypatch.setattr(programs_module, "INCLUDE_ROOT", kernels)
    probe = load_source("probe.cl")
    assert "#include" not in probe and "inline float Probe_value" in probe and "Probe_fill" in probe
    assert load_source("twice.cl").count("inline float Probe_value") == 1


def test_a_released_buffer_is_handed_to_the_next_allocation_of_its_size(device):
    first = device.empty(1000)
    address = first.int_ptr
    del first
    again = device.empty(1000)
    assert again.int_ptr == address
    other = device.empty(1000)  # while ``again`` is held, a buffer of its own
    assert other.int_ptr != address


def test_freeing_held_memory_can_keep_a_cpu_devices_host_memory(device):
    # the tests' device was opened through get_device, so free_held_memory reaches it
    from gpu_core.device import free_held_memory

    dropped = device.empty(1 << 20)
    del dropped
    assert device._pool.held_blocks >= 1
    free_held_memory(keep_host_memory=True)
    assert (device._pool.held_blocks >= 1) == device.is_cpu  # a CPU's host memory waits, a GPU's goes
    free_held_memory()
    assert device._pool.held_blocks == 0


def test_freeing_held_memory_gives_unused_buffers_back(device):
    kept = device.empty(1 << 20)
    dropped = device.empty(1 << 20)
    del dropped
    device.free_held()
    assert device._pool.held_blocks == 0
    assert device._pool.active_blocks >= 1  # the buffer still in use stays
    data = np.arange(1 << 18, dtype=np.int32)
    device.write(kept, data)
    assert (device.read(kept, data.shape, np.int32) == data).all()


def test_a_lone_work_group_is_one_work_item_on_a_cpu_and_the_local_size_elsewhere(device):
    kernel = device.kernel("device/primitives.cl", "Prim_radix_sort_group")
    assert kernel.lone_group(True) == 1 and kernel.lone_group(True, 8) == 1
    assert kernel.lone_group(False) == kernel.local
    assert kernel.lone_group(False, 8) == min(kernel.local, 8)
