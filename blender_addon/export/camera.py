"""The render camera (or a viewport view) to a gpu_core Camera."""

from __future__ import annotations

import numpy as np

from gpu_core.errors import GpuGiError
from gpu_core.scene import (
    CAMERA_ORTHO,
    CAMERA_PERSP,
    FILTER_BLACKMAN_HARRIS,
    FILTER_BOX,
    FILTER_GAUSSIAN,
    Camera,
)

from .inverse import affine_inverse

_FILTER_KINDS = {"BOX": FILTER_BOX, "GAUSSIAN": FILTER_GAUSSIAN, "BLACKMAN_HARRIS": FILTER_BLACKMAN_HARRIS}


class CameraError(GpuGiError):
    """The camera cannot be rendered by this engine; the message says why."""


def render_size(render) -> tuple[int, int]:
    """Image size in pixels after the resolution percentage, as Blender computes it."""
    percentage = int(render.resolution_percentage)
    return (
        max(1, int(render.resolution_x) * percentage // 100),
        max(1, int(render.resolution_y) * percentage // 100),
    )


def border_pixels(render, width: int, height: int) -> tuple[int, int, int, int] | None:
    """Pixel window (x0, y0, x1, y1) of the render border, or None without one.

    Blender multiplies the float border by the size and truncates, in single
    precision; the render result it allocates has exactly that size.
    """
    if not render.use_border:
        return None
    f32 = np.float32
    x0 = int(f32(render.border_min_x) * f32(width))
    x1 = int(f32(render.border_max_x) * f32(width))
    y0 = int(f32(render.border_min_y) * f32(height))
    y1 = int(f32(render.border_max_y) * f32(height))
    x0, y0 = min(max(x0, 0), width - 1), min(max(y0, 0), height - 1)
    x1, y1 = max(min(x1, width), x0 + 1), max(min(y1, height), y0 + 1)
    if (x0, y0, x1, y1) == (0, 0, width, height):
        return None
    return (x0, y0, x1, y1)


def window_from_frame(frame, ortho: bool) -> tuple[float, float, float, float]:
    """Image rectangle (x0, x1, y0, y1) from Blender's camera frame corners:
    on the plane z = -1 for perspective, in scene units for orthographic."""
    corners = np.array([tuple(v) for v in frame], np.float64)
    if not ortho:
        corners = corners[:, :2] / -corners[:, 2:3]
    return (
        float(corners[:, 0].min()),
        float(corners[:, 0].max()),
        float(corners[:, 1].min()),
        float(corners[:, 1].max()),
    )


def pixel_filter(scene) -> tuple[int, float]:
    """The film's pixel filter (FILTER_*, width in pixels): Cycles' Pixel
    Filter where the Cycles add-on's settings exist, so a scene set up for
    Cycles renders alike, else Blackman-Harris of Blender's Filter Size."""
    cycles = getattr(scene, "cycles", None)
    if cycles is not None and hasattr(cycles, "pixel_filter_type"):
        return _FILTER_KINDS.get(cycles.pixel_filter_type, FILTER_BLACKMAN_HARRIS), float(cycles.filter_width)
    return FILTER_BLACKMAN_HARRIS, float(scene.render.filter_size)


def scene_camera(scene, camera_obj, warnings: list[str]) -> Camera:
    """The scene camera at the render resolution, with border and clipping.

    The window comes from Blender's own camera frame, so sensor fit, lens
    shift and pixel aspect are applied exactly as Blender applies them.
    """
    render = scene.render
    data = camera_obj.data
    if data.type == "PANO":
        raise CameraError("panoramic cameras are not supported; switch the camera to Perspective or Orthographic")
    if data.dof.use_dof:
        warnings.append("camera depth of field is not supported; rendered in focus")
    if render.use_motion_blur:
        warnings.append("motion blur is not supported; rendered without it")
    width, height = render_size(render)
    ortho = data.type == "ORTHO"
    film_filter = pixel_filter(scene)
    return Camera(
        matrix=np.array(camera_obj.matrix_world, np.float64),
        window=window_from_frame(data.view_frame(scene=scene), ortho),
        width=width,
        height=height,
        kind=CAMERA_ORTHO if ortho else CAMERA_PERSP,
        clip_start=float(data.clip_start),
        clip_end=float(data.clip_end),
        border=border_pixels(render, width, height),
        filter_kind=film_filter[0],
        filter_width=film_filter[1],
    )


def window_from_projection(projection, ortho: bool) -> tuple[float, float, float, float]:
    """Image rectangle (x0, x1, y0, y1) of an OpenGL-style projection matrix,
    on the plane z = -1 for perspective, in view units for orthographic."""
    p = np.asarray(projection, np.float64)
    if not (np.isfinite(p).all() and abs(p[0, 0]) > 0 and abs(p[1, 1]) > 0):
        raise CameraError("the view's projection is degenerate (zero-size view?)")
    if ortho:
        # x_ndc = P00 x + P03
        sx, ox, sy, oy = p[0, 0], p[0, 3], p[1, 1], p[1, 3]
    else:
        # at z = -1: x_ndc = P00 x - P02
        sx, ox, sy, oy = p[0, 0], -p[0, 2], p[1, 1], -p[1, 2]
    return ((-1 - ox) / sx, (1 - ox) / sx, (-1 - oy) / sy, (1 - oy) / sy)


def clip_from_projection(projection, ortho: bool) -> tuple[float, float]:
    """(near, far) distances along the view axis of a projection matrix."""
    p = np.asarray(projection, np.float64)
    a, b = p[2, 2], p[2, 3]
    if ortho:
        return (b + 1.0) / a, (b - 1.0) / a
    return b / (a - 1.0), b / (a + 1.0)


def view_camera(view_matrix, projection, width: int, height: int, ortho: bool,
                film_filter: tuple[int, float] = (FILTER_BOX, 1.0)) -> Camera:
    """A camera for a 3D viewport from its view and projection matrices,
    with ``film_filter`` (pixel_filter's kind and width) as its pixel filter.

    An orthographic view clips from behind its own origin; the camera is
    moved back so that its clipping range starts at zero.
    """
    matrix = affine_inverse(view_matrix)
    near, far = clip_from_projection(projection, ortho)
    if ortho and near < 0.0:
        back = matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
        matrix[:3, 3] += back * -near
        near, far = 0.0, far - near
    return Camera(
        matrix=matrix,
        window=window_from_projection(projection, ortho),
        width=max(1, int(width)),
        height=max(1, int(height)),
        kind=CAMERA_ORTHO if ortho else CAMERA_PERSP,
        clip_start=max(float(near), 0.0),
        clip_end=float(far),
        filter_kind=film_filter[0],
        filter_width=film_filter[1],
    )
