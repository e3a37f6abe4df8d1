"""The extension zips: built from this repository, validated the way Blender
validates them, and the Linux one installed into a fresh Blender user folder
with Blender's own operators, rendered with, and uninstalled.

The first run downloads the wheels from PyPI into .cache/extension-wheels;
later runs read them from there (offline).
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from blender_addon.extension.build import build_zip
from blender_addon.extension.targets import Target
from conftest import ROOT

HERE = Path(__file__).resolve().parent
REPO = Path(ROOT)
BPY_DIR = Path(importlib.util.find_spec("bpy").submodule_search_locations[0])
SCRIPTS = next(BPY_DIR.glob("*/scripts"))
# What `blender --command extension validate` runs, with the tags Blender accepts
BLENDER_EXT = SCRIPTS / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
VALID_TAGS = SCRIPTS / "modules" / "_bpy_internal" / "extensions" / "tags.py"


@pytest.fixture(scope="module")
def linux_zip(tmp_path_factory) -> Path:
    return build_zip(Target("linux-x64", "cp311"), tmp_path_factory.mktemp("zips"))


def blender_validates(path: Path) -> None:
    done = subprocess.run([sys.executable, str(BLENDER_EXT), "validate", str(path), f"--valid-tags={VALID_TAGS}"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def read_manifest(path: Path) -> dict:
    with zipfile.ZipFile(path) as archive:
        return tomllib.loads(archive.read("blender_manifest.toml").decode())


def wheel_names(path: Path) -> list[str]:
    with zipfile.ZipFile(path) as archive:
        return sorted(name.removeprefix("wheels/") for name in archive.namelist() if name.startswith("wheels/"))


def test_linux_zip_passes_blenders_manifest_validation(linux_zip):
    blender_validates(linux_zip)


def test_linux_zip_holds_addon_gpu_core_kernels_and_its_wheels(linux_zip):
    with zipfile.ZipFile(linux_zip) as archive:
        names = set(archive.namelist())
    core = {
        "gpu_core/" + path.relative_to(REPO / "gpu_core").as_posix()
        for path in (REPO / "gpu_core").rglob("*")
        if path.suffix in (".py", ".cl", ".h") and "__pycache__" not in path.parts
    }
    assert {"__init__.py", "engine.py", "preferences.py", "export/mesh.py"} <= names
    assert any(name.endswith(".cl") for name in core) and core <= names
    repo_only = ("extension/", "cli.py", "__main__.py")
    assert not [name for name in names if "__pycache__" in name or name.startswith(repo_only)]
    manifest = read_manifest(linux_zip)
    assert linux_zip.name == f"gpugi-{manifest['version']}-linux_x64-cp311.zip"
    assert manifest["platforms"] == ["linux-x64"]
    assert (manifest["blender_version_min"], manifest["blender_version_max"]) == ("4.2.0", "5.1.0")
    assert manifest["permissions"]["files"]
    assert sorted(wheel.removeprefix("./wheels/") for wheel in manifest["wheels"]) == wheel_names(linux_zip)
    wheels = wheel_names(linux_zip)
    for package in ("pyopencl", "siphash24", "cffi"):
        assert [w for w in wheels if re.match(rf"{package}-[^-]+-cp311-cp311-manylinux\S*_x86_64\.whl", w)], package
    assert [w for w in wheels if w.startswith("pocl_binary_distribution-")]
    assert [w for w in wheels if w.startswith("pyoidn-")]  # the denoiser
    assert not [w for w in wheels if w.startswith("numpy")]  # Blender ships numpy


def test_bundled_wheels_carry_their_own_dependencies(linux_zip):
    # every Requires-Dist of every bundled wheel (Python 3.11, no extras) is bundled
    # in a version it accepts, or is numpy, which Blender ships
    bundled = {canonicalize_name(name.split("-")[0]): name.split("-")[1] for name in wheel_names(linux_zip)}
    required = []
    with zipfile.ZipFile(linux_zip) as outer:
        for name in wheel_names(linux_zip):
            with outer.open(f"wheels/{name}") as raw, zipfile.ZipFile(raw) as wheel:
                metadata = next(n for n in wheel.namelist() if n.endswith(".dist-info/METADATA"))
                for line in wheel.read(metadata).decode().splitlines():
                    if line.startswith("Requires-Dist:"):
                        requirement = Requirement(line.removeprefix("Requires-Dist:").strip())
                        if requirement.marker is None or requirement.marker.evaluate({"python_version": "3.11",
                                                                                      "extra": ""}):
                            required.append(requirement)
    assert {canonicalize_name(r.name) for r in required} - set(bundled) == {"numpy"}
    for requirement in required:
        version = bundled.get(canonicalize_name(requirement.name))
        assert version is None or requirement.specifier.contains(version), (requirement, version)


@pytest.fixture(scope="module")
def session(linux_zip, tmp_path_factory) -> dict:
    """What one Blender session saw that installed, used and uninstalled the Linux zip."""
    tmp = tmp_path_factory.mktemp("session")
    other_python_zip = build_zip(Target("linux-x64", "cp313"), tmp / "zips")
    # a Python that sees bpy and numpy only: pyopencl can come only from the extension's wheels
    site = tmp / "site"
    site.mkdir()
    numpy_dir = Path(importlib.util.find_spec("numpy").submodule_search_locations[0])
    for package in (BPY_DIR, numpy_dir, numpy_dir.with_name("numpy.libs")):
        if package.exists():
            (site / package.name).symlink_to(package)
    report = tmp / "session.json"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "blender_user"))
    for variable in ("GPUGI_KERNEL_CACHE", "POCL_CACHE_DIR", "GPUGI_DEVICE"):
        env.pop(variable, None)
    done = subprocess.run(
        [sys.executable, "-I", "-S", str(HERE / "extension_session.py"), str(site), str(linux_zip),
         str(other_python_zip), str(REPO / "blend_scenes" / "cornell_box.blend"), str(report)],
        env=env, capture_output=True, text=True, timeout=600,
    )
    assert done.returncode == 0 and report.exists(), done.stdout[-3000:] + done.stderr[-3000:]
    seen = json.loads(report.read_text())
    seen["stdout"] = done.stdout
    assert Path(seen["extensions"]).is_relative_to(tmp / "blender_user")
    return seen


@pytest.mark.slow
def test_blender_5_0_refuses_the_zip_for_python_3_13_with_a_message(session):
    assert not session["other_python_installed"]
    assert "minimum supported version (5.1.0)" in session["stdout"]


@pytest.mark.slow
def test_installed_extension_imports_its_own_gpu_core_and_bundled_pyopencl(session):
    extensions = Path(session["extensions"])
    assert session["install"] == ["FINISHED"] and session["enabled"], session
    assert Path(session["pyopencl"]).is_relative_to(extensions / ".local")
    assert Path(session["gpu_core"]).is_relative_to(extensions / "user_default" / "gpugi")
    # its preferences list the CPU device the Linux zip bundles
    assert session["preferences"] == "GpuGiPreferences"
    assert [label for label in session["devices"] if "Portable Computing Language" in label], session["devices"]


@pytest.mark.slow
def test_installed_extension_renders_and_caches_kernels_in_its_user_folder(session):
    if not session["cpu_compiles"]:
        pytest.skip("the bundled PoCL's compiler does not know this CPU and there is no other device")
    assert session["render_error"] == "" and session["render_warnings"] == []
    assert session["denoised"]  # by the bundled Open Image Denoise
    assert Path(session["pyoidn"]).is_relative_to(Path(session["extensions"]) / ".local")
    assert 32 <= session["asked_width"] <= 64
    assert session["image_shape"][1] == session["asked_width"] and session["image_shape"][2] == 4
    assert session["image_finite"] and session["image_mean_rgb"] > 0.02
    user_folder = Path(session["extensions"]) / ".user" / "user_default" / "gpugi"
    assert Path(session["kernel_cache"]) == user_folder / "kernels"
    assert Path(session["pocl_cache"]) == user_folder / "pocl"
    assert session["kernel_cache_files"] > 0 and session["pocl_cache_files"] > 0


@pytest.mark.slow
def test_installed_extension_on_a_cpu_its_pocl_cannot_compile_for_says_so_at_f12(session):
    if session["cpu_compiles"]:
        pytest.skip("the bundled PoCL compiles for this CPU")
    assert "does not know this CPU model" in session["render_error"], session["render_error"]
    assert "does not know this CPU model" in session["render_raised"]


@pytest.mark.slow
def test_uninstall_leaves_no_extension_files_user_data_or_wheels(session):
    assert session["uninstall"] == ["FINISHED"] and not session["enabled_after_uninstall"]
    assert session["left_in_repo"] == [] and session["left_in_user_data"] == []
    # Blender removes each wheel's recorded paths; the byte-code Python wrote for a
    # single-module wheel (typing_extensions.py) stays in the shared __pycache__,
    # orphaned: Python never imports a __pycache__ file without its source
    orphans = r"lib/python3\.11/site-packages/__pycache__/[^/]+\.cpython-311\.pyc"
    left = session["left_in_site_packages"]
    assert all(re.fullmatch(orphans, path) for path in left), left


@pytest.mark.slow
def test_windows_and_macos_zips_carry_driver_opencl_wheels_and_the_denoiser_where_it_has_one(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "blender_addon", "build-extension", "-o", str(tmp_path),
         "--platform", "windows-x64", "--platform", "macos-arm64"],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    platform_tags = {"windows_x64": r"win_amd64", "macos_arm64": r"macosx_\d+_\d+_arm64"}
    for platform, tag in platform_tags.items():
        for abi, blender_min in (("cp311", "4.2.0"), ("cp313", "5.1.0")):
            path = next(tmp_path.glob(f"gpugi-*-{platform}-{abi}.zip"))
            blender_validates(path)
            manifest = read_manifest(path)
            assert manifest["platforms"] == [platform.replace("_", "-")]
            assert manifest["blender_version_min"] == blender_min
            wheels = wheel_names(path)
            compiled = ("pyopencl", "siphash24") + (("cffi",) if platform == "windows_x64" else ())
            for package in compiled:
                wheel = rf"{package}-[^-]+-{abi}-{abi}-{tag}\.whl"
                assert [w for w in wheels if re.fullmatch(wheel, w)], (path, package)
            assert not [w for w in wheels if "pocl" in w or "manylinux" in w or "numpy" in w], wheels
            # Open Image Denoise has Windows wheels, none for macOS on arm64
            assert bool([w for w in wheels if w.startswith("pyoidn-")]) == (platform == "windows_x64"), wheels
