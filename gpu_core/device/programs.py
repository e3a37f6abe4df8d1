"""Kernel programs: sources with their includes inlined, built once per
process, cached on disk across processes, built up front in parallel
(threads, or helper processes where the compiler takes one at a time).

Every ``#include "dir/file.h"`` is relative to the include root, the
``gpu_core`` folder, and is inlined once; ``#line`` markers keep a build
error pointing at the real file and line. Two files are generated rather
than read: ``device/structs.h`` (the shared structs, device/layout.py) and
``device/layout_probe.cl`` (the kernel that checks them). Every program is
built with the shared constants (device/constants.py) as ``-D`` defines.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pyopencl as cl

from ..errors import DeviceError
from . import constants, layout
from ..shading import microfacet_tables

POCL_PLATFORM = "Portable Computing Language"  # PoCL's platform name, which several quirks below are keyed by
INCLUDE_ROOT = Path(__file__).resolve().parent.parent
_INCLUDE_RE = re.compile(r'^[ \t]*#[ \t]*include[ \t]+"([^"]+)"[ \t]*$', re.MULTILINE)
_KERNEL_RE = re.compile(r"\b__kernel\b")
_GENERATED: dict[str, Callable[[], str]] = {
    "device/structs.h": layout.structs_header,
    "device/layout_probe.cl": layout.probe_source,
    "shading/microfacet_tables.h": microfacet_tables.header,
}
# Programs asked for without defines of their own are built as one, the
# bundle: PoCL spends about 0.3 s on a program before its first line (it
# parses its OpenCL C header), and a first render waits for its programs'
# builds one after another (six of these: 2.4 s apart, 1.3 s as one).
BUNDLE = "device/bundle.cl"
BUNDLED = ("device/primitives.cl", "accel/point_tree_build.cl", "accel/kdtree_blocks.cl", "gi/cache/frame.cl",
           "gi/cache/seeding.cl", "gi/cache/clusters.cl", "gi/cache/grid.cl")
# Likewise the two tracing programs that take the scene's defines and no
# others, photon tracing and the shading points: each parses the whole of
# the shading code besides the header.
SCENE_BUNDLE = "device/scene_bundle.cl"
SCENE_BUNDLED = ("photons/photon_trace.cl", "gi/shading_points.cl")
for _bundle, _members in ((BUNDLE, BUNDLED), (SCENE_BUNDLE, SCENE_BUNDLED)):
    _GENERATED[_bundle] = lambda members=_members: "".join(f'#include "{name}"\n' for name in members)
_OPTIONS = ("-cl-std=CL1.2", "-cl-mad-enable")
_CACHE_FORMAT = "3"
# platforms whose program builds must not run in parallel threads, nor
# load a binary from the disk cache (Oclgrind's compiler crashes on both);
# their interpreter lacks some LLVM intrinsics (llvm.bitreverse), which
# kernels then leave to portable code (GPUGI_SIMULATOR)
_SIMULATOR_PLATFORMS = ("oclgrind",)
_SIMULATOR_MARK = "-DGPUGI_SIMULATOR=1"
# A PoCL program binary holds every kernel compiled for any work-group size,
# which compiles each kernel a second time (the launches compile their own
# size): 11 of the 24 s of a first render. There the cache keeps the
# compiled object instead (PoCL's LLVM bitcode, before linking), and a load
# links it; PoCL's own cache keeps the work-group functions. PoCL's cache
# keys a compiled object and a built program of one source alike, so the
# compiled ones carry a define of their own: a full build of the same source
# elsewhere would otherwise hand compile() a linked program to link again.
_SEPARATE_PLATFORMS = (POCL_PLATFORM,)
_SEPARATE_MARK = "-DGPUGI_COMPILED_OBJECT=1"
# PoCL links its builtins after inlining, leaving each dot or fmax a call:
# there every program starts with the header that inlines them
_INLINE_BUILTINS_PLATFORMS = (POCL_PLATFORM,)
_INLINE_BUILTINS = Path(__file__).with_name("pocl_builtins.h")
# Division and square root correctly rounded wherever the device offers it
# (OpenCL C allows 2.5 and 3 ulp otherwise, and NVIDIA's driver takes that):
# kernels then compute alike on PoCL and a GPU. Without it, on NVIDIA's
# driver the kd-tree's ray shear (dir / dz, times corners 1e5 units away)
# moved hit distances past the tests' 1e-4; it costs the image kernel there
# 5-30% (README, "On a GPU").
_EXACT_DIVISION = "-cl-fp32-correctly-rounded-divide-sqrt"
# Native cosine and sine only where they are accurate to a few ulp (PoCL):
# elsewhere sampling.h takes the accurate pair (Intel's CPU runtime's
# natives err by 1.5e-4, enough to lose a photon path: tests/device/test_sampling.py)
_NATIVE_TRIG_PLATFORMS = (POCL_PLATFORM,)
_NATIVE_TRIG_MARK = "-DGPUGI_NATIVE_TRIG=1"
# PoCL 3.0's LLVM 14 names a CPU newer than it "generic" and refuses to compile for it
_UNKNOWN_CPU_HINT = ("\nThis OpenCL compiler does not know this CPU model. Choose another OpenCL device: "
                     "Intel's CPU runtime (pip install intel-opencl-rt) or a GPU vendor's driver.")
# Platforms whose compiler builds one program at a time per process, threads
# or not (PoCL: a first render's 8 s of builds on two cores took 8 s of CPU):
# there a render's kernels are compiled ahead in a helper process
# (warmup.py), and the programs missing from the disk cache shared with
# helper processes on the cores left (device/prebuild.py), at most
# _MAX_HELPERS, each given at most _HELPER_WAIT seconds before its programs
# are compiled here instead. (NVIDIA's driver builds mostly one at a time
# in threads too: a render's 9 programs 15.8 s one after another, 12.4-14.2
# s in threads on an H100; but helper processes there took 27-35 s against
# 16-22 s in threads, so it keeps to threads.)
_SERIAL_COMPILER_PLATFORMS = (POCL_PLATFORM,)
_MAX_HELPERS = 3
_HELPER_WAIT = 300.0
# A program's build cost, to share builds out evenly, in source characters:
# a fixed part, its source, and a part per kernel (fitted to PoCL on two
# cores, where builds took 0.41 s for 20k characters and one kernel, 1.05 s
# for the image's 329k and one, 1.4 s for the bundle's 80k and 45 kernels)
_PROGRAM_COST = 200_000
_KERNEL_COST = 11_000


def kernel_cache_dir() -> Path:
    """Folder of cached program binaries (``GPUGI_KERNEL_CACHE`` overrides it)."""
    env = os.environ.get("GPUGI_KERNEL_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gpugi" / "kernels"


def _read(name: str) -> str:
    if name in _GENERATED:
        return _GENERATED[name]()
    path = INCLUDE_ROOT / name
    if not path.is_file():
        raise DeviceError(f"kernel source {name!r} is missing from {INCLUDE_ROOT}")
    return path.read_text()


def load_source(name: str) -> str:
    """Source of ``name`` (relative to the include root) with every include
    inlined once, between ``#line`` markers naming the real files."""
    seen: set[str] = set()

    def expand(file_name: str) -> str:
        seen.add(file_name)
        text = _read(file_name)
        out, last = [f'#line 1 "{file_name}"\n'], 0
        for match in _INCLUDE_RE.finditer(text):
            out.append(text[last:match.start()])
            included = match.group(1)
            if included not in seen:
                resume = text.count("\n", 0, match.end()) + 2
                out.append(expand(included) + f'\n#line {resume} "{file_name}"')
            last = match.end()
        out.append(text[last:])
        return "".join(out)

    return expand(name)


