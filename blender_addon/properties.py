"""Render settings stored in the .blend at scene.gpugi."""

from __future__ import annotations

import bpy

from gpu_core.settings import RenderSettings


class GpuGiSceneSettings(bpy.types.PropertyGroup):
    """The engine's settings; each one changes what the renderer does."""

    device: bpy.props.StringProperty(
        name="OpenCL Device",
        description="Platform name part or index, optionally ':device' (e.g. 'NVIDIA', '1:0', 'gpu'); "
        "empty uses GPUGI_DEVICE or the CPU device",
        default="",
    )
    samples: bpy.props.IntProperty(
        name="Samples", description="Camera paths per pixel (final render)", default=16, min=1, soft_max=1024
    )
    preview_samples: bpy.props.IntProperty(
        name="Viewport Samples", description="Camera paths per pixel in the viewport", default=4, min=1, soft_max=256
    )
    max_bounces: bpy.props.IntProperty(
        name="Specular Bounces", description="Mirror and glass bounces followed from the camera", default=8, min=0, max=64
    )
    diffuse_bounces: bpy.props.IntProperty(
        name="Diffuse Bounces",
        description="Diffuse bounces path-traced after the first diffuse hit (0 = direct light only)",
        default=RenderSettings.diffuse_bounces,
        min=0,
        max=64,
    )
    clamp: bpy.props.FloatProperty(
        name="Clamp", description="Largest radiance of one sample (0 disables clamping)", default=0.0, min=0.0
    )
    seed: bpy.props.IntProperty(name="Seed", description="Noise pattern", default=0, min=0)

    def render_settings(self, preview: bool = False, transparent: bool = False) -> RenderSettings:
        """gpu_core settings for a final render, or for the viewport/previews."""
        return RenderSettings(
            samples=self.preview_samples if preview else self.samples,
            max_bounces=self.max_bounces,
            diffuse_bounces=self.diffuse_bounces,
            clamp=self.clamp,
            seed=self.seed,
            transparent_background=transparent,
        )


def register():
    bpy.utils.register_class(GpuGiSceneSettings)
    bpy.types.Scene.gpugi = bpy.props.PointerProperty(type=GpuGiSceneSettings)


def unregister():
    del bpy.types.Scene.gpugi
    bpy.utils.unregister_class(GpuGiSceneSettings)
