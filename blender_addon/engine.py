"""The RenderEngine Blender calls for F12, `blender -b`, previews and the viewport."""

from __future__ import annotations

import bpy

from .display import draw_pixels, prepare_pixels
from .final import render_final
from .viewport import ViewportSession


class GpuGiRenderEngine(bpy.types.RenderEngine):
    bl_idname = "GPUGI"
    bl_label = "GPU GI"
    bl_use_preview = True
    bl_use_shading_nodes_custom = False
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # Material Preview mode stays EEVEE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._viewport: ViewportSession | None = None

    def __del__(self):
        try:
            if self._viewport is not None:
                self._viewport.stop()
        except (ReferenceError, AttributeError):
            pass  # the engine struct is already gone

    # -- final render -----------------------------------------------------------

    def render(self, depsgraph):
        render_final(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        if renderlayer.use_pass_z:
            self.register_pass(scene, renderlayer, "Depth", 1, "Z", "VALUE")
        if renderlayer.use_pass_normal:
            self.register_pass(scene, renderlayer, "Normal", 3, "XYZ", "VECTOR")

    # -- viewport ---------------------------------------------------------------

    def view_update(self, context, depsgraph):
        if self._viewport is None:
            self._viewport = ViewportSession(self.tag_redraw)
        try:
            self._viewport.update_scene(depsgraph, context)
        except Exception as err:  # never a traceback in the viewport
            self.report({"ERROR"}, f"GPU GI: {err}")

    def view_draw(self, context, depsgraph):
        session = self._viewport
        if session is None:
            return
        session.update_view(context)
        if session.error:
            self.report({"ERROR"}, f"GPU GI: {session.error}")
            session.error = None
        image = session.latest()
        if image is None:
            return
        region = context.region
        draw_pixels(self, depsgraph.scene, prepare_pixels(image, region.width, region.height))
