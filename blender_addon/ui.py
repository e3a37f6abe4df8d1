"""Panels: the engine's own settings, and the stock panels that apply to it."""

from __future__ import annotations

import bpy

ENGINE_ID = "GPUGI"

# stock panels that do not describe anything this engine reads
_EXCLUDED_PANELS = {
    "VIEWLAYER_PT_filter",
    "VIEWLAYER_PT_layer_passes",
    "RENDER_PT_freestyle",
    "RENDER_PT_simplify",
}


class GPUGI_PT_sampling(bpy.types.Panel):
    bl_label = "GPU GI"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        settings = context.scene.gpugi
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "samples")
        layout.prop(settings, "preview_samples")
        layout.prop(settings, "max_bounces")
        layout.prop(settings, "clamp")
        layout.prop(settings, "seed")
        layout.prop(settings, "device")


def stock_panels():
    """Stock panels marked for the built-in engine, minus the excluded ones."""
    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        compat = getattr(panel, "COMPAT_ENGINES", None)
        if compat is not None and "BLENDER_RENDER" in compat and panel.__name__ not in _EXCLUDED_PANELS:
            panels.append(panel)
    return panels


def register():
    bpy.utils.register_class(GPUGI_PT_sampling)
    for panel in stock_panels():
        panel.COMPAT_ENGINES.add(ENGINE_ID)


def unregister():
    for panel in stock_panels():
        panel.COMPAT_ENGINES.discard(ENGINE_ID)
    bpy.utils.unregister_class(GPUGI_PT_sampling)
