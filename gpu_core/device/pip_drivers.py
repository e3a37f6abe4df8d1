"""OpenCL drivers installed by pip, made visible to the OpenCL loader.

pyopencl's loader finds PoCL (bundled with it) and the drivers listed in
the system's vendors folder (``/etc/OpenCL/vendors``). PoCL 3.0 compiles
with LLVM 14, which does not know CPUs newer than it (an AMD Zen 5, say):
there it names the CPU "generic" and refuses every program ("unknown target
CPU 'generic'"). Intel's CPU runtime for OpenCL (``intel-opencl-rt`` on
PyPI, which runs on AMD CPUs too) is then the CPU device; pip puts its
library in the environment's ``lib/``, which neither the loader nor the
library path knows. ``register()``, called before the loader's first
call, loads that library with the libraries beside it that it needs, and
points the loader at a vendors folder holding the system's driver files
and one for it. A user's own ``OCL_ICD_VENDORS`` is left as it is (one
that register() set, inherited by a process it starts, is not the user's).

It must run before ``bpy`` is imported: Blender's module carries an older
TBB library of the same name, which the runtime cannot use, while Blender
runs with the newer one.

Intel's work-item vectorizer is turned off (``CL_CONFIG_USE_VECTORIZER``,
unless the user set it; other drivers ignore it): with it on, a batch of
kNN searches wrote work-items' results to one another's rows.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import site
import sys
import tempfile
import threading
from pathlib import Path

INTEL_CPU_LIBRARY = "libintelocl.so"
SYSTEM_VENDORS = "/etc/OpenCL/vendors"
MARK = "GPUGI_PIP_VENDORS"  # the vendors folder register() set, told apart from a user's

_LOCK = threading.Lock()
_DONE = False
problem = ""  # why an installed runtime could not be loaded, for error messages


def register(cache_root: Path) -> None:
    """Make a pip-installed Intel CPU runtime one of the loader's drivers
    (once per process, before the loader lists its platforms); its vendors
    folder is kept under ``cache_root``. Does nothing where the runtime is
    not installed, cannot be loaded, or the user set ``OCL_ICD_VENDORS``."""
    global _DONE, problem
    with _LOCK:
        if _DONE:
            return
        _DONE = True
        os.environ.setdefault("CL_CONFIG_USE_VECTORIZER", "False")
        vendors = os.environ.get("OCL_ICD_VENDORS")
        if (vendors and vendors != os.environ.get(MARK)) or not sys.platform.startswith("linux"):
            return  # the user's choice (a process of ours started by another inherits ours)
        library = intel_cpu_library()
        if library is None:
            return
        problem = _load(library, set())
        if problem:
            return
        folder = _vendors_folder(cache_root, library)
        if folder is not None:
            os.environ["OCL_ICD_VENDORS"] = os.environ[MARK] = str(folder)


def intel_cpu_library() -> Path | None:
    """Intel's CPU runtime library installed by pip in this environment (or
    the user's site), if any."""
    for prefix in (sys.prefix, site.getuserbase()):
        path = Path(prefix) / "lib" / INTEL_CPU_LIBRARY
        if path.is_file():
            return path
    return None


def _load(path: Path, tried: set[str]) -> str:
    """Load ``path`` into the process, first loading each library it names
    that is missing from the library path but lies beside it; the loader's
    complaint where it cannot (in Blender, whose older TBB library is
    loaded first: undefined symbols), else ""."""
    while True:
        try:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
            return ""
        except OSError as err:
            missing = re.match(r"([^:\s]+): cannot open shared object file", str(err))
            beside = path.parent / missing.group(1) if missing else None
            if beside is None or missing.group(1) in tried or not beside.is_file():
                return str(err)
            tried.add(missing.group(1))
            failed = _load(beside, tried)
            if failed:
                return failed


def _vendors_folder(cache_root: Path, library: Path) -> Path | None:
    """A vendors folder holding a copy of each of the system's driver files
    and one naming ``library``; one folder per content, made atomically."""
    system = Path(os.environ.get("OPENCL_VENDOR_PATH") or SYSTEM_VENDORS)
    files = {}
    try:
        for icd in sorted(system.glob("*.icd")):
            files[icd.name] = icd.read_text()
    except OSError:
        pass  # an unreadable system folder leaves its drivers out
    files["gpugi-intel-cpu.icd"] = f"{library}\n"
    digest = hashlib.sha256(repr(sorted(files.items())).encode()).hexdigest()[:16]
    folder = cache_root / "opencl-vendors" / digest
    if folder.is_dir():
        return folder
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=folder.parent))
        for name, text in files.items():
            (staging / name).write_text(text)
        try:
            staging.rename(folder)
        except OSError:  # another process made it first
            for item in staging.iterdir():
                item.unlink()
            staging.rmdir()
    except OSError:
        return None
    return folder if folder.is_dir() else None
