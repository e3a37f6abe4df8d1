"""Denoising the image with Intel Open Image Denoise (the ``pyoidn``
binding), guided by the denoising albedo and normal the image kernel
writes at each path's first diffuse event — what Cycles' OpenImageDenoise
reads too. The colour is HDR (linear, unbounded); the albedo and normal
are noisy where the pixel's samples saw different surfaces, so OIDN
prefilters them. Runs on the host's CPU, after the device's work.
"""

from __future__ import annotations

import threading

import numpy as np

from .errors import GpuGiError

QUALITIES = ("fast", "balanced", "high")
_lock = threading.Lock()  # one shared OIDN filter: calls take turns


def unavailable() -> str:
    """Why denoising cannot run here ('' when it can)."""
    try:
        import pyoidn  # noqa: F401
    except ImportError:
        return "denoising needs the pyoidn package (Intel Open Image Denoise): pip install pyoidn"
    except OSError as err:  # its shared library would not load
        return f"denoising is unavailable: Open Image Denoise did not load ({err})"
    return ""


def denoise(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray, quality: str = "high") -> np.ndarray:
    """The denoised RGB of ``color`` (H, W, 3 or 4: alpha is kept), rows
    in either order; ``albedo`` and ``normal`` (H, W, 3) are its guides.
    Non-finite input values count as black. GpuGiError when OIDN is
    missing or fails."""
    problem = unavailable()
    if problem:
        raise GpuGiError(problem)
    import pyoidn

    rgb = _clean(color[..., :3], 0.0, np.inf)
    guides = _clean(albedo, 0.0, 1.0), _clean(normal, -1.0, 1.0)
    try:
        with _lock:
            out = pyoidn.denoise(rgb, *guides, hdr=True, quality=quality)
    except (RuntimeError, ValueError, TypeError) as err:
        raise GpuGiError(f"denoising failed: {err}") from err
    out = np.nan_to_num(np.maximum(out, 0.0), nan=0.0, posinf=0.0)
    if color.shape[-1] == 4:
        out = np.concatenate([out, color[..., 3:]], axis=-1)
    return out.astype(np.float32)


def _clean(image: np.ndarray, low: float, high: float) -> np.ndarray:
    """A contiguous float32 copy within [low, high], non-finite values 0."""
    clean = np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return np.ascontiguousarray(np.clip(clean, low, high))
