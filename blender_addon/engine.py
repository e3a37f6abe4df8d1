"""The RenderEngine Blender calls for F12, `blender -b`, previews and the viewport.

It stays thin: final renders go through final.py, the Rendered viewport
through a ViewportSession (viewport.py) and a ViewportDrawer (display.py).
"""

from __future__ import annotations

import bpy

from gpu_core.errors import DeviceError, GpuGiError

from .display import ViewportDrawer
from .export.sync import SceneSync, read_updates
from .final import render_final
from .opencl_devices import survey
from .passes import enabled_passes
from .viewport import ViewportSession, view_state, view_update_session, warm_edit_kernels


class GpuGiRenderEngine(bpy.types.RenderEngine):
    bl_idname = "GPUGI"
    bl_label = "GPU GI"
    bl_use_preview = True
    bl_use_shading_nodes_custom = False  # users keep Cycles' shader nodes (Principled BSDF)
    bl_use_postprocess = True
    bl_use_eevee_viewport = True  # Material Preview shading stays EEVEE

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._viewport: ViewportSession | None = None
        self._sync: SceneSync | None = None
        self._drawer = ViewportDrawer()
        self._reported_error: str | None = None

    def __del__(self):
        try:
            session = self._viewport
        except (ReferenceError, AttributeError):
            return  # the struct is gone: the worker stops at its next redraw request
        if session is not None:
            session.stop()

    # -- final render -----------------------------------------------------------

    def render(self, depsgraph):
        render_final(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        """Declare the passes the view layer's toggles ask for (the compositor's sockets)."""
        for spec in enabled_passes(renderlayer):
            self.register_pass(scene, renderlayer, spec.name, len(spec.channels), spec.channels, spec.kind)

    # -- viewport ---------------------------------------------------------------

    def view_update(self, context, depsgraph):
        """An edit (or the first draw): sync what it changed on this (main)
        thread, render in the worker."""
        try:
            if self._viewport is None:
                self._viewport = ViewportSession(self.tag_redraw, warm_up=warm_edit_kernels)
            if survey().problem:
                raise DeviceError(survey().problem)
            first = self._sync is None
            if first:
                self._sync = SceneSync()
            view_update_session(self._viewport, self._sync, context, depsgraph, self.get_preview_pixel_size,
                                None if first else read_updates(depsgraph))
        except Exception as err:  # never a traceback in the viewport
            if not isinstance(err, GpuGiError):
                self._sync = None  # an unexpected failure: the next edit exports everything again
            self._report_viewport_error(err)

    def view_draw(self, context, depsgraph):
        """Follow view changes and draw the newest image; cheap by design."""
        session = self._viewport
        if session is None:
            return
        try:
            session.update_view(view_state(context))
            image, version = session.latest()
            if image is not None:
                region = context.region
                self._drawer.draw(self, depsgraph.scene, image, version, region.width, region.height)
            self.update_stats("", session.status)
            if session.error and session.error != self._reported_error:
                self._reported_error = session.error
                self.report({"ERROR"}, f"GPU GI: {session.error}")
        except Exception as err:
            self._report_viewport_error(err)

    def _report_viewport_error(self, err: Exception) -> None:
        if isinstance(err, GpuGiError):
            message = str(err)
        else:
            message = f"internal error ({type(err).__name__}): {err}"
        self.update_stats("", f"GPU GI | error: {message}")
        self.report({"ERROR"}, f"GPU GI: {message}")
