"""Render settings stored in the .blend at scene.gpugi (and view_layer.gpugi).

Every knob is made from its declaration in gpu_core's RenderSettings (label,
description, range, default: gpu_core/settings.py); only what the add-on
alone has (the OpenCL device string, the preset choice, a pass toggle) is
declared here.
"""

from __future__ import annotations

import bpy

from gpu_core.settings import PRESETS, RenderSettings, knobs

_PRESET_KEYS = set(PRESETS["draft"])
# samples of a material preview when Viewport Samples is 0 (the viewport then refines until stopped)
MATERIAL_PREVIEW_SAMPLES = 64

# True while a preset writes its values, so those writes keep the preset
_applying_preset = False


def _apply_preset(settings, _context) -> None:
    """Write the chosen preset's values into the settings it covers."""
    global _applying_preset
    if settings.preset == "CUSTOM":
        return
    _applying_preset = True
    try:
        for key, value in PRESETS[settings.preset.lower()].items():
            setattr(settings, key, value)
    finally:
        _applying_preset = False


def _mark_custom(settings, _context) -> None:
    """An edit of a preset-covered setting makes the preset Custom."""
    if not _applying_preset and settings.preset != "CUSTOM":
        settings.preset = "CUSTOM"


def _preset_item(key: str, label: str, purpose: str) -> tuple[str, str, str]:
    """An enum item whose tooltip lists the preset's main values."""
    p = PRESETS[key.lower()]
    return (key, label, f"{purpose.capitalize()}: {p['samples']} samples, {p['diffuse_bounces']} diffuse bounces, "
            f"{p['global_photons']:,}/{p['caustic_photons']:,} global/caustic photons, {p['gather_rays']} gather rays")


def _refresh_passes(settings, _context) -> None:
    """A pass toggle changed: let Blender ask the engine for its passes again."""
    for view_layer in settings.id_data.view_layers:
        if view_layer.gpugi.as_pointer() == settings.as_pointer():
            view_layer.update_render_passes()


def knob_property(f):
    """The bpy property of one RenderSettings knob, from its metadata."""
    meta = f.metadata
    common = dict(name=meta["label"], description=meta["description"])
    if f.name in _PRESET_KEYS:
        common["update"] = _mark_custom
    if meta["items"]:
        items = [(value.upper(), label, description) for value, label, description in meta["items"]]
        return bpy.props.EnumProperty(items=items, default=meta["blender_default"].upper(), **common)
    if isinstance(f.default, bool):
        return bpy.props.BoolProperty(default=meta["blender_default"], **common)
    bounds = {key: meta[name] for key, name in (("min", "minimum"), ("max", "maximum"), ("soft_max", "soft_max"))
              if meta[name] is not None}
    kind = bpy.props.FloatProperty if isinstance(f.default, float) else bpy.props.IntProperty
    return kind(default=meta["blender_default"], **bounds, **common)


def knob_value(settings, name: str):
    """A knob's value as gpu_core reads it (choices in lower case)."""
    value = getattr(settings, name)
    return value.lower() if isinstance(value, str) else value


class GpuGiSceneSettings(bpy.types.PropertyGroup):
    """The engine's settings; each one changes what the renderer does. The
    knobs are added from gpu_core's declarations at registration."""

    device: bpy.props.StringProperty(
        name="OpenCL Device",
        description="Platform name part or index, optionally ':device' (e.g. 'NVIDIA', '1:0', 'gpu'); "
        "empty uses the device chosen in the add-on's preferences, else GPUGI_DEVICE or the CPU device",
        default="",
    )
    preset: bpy.props.EnumProperty(
        name="Preset",
        description="Sets samples, bounces and the GI knobs to one step of the speed/accuracy ladder; "
        "editing one of them makes it Custom",
        items=(
            _preset_item("DRAFT", "Draft", "fastest"),
            _preset_item("PREVIEW", "Preview", "quick look"),
            _preset_item("FINAL", "Final", "final frames"),
            _preset_item("REFERENCE", "Reference", "ground truth"),
            ("CUSTOM", "Custom", "The values as set by hand"),
        ),
        default="CUSTOM",
        update=_apply_preset,
    )

    def render_settings(self, preview: bool = False, transparent: bool = False) -> RenderSettings:
        """gpu_core settings for a final render, or for the viewport/previews."""
        values = {f.name: knob_value(self, f.name) for f in knobs()}
        if preview:
            # 0 Viewport Samples (until stopped) gives a material preview MATERIAL_PREVIEW_SAMPLES
            values["samples"] = values["preview_samples"] or MATERIAL_PREVIEW_SAMPLES
            values["denoise"] = values["preview_denoise"]
        return RenderSettings(**values, transparent_background=transparent)


for _knob in knobs():
    GpuGiSceneSettings.__annotations__[_knob.name] = knob_property(_knob)


class GpuGiViewLayerSettings(bpy.types.PropertyGroup):
    """Pass toggles Blender's view layer has no property for."""

    use_pass_caustics: bpy.props.BoolProperty(
        name="Caustics",
        description="Light that reached a diffuse surface through mirrors or glass (a part of the light passes, "
        "not added to them again)",
        default=False,
        update=_refresh_passes,
    )


def register():
    bpy.utils.register_class(GpuGiSceneSettings)
    bpy.utils.register_class(GpuGiViewLayerSettings)
    bpy.types.Scene.gpugi = bpy.props.PointerProperty(type=GpuGiSceneSettings)
    bpy.types.ViewLayer.gpugi = bpy.props.PointerProperty(type=GpuGiViewLayerSettings)


def unregister():
    del bpy.types.ViewLayer.gpugi
    del bpy.types.Scene.gpugi
    bpy.utils.unregister_class(GpuGiViewLayerSettings)
    bpy.utils.unregister_class(GpuGiSceneSettings)
