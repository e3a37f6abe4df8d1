"""The add-on's preferences: the OpenCL devices with their versions, the
default device, clearing the kernel cache, and one clear line when there is
no OpenCL device at all."""

from __future__ import annotations

import pyopencl as cl
import pytest

from blender_addon import cache_dirs, preferences
from blender_addon.opencl_devices import survey


class RecordingLayout:
    """Enough of UILayout for the preferences' draw(): records labels, properties and operators."""

    def __init__(self):
        self.labels: list[tuple[str, str]] = []
        self.props: list[str] = []
        self.operators: list[str] = []

    def column(self, **kwargs):
        return self

    def label(self, text="", icon="NONE"):
        self.labels.append((text, icon))

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, name
        self.props.append(name)

    def operator(self, idname, **kwargs):
        self.operators.append(idname)


@pytest.fixture
def prefs(bpy_module):
    """The add-on's preferences, as Blender keeps them for an enabled add-on."""
    addons = bpy_module.context.preferences.addons
    addon = addons.new()
    addon.module = "blender_addon"
    yield addon.preferences
    addons.remove(addon)


@pytest.fixture
def no_opencl(monkeypatch):
    """pyopencl as on a computer with no OpenCL driver: listing platforms fails."""

    def no_platform():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", no_platform)
    monkeypatch.setattr(preferences, "_items", [])
    survey.cache_clear()
    yield
    survey.cache_clear()


class PreferencesPanel:
    """The preferences as draw() sees them: their properties, and a layout."""

    def __init__(self, prefs, layout):
        self._prefs, self.layout = prefs, layout

    def __getattr__(self, name):
        return getattr(self._prefs, name)


def draw(prefs) -> RecordingLayout:
    layout = RecordingLayout()
    type(prefs).draw(PreferencesPanel(prefs, layout), None)
    return layout


def test_preferences_list_each_device_with_its_opencl_and_driver_versions(prefs):
    from gpu_core.device import list_devices

    devices = survey().devices
    assert devices and not survey().problem
    # numbered as gpu_core numbers them, so a choice is a spec gpu_core understands
    assert [device.label for device in devices] == list_devices()
    layout = draw(prefs)
    texts = [text for text, _ in layout.labels]
    for device in devices:
        assert any(text.startswith(device.label) for text in texts)
        assert f"{device.opencl}, driver {device.driver}" in texts
        assert device.opencl.startswith("OpenCL") and device.driver != "unknown"
    assert layout.props == ["device_choice"] and layout.operators == ["gpugi.clear_kernel_cache"]


def test_chosen_device_is_the_default_and_a_scenes_own_device_wins(prefs, bpy_empty):
    scene = bpy_empty.context.scene
    spec = survey().devices[0].spec
    prefs.device_choice = spec
    assert prefs.device == spec and prefs.device_choice == spec
    assert preferences.device_spec(scene) == spec
    scene.gpugi.device = "gpu"
    assert preferences.device_spec(scene) == "gpu"
    scene.gpugi.device = ""
    prefs.device_choice = preferences.AUTOMATIC
    assert prefs.device == "" and preferences.device_spec(scene) is None


def test_a_saved_device_that_is_gone_is_named_in_the_preferences(prefs):
    prefs.device = "7:3"
    assert prefs.device_choice == preferences.AUTOMATIC
    assert any("7:3" in text and icon == "ERROR" for text, icon in draw(prefs).labels)


def test_without_opencl_the_addon_enables_and_the_preferences_say_what_to_install(bpy_module, no_opencl, request):
    import blender_addon

    blender_addon.unregister()
    blender_addon.register()  # enabling touches no OpenCL device
    assert bpy_module.types.RenderEngine.bl_rna_get_subclass_py("GPUGI") is not None
    layout = draw(request.getfixturevalue("prefs"))
    errors = [text for text, icon in layout.labels if icon == "ERROR"]
    assert len(errors) == 1 and len(layout.labels) == 1
    assert errors[0].startswith("No OpenCL device found. Install") and "driver" in errors[0]
    assert "\n" not in errors[0]
    assert [item[0] for item in preferences._device_items()] == [preferences.AUTOMATIC]


def test_clear_kernel_cache_removes_cached_programs_and_keeps_other_files(bpy_module, monkeypatch, tmp_path):
    monkeypatch.setenv("GPUGI_KERNEL_CACHE", str(tmp_path))
    for name in ("render-0123.bin", "photon_trace-4567.bin", "gather-89ab.4242.tmp", "notes.txt"):
        (tmp_path / name).write_bytes(b"x" * 1000)
    assert cache_dirs.clear() == f"removed 3 files (0.0 MiB) from {tmp_path}"
    assert [path.name for path in tmp_path.iterdir()] == ["notes.txt"]
    (tmp_path / "render-0123.bin").write_bytes(b"x")
    assert bpy_module.ops.gpugi.clear_kernel_cache() == {"FINISHED"}
    assert [path.name for path in tmp_path.iterdir()] == ["notes.txt"]


def test_as_an_extension_caches_go_to_its_user_folder_unless_the_user_chose_one(bpy_module, monkeypatch, tmp_path):
    user_pocl = tmp_path / "my_pocl"
    monkeypatch.delenv("GPUGI_KERNEL_CACHE", raising=False)
    monkeypatch.setenv("POCL_CACHE_DIR", str(user_pocl))
    monkeypatch.setattr(bpy_module.utils, "extension_path_user",
                        lambda package, path="", create=False: str(tmp_path / package / path))
    cache_dirs.configure("blender_addon")  # a legacy add-on keeps gpu_core's default folder
    assert "GPUGI_KERNEL_CACHE" not in cache_dirs.os.environ
    cache_dirs.configure("bl_ext.user_default.gpugi")
    try:
        assert cache_dirs.os.environ["GPUGI_KERNEL_CACHE"] == str(tmp_path / "bl_ext.user_default.gpugi" / "kernels")
        assert cache_dirs.os.environ["POCL_CACHE_DIR"] == str(user_pocl)
        assert cache_dirs.kernel_cache_folder() == tmp_path / "bl_ext.user_default.gpugi" / "kernels"
        user_pocl.mkdir()
        (user_pocl / "kernel.so").write_bytes(b"x")
        assert "my_pocl" not in cache_dirs.clear()  # a PoCL folder the user chose is left alone
        assert (user_pocl / "kernel.so").exists()
    finally:
        cache_dirs.restore()
    assert "GPUGI_KERNEL_CACHE" not in cache_dirs.os.environ
    assert cache_dirs.os.environ["POCL_CACHE_DIR"] == str(user_pocl)
