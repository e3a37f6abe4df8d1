"""Render settings stored in the .blend at scene.gpugi (and view_layer.gpugi)."""

from __future__ import annotations

import bpy

from gpu_core.settings import PRESETS, RenderSettings

_GI_ONLY = " (GI mode only)"

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


class GpuGiSceneSettings(bpy.types.PropertyGroup):
    """The engine's settings; each one changes what the renderer does."""

    device: bpy.props.StringProperty(
        name="OpenCL Device",
        description="Platform name part or index, optionally ':device' (e.g. 'NVIDIA', '1:0', 'gpu'); "
        "empty uses GPUGI_DEVICE or the CPU device",
        default="",
    )
    mode: bpy.props.EnumProperty(
        name="Mode",
        description="How indirect light is computed",
        items=(
            ("REFERENCE", "Reference", "Path tracer: the ground truth, noisy until many samples; indirect light "
             "needs Diffuse Bounces above 0"),
            ("GI", "GI", "Photon maps, irradiance cache and final gathering: direct light and mirrors/glass "
             "traced, indirect light and caustics from photons; smooth at few samples"),
        ),
        default="GI",
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
    samples: bpy.props.IntProperty(
        name="Samples", description="Camera paths per pixel (final render)", default=16, min=1, soft_max=1024,
        update=_mark_custom,
    )
    preview_samples: bpy.props.IntProperty(
        name="Viewport Samples", description="Camera paths per pixel in the viewport", default=4, min=1, soft_max=256
    )
    max_bounces: bpy.props.IntProperty(
        name="Specular Bounces", description="Mirror and glass bounces followed from the camera", default=8, min=0,
        max=64, update=_mark_custom,
    )
    diffuse_bounces: bpy.props.IntProperty(
        name="Diffuse Bounces",
        description="Diffuse bounces path-traced after the first diffuse hit (0 = direct light only)",
        default=RenderSettings.diffuse_bounces,
        min=0,
        max=64,
        update=_mark_custom,
    )
    clamp: bpy.props.FloatProperty(
        name="Clamp", description="Largest radiance of one sample (0 disables clamping)", default=0.0, min=0.0
    )
    seed: bpy.props.IntProperty(name="Seed", description="Noise pattern", default=0, min=0)

    # global-illumination knobs (issue 5): stored now, consumed by the GI mode later
    global_photons: bpy.props.IntProperty(
        name="Global Photons", description="Photons emitted for the global photon map" + _GI_ONLY,
        default=RenderSettings.global_photons, min=0, soft_max=5_000_000, update=_mark_custom,
    )
    caustic_photons: bpy.props.IntProperty(
        name="Caustic Photons", description="Photons emitted for the caustic photon map (traced only when "
        "the scene has mirrors or glass)" + _GI_ONLY,
        default=RenderSettings.caustic_photons, min=0, soft_max=5_000_000, update=_mark_custom,
    )
    photon_k: bpy.props.IntProperty(
        name="Photons per Estimate", description="Nearest photons in one density estimate (k)" + _GI_ONLY,
        default=RenderSettings.photon_k, min=1, soft_max=500, update=_mark_custom,
    )
    cache_seeds: bpy.props.IntProperty(
        name="Cache Points", description="Irradiance-cache sample points (k-means seeds)" + _GI_ONLY,
        default=RenderSettings.cache_seeds, min=1, soft_max=20_000, update=_mark_custom,
    )
    gather_rays: bpy.props.IntProperty(
        name="Gather Rays", description="Final-gather rays per cache point" + _GI_ONLY,
        default=RenderSettings.gather_rays, min=1, soft_max=2048, update=_mark_custom,
    )
    cut_delta: bpy.props.FloatProperty(
        name="Cut Threshold",
        description="Illumination cut: a node is replaced by its children where its approximate irradiance "
        "differs from the exact one by more than this fraction of it (delta)" + _GI_ONLY,
        default=RenderSettings.cut_delta, min=0.0, soft_max=4.0, update=_mark_custom,
    )
    cache_alpha: bpy.props.FloatProperty(
        name="Cache Distance Weight",
        description="Weight of distance against normal change when grouping cache points (alpha, times the "
        "scene's largest side)" + _GI_ONLY,
        default=RenderSettings.cache_alpha, min=0.0, soft_max=10.0, update=_mark_custom,
    )

    def render_settings(self, preview: bool = False, transparent: bool = False) -> RenderSettings:
        """gpu_core settings for a final render, or for the viewport/previews."""
        return RenderSettings(
            mode=self.mode.lower(),
            samples=self.preview_samples if preview else self.samples,
            max_bounces=self.max_bounces,
            diffuse_bounces=self.diffuse_bounces,
            clamp=self.clamp,
            seed=self.seed,
            transparent_background=transparent,
            global_photons=self.global_photons,
            caustic_photons=self.caustic_photons,
            photon_k=self.photon_k,
            cache_seeds=self.cache_seeds,
            gather_rays=self.gather_rays,
            cut_delta=self.cut_delta,
            cache_alpha=self.cache_alpha,
        )


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
