"""Where compiled kernels are cached, and clearing them.

Two caches: GPU GI's own program binaries (gpu_core reads the folder from
GPUGI_KERNEL_CACHE) and PoCL's (POCL_CACHE_DIR). As an extension the add-on
keeps both in its user folder, which Blender removes on uninstall.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import bpy

KERNEL_CACHE = "GPUGI_KERNEL_CACHE"
POCL_CACHE = "POCL_CACHE_DIR"
_SUBFOLDERS = {KERNEL_CACHE: "kernels", POCL_CACHE: "pocl"}

# The variables this add-on set, and to what (a variable the user set is left alone).
_set_here: dict[str, str] = {}


def is_extension(package: str) -> bool:
    """True when Blender loaded the add-on as an extension (module ``bl_ext.<repo>.<id>``)."""
    return package.startswith("bl_ext.")


def configure(package: str) -> None:
    """As an extension, cache in the extension's user folder unless the user chose a folder.

    PoCL reads its variable when pyopencl first lists the platforms, so this
    runs at register time, before any device is opened.
    """
    if not is_extension(package):
        return
    for variable, subfolder in _SUBFOLDERS.items():
        if not os.environ.get(variable):
            path = bpy.utils.extension_path_user(package, path=subfolder, create=True)
            os.environ[variable] = path
            _set_here[variable] = path


def restore() -> None:
    """Unset what configure() set (the add-on is being disabled)."""
    for variable, path in _set_here.items():
        if os.environ.get(variable) == path:
            del os.environ[variable]
    _set_here.clear()


def kernel_cache_folder() -> Path:
    """GPU GI's program-binary folder, as gpu_core resolves it."""
    from gpu_core.device import kernel_cache_dir

    return Path(kernel_cache_dir())


def clear() -> str:
    """Delete the cached kernels; returns one line saying what was removed from where."""
    # gpu_core's binaries (and temporary files of an interrupted write): the
    # folder may be one the user chose, so nothing else in it is touched
    folder = kernel_cache_folder()
    removed = [_remove(folder, [p for p in _children(folder) if p.suffix in (".bin", ".tmp")])]
    # PoCL's cache only when this add-on chose its folder
    if POCL_CACHE in _set_here:
        folder = Path(_set_here[POCL_CACHE])
        removed.append(_remove(folder, _children(folder)))
    return "; ".join(removed)


def _children(folder: Path) -> list[Path]:
    return sorted(folder.iterdir()) if folder.is_dir() else []


def _remove(folder: Path, paths: list[Path]) -> str:
    """Delete ``paths`` (files or folders) and say how many files and bytes went."""
    files, size = 0, 0
    for path in paths:
        tree = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
        files += len(tree)
        size += sum(p.stat().st_size for p in tree)
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    return f"removed {files} files ({size / 2**20:.1f} MiB) from {folder}"
