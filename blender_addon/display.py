"""Pixels to screen: preparing the float RGBA image and drawing it in the viewport.

``prepare_pixels`` has no Blender dependency, so tests check it and draw its
output with moderngl; ``ViewportDrawer`` imports Blender's gpu module only
when it draws (gpu drawing is unavailable in background mode).
"""

from __future__ import annotations

import numpy as np

# Largest value uploaded: keeps the display transform's arithmetic finite
# (and would also fit a half-float texture).
DISPLAY_MAX = 65504.0


def prepare_pixels(rgba: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width, 4) float32 C-contiguous pixels for a region of that size.

    A smaller (coarse) image is scaled up by nearest neighbour; NaN becomes
    0, +Inf DISPLAY_MAX, and everything is clamped to [0, DISPLAY_MAX]. Rows
    stay bottom-up, as both Blender's and OpenGL's textures expect.
    """
    img = np.asarray(rgba, np.float32)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"expected an (H, W, 4) image, got {img.shape}")
    if width < 1 or height < 1:
        raise ValueError(f"region size {width}x{height} is empty")
    src_h, src_w = img.shape[:2]
    if (src_h, src_w) != (height, width):
        rows = np.minimum((np.arange(height) * src_h) // height, src_h - 1)
        cols = np.minimum((np.arange(width) * src_w) // width, src_w - 1)
        img = img[rows][:, cols]
    img = np.nan_to_num(img, nan=0.0, posinf=DISPLAY_MAX, neginf=0.0)
    return np.ascontiguousarray(np.clip(img, 0.0, DISPLAY_MAX), np.float32)


class ViewportDrawer:
    """Keeps the GPU texture of the latest image; re-uploads only when the
    image or the region size changes."""

    def __init__(self):
        self._key = None
        self._texture = None

    def draw(self, engine, scene, image: np.ndarray, version: int, width: int, height: int) -> None:
        """Draw ``image`` over the whole region with the scene's view transform."""
        import gpu
        from gpu_extras.presets import draw_texture_2d

        key = (version, width, height)
        if key != self._key:
            pixels = prepare_pixels(image, width, height)
            buffer = gpu.types.Buffer("FLOAT", width * height * 4, pixels.ravel())
            self._texture = gpu.types.GPUTexture((width, height), format="RGBA32F", data=buffer)
            self._key = key
        gpu.state.blend_set("ALPHA_PREMULT")
        engine.bind_display_space_shader(scene)
        draw_texture_2d(self._texture, (0, 0), width, height)
        engine.unbind_display_space_shader()
        gpu.state.blend_set("NONE")
