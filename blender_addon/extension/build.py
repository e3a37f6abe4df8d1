"""``python -m blender_addon build-extension -o DIR``: one extension zip per
platform and Python ABI, named like ``gpugi-0.1.0-linux_x64-cp311.zip``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import BuildError
from .archive import MANIFEST, addon_files, core_files, write_zip
from .manifest import manifest_for, to_toml
from .targets import BLENDER_RANGES, WHEEL_PLATFORMS, Target, all_targets
from .wheels import NoWheel, fetch, pins_for

ROOT = Path(__file__).resolve().parents[2]
ADDON_DIR = ROOT / "blender_addon"
CORE_DIR = ROOT / "gpu_core"
REQUIREMENTS = ROOT / "requirements.txt"
DEFAULT_CACHE = ROOT / ".cache" / "extension-wheels"


def build_zip(target: Target, out_dir: Path, cache: Path = DEFAULT_CACHE) -> Path:
    """Build ``target``'s zip in ``out_dir`` and return its path."""
    wheels = [fetch(name, version, target, cache) for name, version in pins_for(target, REQUIREMENTS).items()]
    manifest = manifest_for(ADDON_DIR / MANIFEST, target, [wheel.name for wheel in wheels])
    path = out_dir / f"{manifest['id']}-{manifest['version']}-{target.tag}.zip"
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [*addon_files(ADDON_DIR), *core_files(CORE_DIR)]
    write_zip(path, files, to_toml(manifest), wheels)
    return path


def parse_args(argv):
    parser = argparse.ArgumentParser(
        prog="python -m blender_addon build-extension",
        description="Build the add-on as Blender extension zips with pyopencl's wheels bundled "
        "(downloaded from PyPI on the first build, then read from the cache).",
    )
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "out" / "extensions", help="folder of the zips")
    parser.add_argument("--platform", action="append", choices=list(WHEEL_PLATFORMS),
                        help="build for this platform only (repeatable; default: all)")
    parser.add_argument("--abi", action="append", choices=list(BLENDER_RANGES),
                        help="build for this Python ABI only (repeatable; default: all)")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="folder of downloaded wheels")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    built = 0
    for target in all_targets(args.platform, args.abi):
        try:
            path = build_zip(target, args.output, args.cache)
        except NoWheel as err:  # this platform and ABI pair has no build
            print(f"skipped {target.tag}: {err}")
            continue
        except BuildError as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
        built += 1
        print(f"{path}  {path.stat().st_size / 2**20:.1f} MiB")
    return 0 if built else 1
