"""OpenCL device choice and kernel programs built once, cached on disk.

The device is chosen by a spec string (argument, or the ``GPUGI_DEVICE``
environment variable):

* ``""`` or ``"cpu"``: the first CPU device (PoCL from PyPI, the default);
* ``"gpu"``: the first GPU device of any platform;
* ``"P"`` or ``"P:D"``: platform whose name contains ``P`` (case-insensitive)
  or whose index is ``P``, and its device number ``D`` (default 0).

When the asked-for device is missing, the CPU device is used and
``Device.fallback_message`` says why, so the add-on can show it.
"""

from __future__ import annotations

import hashlib
import os
import re
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyopencl as cl

from .errors import DeviceError

KERNEL_DIR = Path(__file__).resolve().parent / "kernels"
_INCLUDE_RE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$', re.MULTILINE)
_CACHE_FORMAT = "1"


def kernel_cache_dir() -> Path:
    """Folder of cached program binaries (``GPUGI_KERNEL_CACHE`` overrides it)."""
    env = os.environ.get("GPUGI_KERNEL_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "gpugi" / "kernels"


def load_source(name: str) -> str:
    """Source of ``kernels/<name>`` with every ``#include "x.h"`` inlined once.

    Inlining makes the cache key cover the headers too.
    """
    seen: set[str] = set()

    def expand(file_name: str) -> str:
        if file_name in seen:
            return ""
        seen.add(file_name)
        path = KERNEL_DIR / file_name
        if not path.is_file():
            raise DeviceError(f"kernel source {file_name!r} is missing from {KERNEL_DIR}")
        text = path.read_text()
        return _INCLUDE_RE.sub(lambda m: expand(m.group(1)), text)

    return expand(name)


@dataclass
class BuildRecord:
    """How one program was obtained: compiled now or loaded from the disk cache."""

    name: str
    from_cache: bool
    milliseconds: float


@dataclass
class Device:
    """An OpenCL context and queue on one device, with its built programs."""

    context: cl.Context
    queue: cl.CommandQueue
    device: cl.Device
    fallback_message: str = ""
    builds: list[BuildRecord] = field(default_factory=list)
    _programs: dict = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def is_cpu(self) -> bool:
        return bool(self.device.type & cl.device_type.CPU)

    @property
    def max_alloc_bytes(self) -> int:
        return int(self.device.max_mem_alloc_size)

    @property
    def global_mem_bytes(self) -> int:
        return int(self.device.global_mem_size)

    def program(self, name: str, defines: dict | None = None) -> cl.Program:
        """The built program of ``kernels/<name>`` with ``-D`` defines.

        Built once per process; across processes the binary comes from the
        on-disk cache, keyed by the full source, options, device and driver.
        """
        options = ["-cl-std=CL1.2", "-cl-mad-enable"]
        for key, value in sorted((defines or {}).items()):
            options.append(f"-D{key}={value}")
        key = (name, tuple(options))
        with self._lock:
            if key not in self._programs:
                self._programs[key] = self._build(name, options)
            return self._programs[key]

    def _build(self, name: str, options: list[str]) -> cl.Program:
        start = time.perf_counter()
        source = load_source(name)
        ident = "\n".join(
            [
                _CACHE_FORMAT,
                source,
                " ".join(options),
                self.device.platform.name,
                self.device.platform.version,
                self.device.name,
                self.device.driver_version,
                cl.VERSION_TEXT,
            ]
        )
        digest = hashlib.sha256(ident.encode()).hexdigest()
        path = kernel_cache_dir() / f"{Path(name).stem}-{digest[:32]}.bin"
        program = self._load_cached(path, options)
        from_cache = program is not None
        if program is None:
            program = self._compile(name, source, options)
            self._store_cached(path, program)
        self.builds.append(BuildRecord(name, from_cache, (time.perf_counter() - start) * 1e3))
        return program

    def _load_cached(self, path: Path, options: list[str]) -> cl.Program | None:
        try:
            binary = path.read_bytes()
        except OSError:
            return None
        try:
            program = cl.Program(self.context, [self.device], [binary])
            return program.build(options=options)
        except (cl.Error, ValueError):
            return None

    def _compile(self, name: str, source: str, options: list[str]) -> cl.Program:
        try:
            return cl.Program(self.context, source).build(options=options)
        except cl.RuntimeError as err:
            raise DeviceError(f"OpenCL program {name!r} failed to build on {self.name}:\n{err}") from err

    @staticmethod
    def _store_cached(path: Path, program: cl.Program) -> None:
        try:
            binary = program.get_info(cl.program_info.BINARIES)[0]
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(bytes(binary))
            tmp.replace(path)
        except (OSError, cl.Error):
            pass  # a read-only cache only costs a recompile next time

    def buffer(self, array: np.ndarray, writable: bool = False) -> cl.Buffer:
        """A device buffer holding ``array`` (never zero-sized)."""
        array = np.ascontiguousarray(array)
        flags = cl.mem_flags.READ_WRITE if writable else cl.mem_flags.READ_ONLY
        if array.nbytes == 0:
            return cl.Buffer(self.context, flags, size=16)
        return cl.Buffer(self.context, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)

    def empty(self, nbytes: int) -> cl.Buffer:
        """An uninitialised read-write buffer of at least 16 bytes."""
        return cl.Buffer(self.context, cl.mem_flags.READ_WRITE, size=max(int(nbytes), 16))


def _all_devices() -> list[tuple[int, cl.Platform, list[cl.Device]]]:
    out = []
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return out
    for index, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            devices = []
        if devices:  # platforms without devices (e.g. rusticl with none) are skipped
            out.append((index, platform, devices))
    return out


def list_devices() -> list[str]:
    """``"P:D  platform / device"`` lines for every device, for UI and errors."""
    return [
        f"{index}:{number}  {platform.name.strip()} / {dev.name.strip()}"
        for index, platform, devices in _all_devices()
        for number, dev in enumerate(devices)
    ]


def _match(spec: str, found) -> cl.Device | None:
    spec = spec.strip()
    lowered = spec.lower()
    if lowered in ("", "cpu", "gpu"):
        wanted = cl.device_type.GPU if lowered == "gpu" else cl.device_type.CPU
        for _, _, devices in found:
            for dev in devices:
                if dev.type & wanted:
                    return dev
        return None
    platform_part, _, device_part = spec.partition(":")
    try:
        device_number = int(device_part) if device_part else 0
    except ValueError:
        return None
    for index, platform, devices in found:
        if platform_part.isdigit():
            hit = int(platform_part) == index
        else:
            hit = platform_part.lower() in platform.name.lower()
        if hit and 0 <= device_number < len(devices):
            return devices[device_number]
    return None


_DEVICES: dict[str, Device] = {}
_DEVICES_LOCK = threading.Lock()


def get_device(spec: str | None = None) -> Device:
    """The device for ``spec`` (or ``GPUGI_DEVICE``), created once per process."""
    if spec is None:
        spec = os.environ.get("GPUGI_DEVICE", "")
    with _DEVICES_LOCK:
        if spec not in _DEVICES:
            _DEVICES[spec] = _create(spec)
        return _DEVICES[spec]


def _create(spec: str) -> Device:
    found = _all_devices()
    chosen = _match(spec, found)
    message = ""
    if chosen is None:
        chosen = _match("cpu", found)
        available = "; ".join(list_devices()) or "none"
        if chosen is None:
            raise DeviceError(
                "No OpenCL device found. Install the CPU device with "
                "'pip install pocl-binary-distribution' or a GPU vendor's OpenCL driver. "
                f"Devices seen: {available}."
            )
        message = (
            f"OpenCL device {spec!r} not found (devices: {available}); "
            f"using {chosen.platform.name.strip()} / {chosen.name.strip()} instead."
        )
    try:
        context = cl.Context([chosen])
        queue = cl.CommandQueue(context)
    except cl.Error as err:
        raise DeviceError(f"Could not open OpenCL device {chosen.name.strip()}: {err}") from err
    return Device(context=context, queue=queue, device=chosen, fallback_message=message)
