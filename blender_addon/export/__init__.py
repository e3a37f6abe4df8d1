"""Depsgraph to gpu_core Scene: meshes, instances, materials, lights, world, camera.

Reads only evaluated data and never writes to the user's scene.
"""

from __future__ import annotations

from gpu_core.errors import GpuGiError
from gpu_core.scene import Scene

from .camera import CameraError, scene_camera
from .sync import SceneSync


class ExportError(GpuGiError):
    """The scene cannot be exported (e.g. no camera); the message says why."""


def export_scene(depsgraph, camera=None, camera_object=None, should_stop=None) -> Scene:
    """A gpu_core Scene of everything ``depsgraph`` renders (a sync with nothing kept).

    ``camera`` (a gpu_core Camera) replaces the render camera, as the viewport
    does; otherwise ``camera_object`` or the scene's camera is used.
    ``should_stop`` is polled every few thousand instances; when it answers
    True the export ends early and the caller is expected to cancel.
    """
    warnings: list[str] = []
    if camera is None:
        camera = _render_camera(depsgraph, camera_object or depsgraph.scene.camera, warnings)
    scene, _ = SceneSync().export(depsgraph, camera, should_stop=should_stop)
    if warnings:
        scene.warnings[:0] = [w for w in warnings if w not in scene.warnings]
    return scene


def _render_camera(depsgraph, camera_object, warnings: list[str]):
    """The gpu_core camera of the render camera object, or ExportError."""
    if camera_object is None:
        raise ExportError("the scene has no active camera; add one or set Scene > Camera")
    if camera_object.type != "CAMERA":
        raise ExportError(f"the active camera '{camera_object.name}' is not a camera object")
    try:
        return scene_camera(depsgraph.scene, camera_object.evaluated_get(depsgraph), warnings)
    except CameraError as err:
        raise ExportError(str(err)) from err