def with_inline_builtins(source: str) -> str:
    """A program's source as PoCL builds it: after the header that inlines
    OpenCL's math builtins (pocl_builtins.h)."""
    return f'#line 1 "device/{_INLINE_BUILTINS.name}"\n{_INLINE_BUILTINS.read_text()}\n{source}'


def built_as(name: str, defines: dict | None = None) -> str:
    """The program that holds program ``name`` built with ``defines``: the
    bundle for a bundled program without defines, the scene bundle for a
    program of SCENE_BUNDLED (built with the scene's defines it is asked
    with), else ``name`` itself."""
    if name in BUNDLED and not defines:
        return BUNDLE
    return SCENE_BUNDLE if name in SCENE_BUNDLED else name


def _distinct(wanted: list[tuple[str, dict]]) -> list[tuple[str, dict]]:
    """The (program, defines) builds ``wanted`` asks for, each once, in
    order, bundled programs named by their bundle."""
    keys = dict.fromkeys((built_as(n, d), tuple(sorted((d or {}).items()))) for n, d in wanted)
    return [(n, dict(d)) for n, d in keys]


def device_spec(device: cl.Device) -> str | None:
    """``P:D``, the platform and device numbers get_device takes, of ``device``."""
    try:
        for p, platform in enumerate(cl.get_platforms()):
            for d, other in enumerate(platform.get_devices()):
                if other == device:
                    return f"{p}:{d}"
    except cl.Error:
        pass
    return None


