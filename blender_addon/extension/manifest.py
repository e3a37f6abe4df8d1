"""blender_manifest.toml of one zip: the add-on's own manifest with the zip's
platform, Blender range, wheels and permissions."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

from .targets import Target

# Why the extension writes files (Blender shows this before enabling it).
FILES_PERMISSION = "Caches compiled OpenCL kernels in its user folder"


def manifest_for(source: Path, target: Target, wheel_names: list[str]) -> dict:
    """The manifest of ``target``'s zip, keys in the source manifest's order."""
    with open(source, "rb") as f:
        manifest = tomllib.load(f)
    first, first_unsupported = target.blender_range
    manifest["blender_version_min"] = first
    if first_unsupported:
        manifest["blender_version_max"] = first_unsupported
    else:
        manifest.pop("blender_version_max", None)
    manifest["platforms"] = [target.platform]
    manifest["wheels"] = [f"./wheels/{name}" for name in wheel_names]
    manifest["permissions"] = {"files": FILES_PERMISSION}
    return manifest


def to_toml(manifest: dict) -> str:
    """TOML text of a manifest: strings and lists of strings at the top, then one level of tables."""
    lines = [f"{key} = {_value(value)}" for key, value in manifest.items() if not isinstance(value, dict)]
    for key, table in manifest.items():
        if isinstance(table, dict):
            lines += ["", f"[{key}]", *(f"{k} = {_value(v)}" for k, v in table.items())]
    return "\n".join(lines) + "\n"


def _value(value) -> str:
    # JSON's string escapes are valid TOML basic strings
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_value(item) for item in value) + "]"
    raise TypeError(f"manifest value {value!r} is neither a string nor a list of strings")
