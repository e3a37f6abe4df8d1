"""The wheels an extension bundles: pyopencl, PoCL, pyoidn and their
dependencies, pinned, downloaded unmodified from PyPI once and kept in a
cache folder."""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
from pathlib import Path

from . import BuildError
from .targets import Target

# Pinned in requirements.txt, as for a development set-up.
FROM_REQUIREMENTS = ("pyopencl", "pocl-binary-distribution", "pyoidn")

# The rest of their dependencies (from their wheels' Requires-Dist); numpy
# stays out: Blender ships it.
DEPENDENCY_PINS = {
    "pytools": "2026.1.1",
    "siphash24": "1.9",  # compiled: one wheel per platform and ABI
    "platformdirs": "4.14.7",
    "typing_extensions": "4.16.0",
    "cffi": "2.1.1",  # compiled
    "pycparser": "3.12",
}

# The CPU OpenCL device (PoCL) has wheels for Linux x64 only; elsewhere the
# GPU driver's OpenCL is the device.
CPU_RUNTIME = "pocl-binary-distribution"
CPU_RUNTIME_PLATFORMS = ("linux-x64",)

# Open Image Denoise has no wheel for macOS on arm64: there the Denoise
# setting says what is missing and the image stays as rendered.
DENOISER = "pyoidn"
DENOISER_PLATFORMS = ("linux-x64", "windows-x64")


def pins_for(target: Target, requirements: Path) -> dict[str, str]:
    """Package name -> exact version, for the wheels of ``target``'s zip."""
    pinned = _read_pins(requirements)
    missing = [name for name in FROM_REQUIREMENTS if name not in pinned]
    if missing:
        raise BuildError(f"{requirements} has no '==' pin for {', '.join(missing)}")
    pins = {name: pinned[name] for name in FROM_REQUIREMENTS} | DEPENDENCY_PINS
    if target.platform not in CPU_RUNTIME_PLATFORMS:
        del pins[CPU_RUNTIME]
    if target.platform not in DENOISER_PLATFORMS:
        for name in (DENOISER, "cffi", "pycparser"):
            del pins[name]
    return pins


def _read_pins(requirements: Path) -> dict[str, str]:
    pins = {}
    for line in requirements.read_text().splitlines():
        match = re.match(r"\s*([A-Za-z0-9_.-]+)\s*==\s*([^\s;#]+)", line)
        if match:
            pins[match.group(1).lower()] = match.group(2)
    return pins


class NoWheel(BuildError):
    """PyPI has no wheel of this version for the target's platform and ABI."""


def fetch(name: str, version: str, target: Target, cache: Path) -> Path:
    """The wheel of ``name==version`` for ``target``, downloaded into ``cache`` if not there yet."""
    folder = cache / target.tag
    found = _cached(folder, name, version)
    if found is None:
        _download(name, version, target, folder)
        found = _cached(folder, name, version)
    if found is None:
        raise BuildError(f"pip reported success but left no {name}=={version} wheel in {folder}")
    return found


def _cached(folder: Path, name: str, version: str) -> Path | None:
    """The wheel file of ``name==version`` in ``folder`` (wheel names normalise '-' and '.' to '_')."""
    prefix = f"{re.sub(r'[-_.]+', '_', name).lower()}-{version}-"
    hits = sorted(p for p in folder.glob("*.whl") if p.name.lower().startswith(prefix)) if folder.is_dir() else []
    return hits[0] if hits else None


def _download(name: str, version: str, target: Target, folder: Path) -> None:
    """``pip download`` exactly one binary wheel, without its dependencies (they are pinned here).

    The wheel lands in a temporary folder first and then moves into the
    cache, so an interrupted download never leaves a partial wheel there.
    """
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=".download-") as landing:
        command = [
            sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
            "--only-binary=:all:", "--no-deps",
            *(f"--platform={tag}" for tag in target.wheel_platforms),
            f"--python-version={target.python_version}", "--implementation=cp", f"--abi={target.abi}",
            "--dest", landing, f"{name}=={version}",
        ]
        done = subprocess.run(command, capture_output=True, text=True)
        for wheel in Path(landing).glob("*.whl"):
            wheel.replace(folder / wheel.name)
    if done.returncode == 0:
        return
    detail = (done.stderr.strip().splitlines() or ["pip failed"])[-1]
    if "No matching distribution" in done.stderr:
        raise NoWheel(f"PyPI has no {name}=={version} wheel for {target.platform} {target.abi}")
    raise BuildError(
        f"could not download {name}=={version} for {target.platform} {target.abi}: {detail}\n"
        f"The first build needs PyPI; later builds read the wheels from {folder.parent}."
    )