def compile_helpers(device: cl.Device) -> bool:
    """Whether helper processes share the compiling for ``device``: where its
    compiler builds one program at a time per process, unless
    ``GPUGI_COMPILE_HELPERS=0`` (e.g. a farm job held to its cores)."""
    return (device.platform.name.strip() in _SERIAL_COMPILER_PLATFORMS
            and os.environ.get("GPUGI_COMPILE_HELPERS", "1") != "0")


def build_cost(name: str) -> int:
    """A rough measure of how long program ``name`` takes to build (see
    _KERNEL_COST), to balance shares of builds between processes."""
    source = load_source(name)
    return _PROGRAM_COST + len(source) + _KERNEL_COST * len(_KERNEL_RE.findall(source))


def shares(wanted: list[tuple[str, dict]], count: int) -> list[list[tuple[str, dict]]]:
    """``wanted`` split into ``count`` shares of about equal build cost:
    the costliest first, each to the share with the least so far (the
    first share stays with the caller)."""
    costs = {name: build_cost(name) for name in {name for name, _ in wanted}}
    out, totals = [[] for _ in range(count)], [0] * count
    for item in sorted(wanted, key=lambda item: -costs[item[0]]):
        least = totals.index(min(totals))
        out[least].append(item)
        totals[least] += costs[item[0]]
    return out


