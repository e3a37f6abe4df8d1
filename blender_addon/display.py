"""Pixels to screen: preparing the float RGBA image and drawing it in the viewport.

``prepare_pixels`` has no Blender dependency so tests can check it (and draw
its output with moderngl); ``draw_pixels`` imports Blender's gpu module only
when called, from view_draw.
"""

from __future__ import annotations

import numpy as np

# RGBA16F would overflow at 65504; we upload RGBA32F and still clamp to keep
# the display shader's arithmetic finite.
DISPLAY_MAX = 65504.0


def prepare_pixels(rgba: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width, 4) float32 contiguous pixels for a region of that size.

    A smaller (coarse) image is scaled up by nearest neighbour; non-finite
    values become 0 and the rest is clamped to [0, DISPLAY_MAX]. Rows stay
    bottom-up, as both Blender's and OpenGL's textures expect.
    """
    img = np.asarray(rgba, np.float32)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"expected an (H, W, 4) image, got {img.shape}")
    src_h, src_w = img.shape[:2]
    if (src_h, src_w) != (height, width):
        rows = np.minimum((np.arange(height) * src_h) // max(height, 1), src_h - 1)
        cols = np.minimum((np.arange(width) * src_w) // max(width, 1), src_w - 1)
        img = img[rows][:, cols]
    img = np.nan_to_num(img, nan=0.0, posinf=DISPLAY_MAX, neginf=0.0)
    return np.ascontiguousarray(np.clip(img, 0.0, DISPLAY_MAX), np.float32)


def draw_pixels(engine, scene, pixels: np.ndarray) -> None:
    """Draw prepared pixels over the region with the scene's view transform."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    height, width = pixels.shape[:2]
    buffer = gpu.types.Buffer("FLOAT", width * height * 4, pixels.ravel())
    texture = gpu.types.GPUTexture((width, height), format="RGBA32F", data=buffer)
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(texture, (0, 0), width, height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")
