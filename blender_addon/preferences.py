"""The add-on's preferences: the OpenCL devices found with their versions,
the default device, and clearing the kernel cache."""

from __future__ import annotations

import bpy

from . import cache_dirs
from .opencl_devices import survey

AUTOMATIC = "AUTO"

# Blender needs the enum items kept alive while it shows them.
_items: list[tuple[str, str, str, int]] = []


def device_spec(scene) -> str | None:
    """The device a render of ``scene`` asks gpu_core for: the scene's own
    setting, else the preferences' choice, else None (gpu_core's default)."""
    if scene.gpugi.device:
        return scene.gpugi.device
    addon = bpy.context.preferences.addons.get(__package__)
    return (addon.preferences.device or None) if addon else None


def _device_items(_prefs=None, _context=None):
    """Automatic, then every device found; an item's number is its place in the list."""
    if not _items:
        _items.append((AUTOMATIC, "Automatic", "The CPU device, or the GPUGI_DEVICE environment variable", 0))
        for number, device in enumerate(survey().devices, start=1):
            tooltip = f"{device.kind}, {device.opencl}, driver {device.driver}"
            _items.append((device.spec, device.label, tooltip, number))
    return _items


# The choice is stored as the device spec string (saved with the preferences);
# a device no longer present shows as Automatic and draw() names it.
def _get_choice(prefs) -> int:
    specs = [item[0] for item in _device_items()]
    return specs.index(prefs.device) if prefs.device in specs else 0


def _set_choice(prefs, value: int) -> None:
    spec = _device_items()[value][0]
    prefs.device = "" if spec == AUTOMATIC else spec


class GPUGI_OT_clear_kernel_cache(bpy.types.Operator):
    """Delete the OpenCL programs GPU GI compiled and cached on disk; the next render compiles them again"""

    bl_idname = "gpugi.clear_kernel_cache"
    bl_label = "Clear Kernel Cache"

    def execute(self, context):
        try:
            removed = cache_dirs.clear()
        except Exception as err:  # never a traceback into Blender
            self.report({"ERROR"}, f"GPU GI: could not clear the kernel cache: {err}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"GPU GI: {removed}")
        return {"FINISHED"}


class GpuGiPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    device: bpy.props.StringProperty(
        name="Default Device",
        description="Device spec renders use when the scene names none ('P:D'; empty: automatic)",
        default="",
    )
    device_choice: bpy.props.EnumProperty(
        name="Default Device",
        description="The OpenCL device renders use when the scene's own Device field is empty",
        items=_device_items,
        get=_get_choice,
        set=_set_choice,
    )

    def draw(self, context):
        layout = self.layout
        found = survey()
        if found.problem:
            layout.label(text=found.problem, icon="ERROR")
        for device in found.devices:
            col = layout.column(align=True)
            col.label(text=f"{device.label}  ({device.kind})")
            col.label(text=f"{device.opencl}, driver {device.driver}")
        layout.prop(self, "device_choice")
        if self.device and self.device not in [item[0] for item in _device_items()]:
            layout.label(text=f"Device {self.device} is not present; renders fall back to the CPU device", icon="ERROR")
        layout.operator(GPUGI_OT_clear_kernel_cache.bl_idname, icon="TRASH")


CLASSES = (GPUGI_OT_clear_kernel_cache, GpuGiPreferences)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