def start_helper(module: str, spec: str, data: bytes) -> subprocess.Popen | None:
    """``python -m module spec`` with ``data`` on its standard input, in
    this process's interpreter, finding this gpu_core first (an extension
    loads it from inside its own folder), then this process's path; None
    when it cannot start."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(INCLUDE_ROOT.parent), *(p for p in sys.path if p)]))
    try:
        process = subprocess.Popen([sys.executable, "-m", module, spec], env=env, stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except (OSError, ValueError):
        return None
    try:
        process.stdin.write(data)
        process.stdin.close()
    except OSError:  # it ended at once
        process.kill()
        process.wait()
        return None
    return process


def stop_helper(process: subprocess.Popen | None) -> None:
    """End a helper process of start_helper (what it has not done is not needed)."""
    if process is not None:
        if process.poll() is None:
            process.kill()
        process.wait()


def build_options(defines: dict | None = None) -> tuple[str, ...]:
    """Compiler options: the standard, the shared constants, then ``defines``."""
    merged = {**constants.defines(), **(defines or {})}
    return _OPTIONS + tuple(f"-D{key}={value}" for key, value in sorted(merged.items()))


@dataclass
class BuildRecord:
    """How one program was obtained: compiled now or loaded from the disk cache."""

    name: str
    from_cache: bool
    milliseconds: float


class Programs:
    """The built programs of one device, each built once (thread-safe)."""

    def __init__(self, context: cl.Context, device: cl.Device):
        self.context = context
        self.device = device
        self._separate = device.platform.name.strip() in _SEPARATE_PLATFORMS
        self._inline_builtins = device.platform.name.strip() in _INLINE_BUILTINS_PLATFORMS
        self._native_trig = device.platform.name.strip() in _NATIVE_TRIG_PLATFORMS
        self._exact_division = bool(device.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT)
        self._simulator = any(name in device.platform.name.lower() for name in _SIMULATOR_PLATFORMS)
        self.builds: list[BuildRecord] = []
        self._wait = 0.0  # seconds to wait for a program to reach the disk cache instead of compiling it
        self._programs: dict[tuple, cl.Program] = {}
        self._pending: dict[tuple, threading.Event] = {}
        self._lock = threading.Lock()

    def get(self, name: str, defines: dict | None = None) -> cl.Program:
        """The built program ``name`` with ``defines``; a second thread asking
        while the first builds it waits for that build."""
        name = built_as(name, defines)
        key = (name, build_options(defines))
        with self._lock:
            if key in self._programs:
                return self._programs[key]
            waiting = self._pending.get(key)
            if waiting is None:
                self._pending[key] = threading.Event()
        if waiting is not None:
            waiting.wait()
            with self._lock:
                if key in self._programs:
                    return self._programs[key]
            return self.get(name, defines)  # the other build failed: raise its error here
        try:
            program = self._build(name, key[1])
            with self._lock:
                self._programs[key] = program
        finally:
            with self._lock:
                self._pending.pop(key).set()
        return program

    def wait_for_cache(self, seconds: float) -> None:
        """From now on take every program from the disk cache, waiting up to
        ``seconds`` for another process to store it, and compile none (a
        DeviceError when it does not come)."""
        self._wait = float(seconds)

    def missing(self, wanted: list[tuple[str, dict]]) -> list[tuple[str, dict]]:
        """The (name, defines) of ``wanted`` neither built here nor in the disk
        cache, bundled programs named by their bundle (built_as)."""
        return [(n, d) for n, d in self.unbuilt(wanted) if not self._cache_entry(n, build_options(d))[2].is_file()]

    def unbuilt(self, wanted: list[tuple[str, dict]]) -> list[tuple[str, dict]]:
        """The (name, defines) of ``wanted`` not built in this process yet,
        bundled programs named by their bundle (built_as)."""
        return [(n, d) for n, d in _distinct(wanted) if (n, build_options(d)) not in self._programs]

    def build_all(self, wanted: list[tuple[str, dict]], progress: Callable[[int, int], None] | None = None,
                  busy: int = 0) -> None:
        """Build every (name, defines) in ``wanted`` that is not built yet, in
        parallel threads, and a share of those missing from the disk cache in
        helper processes where the compiler takes one at a time (on the
        cores not taken by this process and ``busy`` others);
        ``progress(compiled, to_compile)`` after each one that is not in the
        disk cache (loading one reports nothing)."""
        todo = self.unbuilt(wanted)
        if not todo:
            return
        missing = self.missing(todo)
        compiled = 0

        def count() -> None:
            nonlocal compiled
            if progress is not None:
                compiled += 1
                progress(compiled, len(missing))

        helpers, given = self._share(missing, busy)
        try:
            mine = [(t, t in missing) for t in todo if t not in given]
            # one at a time where the compiler is not safe to run on two threads (Oclgrind's crashes)
            workers = 1 if self._simulator else max(1, min(len(mine), os.cpu_count() or 1))
            with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gpugi-build") as pool:
                for future, (_, absent) in zip([pool.submit(self.get, n, d) for (n, d), _ in mine], mine):
                    future.result()
                    if absent:
                        count()
            self._await(helpers, given, count)
        finally:
            for process in helpers:
                stop_helper(process)
        for name, defines in given:
            self.get(name, defines)  # from the disk cache, or compiled here where a helper failed

    def _share(self, missing: list[tuple[str, dict]], busy: int) -> tuple[list[subprocess.Popen], list[tuple[str, dict]]]:
        """Helper processes compiling a share of ``missing`` into the disk
        cache, where the compiler builds one program at a time per process,
        on the cores left beside this process and ``busy`` others: the
        processes, and the programs given to them (none elsewhere, or when a
        process cannot start)."""
        count = min(_MAX_HELPERS, (os.cpu_count() or 1) - 1 - busy, len(missing) - 1)
        if not compile_helpers(self.device) or count < 1:
            return [], []
        spec = device_spec(self.device)
        if spec is None:
            return [], []
        processes, given = [], []
        for share in shares(missing, count + 1)[1:]:  # this process keeps the first
            process = start_helper("gpu_core.device.prebuild", spec, json.dumps(share).encode())
            if process is not None:  # else this process compiles them
                processes.append(process)
                given += share
        return processes, given

    def _await(self, processes: list[subprocess.Popen], given: list[tuple[str, dict]], count: Callable[[], None]) -> None:
        """Wait for the helpers, counting their programs as they reach the
        disk cache, at most _HELPER_WAIT seconds."""
        paths = {self._cache_entry(n, build_options(d))[2] for n, d in given}
        deadline = time.monotonic() + _HELPER_WAIT
        while paths:
            done = {path for path in paths if path.is_file()}
            for _ in done:
                count()
            paths -= done
            if all(p.poll() is not None for p in processes) or time.monotonic() > deadline:
                return
            time.sleep(0.02)

    def _cache_entry(self, name: str, options: tuple[str, ...]) -> tuple[str, tuple[str, ...], Path]:
        """The source of ``name``, the options it is built with on this
        device, and its file in the disk cache."""
        source = load_source(name)
        if self._inline_builtins:
            source = with_inline_builtins(source)
        if self._exact_division:
            options = options + (_EXACT_DIVISION,)
        if self._separate:
            options = options + (_SEPARATE_MARK,)
        if self._native_trig:
            options = options + (_NATIVE_TRIG_MARK,)
        if self._simulator:
            options = options + (_SIMULATOR_MARK,)
        dev = self.device
        ident = "\n".join([_CACHE_FORMAT, source, " ".join(options), dev.platform.name, dev.platform.version,
                           dev.name, dev.driver_version, cl.VERSION_TEXT, os.environ.get("POCL_WORK_GROUP_SPECIALIZATION", ""),
                           os.environ.get("CL_CONFIG_USE_VECTORIZER", "")])
        digest = hashlib.sha256(ident.encode()).hexdigest()
        return source, options, kernel_cache_dir() / f"{Path(name).stem}-{digest[:32]}.bin"

    def _build(self, name: str, options: tuple[str, ...]) -> cl.Program:
        start = time.perf_counter()
        source, options, path = self._cache_entry(name, options)
        program = None if self._simulator else self._load_cached(path, options)
        deadline = time.monotonic() + self._wait
        while program is None and self._wait and time.monotonic() < deadline:
            time.sleep(0.05)
            program = self._load_cached(path, options)
        if program is None and self._wait:
            raise DeviceError(f"program {name!r} did not reach the disk cache in {self._wait:g} s")
        from_cache = program is not None
        if program is None:
            program, cached = self._compile(name, source, options)
            if not self._simulator:
                self._store_cached(path, cached)
        with self._lock:
            self.builds.append(BuildRecord(name, from_cache, (time.perf_counter() - start) * 1e3))
        return program

    def _load_cached(self, path: Path, options) -> cl.Program | None:
        try:
            binary = path.read_bytes()
        except OSError:
            return None
        try:
            program = cl.Program(self.context, [self.device], [binary])
            if self._separate:
                return cl.link_program(self.context, [program])
            return program.build(options=list(options))
        except (cl.Error, ValueError):
            return None

    def _compile(self, name: str, source: str, options) -> tuple[cl.Program, cl.Program]:
        """The built program, and what the disk cache keeps of it (the
        program itself, or its compiled object)."""
        try:
            if not self._separate:
                program = cl.Program(self.context, source).build(options=list(options))
                return program, program
            with warnings.catch_warnings():  # pyopencl's own cache does not apply to a compiled object
                warnings.simplefilter("ignore", UserWarning)
                compiled = cl.Program(self.context, source).compile(options=list(options))
            return cl.link_program(self.context, [compiled]), compiled
        except cl.RuntimeError as err:
            hint = _UNKNOWN_CPU_HINT if "unknown target CPU" in str(err) else ""
            raise DeviceError(f"OpenCL program {name!r} failed to build on {self.device.name.strip()}:\n{err}{hint}") from err

    @staticmethod
    def _store_cached(path: Path, program: cl.Program) -> None:
        try:
            binary = program.get_info(cl.program_info.BINARIES)[0]
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
            tmp.write_bytes(bytes(binary))
            tmp.replace(path)
        except (OSError, cl.Error):
            pass  # a read-only cache only costs a recompile next time
