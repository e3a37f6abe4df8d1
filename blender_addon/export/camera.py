"""The render camera (or a viewport view) to a gpu_core Camera."""

from __future__ import annotations

import numpy as np

from gpu_core.scene import CAMERA_ORTHO, CAMERA_PERSP, Camera


def window_from_projection(projection, ortho: bool) -> tuple[float, float, float, float]:
    """Image rectangle (x0, x1, y0, y1) in camera space from a projection matrix:
    on the plane z = -1 for perspective, in scene units for orthographic."""
    p = np.asarray(projection, np.float64)
    if ortho:
        sx, ox, sy, oy = p[0, 0], p[0, 3], p[1, 1], p[1, 3]
    else:
        # x_ndc = (P00 x + P02 z) / -z: at z = -1, x = (x_ndc + P02) / P00
        sx, ox, sy, oy = p[0, 0], -p[0, 2], p[1, 1], -p[1, 2]
    return ((-1 - ox) / sx, (1 - ox) / sx, (-1 - oy) / sy, (1 - oy) / sy)


def render_size(render) -> tuple[int, int]:
    """Image size in pixels after the resolution percentage."""
    scale = render.resolution_percentage / 100.0
    return max(1, int(render.resolution_x * scale)), max(1, int(render.resolution_y * scale))


def border_pixels(render, width: int, height: int):
    """Pixel window (x0, y0, x1, y1) of the render border, or None."""
    if not render.use_border:
        return None
    x0 = int(round(render.border_min_x * width))
    x1 = int(round(render.border_max_x * width))
    y0 = int(round(render.border_min_y * height))
    y1 = int(round(render.border_max_y * height))
    x0, y0 = min(max(x0, 0), width - 1), min(max(y0, 0), height - 1)
    x1, y1 = max(min(x1, width), x0 + 1), max(min(y1, height), y0 + 1)
    return (x0, y0, x1, y1)


def scene_camera(depsgraph, camera_obj) -> Camera:
    """The scene camera at the render resolution, with border and clipping."""
    scene = depsgraph.scene
    render = scene.render
    width, height = render_size(render)
    data = camera_obj.data
    projection = camera_obj.calc_matrix_camera(depsgraph, x=width, y=height,
                                               scale_x=render.pixel_aspect_x, scale_y=render.pixel_aspect_y)
    ortho = data.type == "ORTHO"
    if data.type == "PANO":
        raise ValueError("panoramic cameras are not supported; switch the camera to Perspective or Orthographic")
    matrix = np.asarray(camera_obj.matrix_world, np.float64)
    return Camera(
        matrix=matrix,
        window=window_from_projection(projection, ortho),
        width=width,
        height=height,
        kind=CAMERA_ORTHO if ortho else CAMERA_PERSP,
        clip_start=float(data.clip_start),
        clip_end=float(data.clip_end),
        border=border_pixels(render, width, height),
    )


def view_camera(view_matrix, projection, width: int, height: int, ortho: bool, clip_start: float, clip_end: float) -> Camera:
    """A camera from a 3D viewport's view and projection matrices."""
    matrix = np.linalg.inv(np.asarray(view_matrix, np.float64))
    return Camera(
        matrix=matrix,
        window=window_from_projection(projection, ortho),
        width=max(1, width),
        height=max(1, height),
        kind=CAMERA_ORTHO if ortho else CAMERA_PERSP,
        clip_start=clip_start,
        clip_end=clip_end,
    )
