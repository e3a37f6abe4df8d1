"""One extension zip: the add-on's files, gpu_core with its kernels, the
generated manifest and the wheels, all at the zip's root."""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

MANIFEST = "blender_manifest.toml"

# Add-on files that serve the repository only: the command line
# (python -m blender_addon) and this build tool.
REPO_ONLY = ("__main__.py", "cli.py", "extension")

# What gpu_core needs at run time: its modules, the OpenCL sources and the
# microfacet albedo tables.
CORE_SUFFIXES = (".py", ".cl", ".h", ".npz")


def addon_files(addon_dir: Path):
    """(path, name in the zip) of every add-on file but caches, repository tools and the source manifest."""
    for path in _walk(addon_dir):
        rel = path.relative_to(addon_dir)
        if rel.parts[0] not in REPO_ONLY and rel.as_posix() != MANIFEST:
            yield path, rel.as_posix()


def core_files(core_dir: Path):
    """(path, name in the zip) of every module and kernel file of the gpu_core package tree."""
    for path in _walk(core_dir):
        if path.suffix in CORE_SUFFIXES:
            yield path, f"gpu_core/{path.relative_to(core_dir).as_posix()}"


def _walk(folder: Path):
    """Files below ``folder``, without byte-code caches and hidden files."""
    for parent, dirs, files in os.walk(folder):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not d.startswith("."))
        for name in sorted(files):
            if not name.endswith(".pyc") and not name.startswith("."):
                yield Path(parent) / name


def write_zip(path: Path, files, manifest_text: str, wheels: list[Path]) -> None:
    """Write the zip through a temporary file, so a failed build leaves no half zip."""
    partial = path.with_name(path.name + ".partial")
    try:
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr(MANIFEST, manifest_text)
            for source, name in files:
                archive.write(source, name)
            for wheel in wheels:  # wheels are zips already: stored as they are
                archive.write(wheel, f"wheels/{wheel.name}", compress_type=zipfile.ZIP_STORED)
        partial.replace(path)
    finally:
        partial.unlink(missing_ok=True)
