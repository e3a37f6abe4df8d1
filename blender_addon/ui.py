"""Panels: the engine's own settings, and the stock panels that apply to it."""

from __future__ import annotations

import bpy

ENGINE_ID = "GPUGI"

# Stock panels marked for the built-in render engine that describe something
# this engine does not read.
EXCLUDED_PANELS = {
    "VIEWLAYER_PT_filter",
    "VIEWLAYER_PT_layer_passes",
    "RENDER_PT_freestyle",
    "MATERIAL_PT_freestyle_line",
}

# EEVEE panels whose settings this engine reads the same way (each defines
# its own COMPAT_ENGINES set, so adding to it touches no other panel).
EXTRA_PANELS = (
    "EEVEE_MATERIAL_PT_context_material",  # material slots
    "EEVEE_MATERIAL_PT_surface",  # the surface node inputs
    "MATERIAL_PT_preview",
    "EEVEE_WORLD_PT_surface",
    "DATA_PT_EEVEE_light",  # colour, temperature, power, exposure, normalize, shape and size
)


class GpuGiRenderPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"

    @classmethod
    def poll(cls, context):
        return context.engine == ENGINE_ID


class GPUGI_PT_sampling(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        settings = context.scene.gpugi
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(settings, "samples", text="Render")
        col.prop(settings, "preview_samples", text="Viewport")
        layout.prop(settings, "seed")
        layout.prop(settings, "clamp")


class GPUGI_PT_light_paths(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Light Paths"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(context.scene.gpugi, "max_bounces", text="Specular")
        col.prop(context.scene.gpugi, "diffuse_bounces", text="Diffuse")


class GPUGI_PT_film(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Film"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.scene.render, "film_transparent", text="Transparent")


class GPUGI_PT_device(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Device"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.scene.gpugi, "device")


PANELS = (GPUGI_PT_sampling, GPUGI_PT_light_paths, GPUGI_PT_film, GPUGI_PT_device)


def stock_panels() -> list:
    """Stock panels that apply: those marked for the built-in render engine
    (minus the excluded ones) and the extra EEVEE panels that exist."""
    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        compat = getattr(panel, "COMPAT_ENGINES", None)
        if compat is not None and "BLENDER_RENDER" in compat and panel.__name__ not in EXCLUDED_PANELS:
            panels.append(panel)
    for name in EXTRA_PANELS:
        panel = getattr(bpy.types, name, None)
        if panel is not None and "COMPAT_ENGINES" in vars(panel):
            panels.append(panel)
    return panels


def register():
    for panel in PANELS:
        bpy.utils.register_class(panel)
    for panel in stock_panels():
        panel.COMPAT_ENGINES.add(ENGINE_ID)


def unregister():
    for panel in stock_panels():
        panel.COMPAT_ENGINES.discard(ENGINE_ID)
    for panel in reversed(PANELS):
        bpy.utils.unregister_class(panel)
