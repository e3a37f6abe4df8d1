"""Panels: the engine's own settings, and the stock panels that apply to it."""

from __future__ import annotations

import bpy

from gpu_core.settings import knobs

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


def draw_knobs(layout, settings, panel: str) -> None:
    """The knobs gpu_core's settings place in ``panel``, under their short labels."""
    col = layout.column(align=True)
    for knob in knobs():
        if knob.metadata["panel"] == panel:
            col.prop(settings, knob.name, text=knob.metadata["text"])


class GPUGI_PT_mode(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Mode"

    def draw(self, context):
        settings = context.scene.gpugi
        layout = self.layout
        layout.use_property_split = True
        draw_knobs(layout, settings, "mode")
        layout.prop(settings, "preset")


class GPUGI_PT_sampling(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        self.layout.use_property_split = True
        draw_knobs(self.layout, context.scene.gpugi, "sampling")


class GPUGI_PT_light_paths(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Light Paths"

    def draw(self, context):
        self.layout.use_property_split = True
        draw_knobs(self.layout, context.scene.gpugi, "light_paths")


class GPUGI_PT_global_illumination(GpuGiRenderPanel, bpy.types.Panel):
    bl_label = "Global Illumination"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings = context.scene.gpugi
        layout = self.layout
        layout.use_property_split = True
        layout.active = settings.mode == "GI"
        draw_knobs(layout, settings, "gi")


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
        # Blender's own setting: final renders keep the scene, kd-tree and photons between frames
        layout.prop(context.scene.render, "use_persistent_data", text="Persistent Data")


class GPUGI_PT_passes(bpy.types.Panel):
    """The passes this engine writes, under View Layer Properties."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "view_layer"
    bl_label = "Passes"

    @classmethod
    def poll(cls, context):
        return context.engine == ENGINE_ID

    def draw(self, context):
        view_layer = context.view_layer
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="Data", align=True)
        col.prop(view_layer, "use_pass_combined")
        col.prop(view_layer, "use_pass_z")
        col.prop(view_layer, "use_pass_normal")
        if hasattr(view_layer, "cycles"):  # the toggle belongs to the Cycles add-on
            col.prop(view_layer.cycles, "denoising_store_passes", text="Denoising Data")
        col = layout.column(heading="Light", align=True)
        for kind in ("diffuse", "glossy", "transmission"):
            row = col.row(heading=kind.capitalize(), align=True)
            row.prop(view_layer, f"use_pass_{kind}_direct", text="Direct", toggle=True)
            row.prop(view_layer, f"use_pass_{kind}_indirect", text="Indirect", toggle=True)
        col.prop(view_layer, "use_pass_emit", text="Emission")
        col.prop(view_layer, "use_pass_environment")
        col.prop(view_layer.gpugi, "use_pass_caustics")


PANELS = (GPUGI_PT_mode, GPUGI_PT_sampling, GPUGI_PT_light_paths, GPUGI_PT_global_illumination, GPUGI_PT_film,
          GPUGI_PT_device, GPUGI_PT_passes)


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
