"""Denoising (Open Image Denoise through pyoidn): closer to the converged
image than the noisy one, the plan and stats say so, bad values never pass
through, and a missing denoiser is a warning, never a failed render."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scenes_py import camera_looking_down, plane_scene, quad

from gpu_core.denoise import denoise, unavailable
from gpu_core.errors import GpuGiError
from gpu_core.image import DENOISING_PASSES
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights
from gpu_core.settings import RenderSettings


def soft_shadow_scene():
    """A plane, a floating square and a large round light: a soft shadow, noisy at few samples."""
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 1.5), power=(60.0,) * 3, radius=0.5)])
    occluder = quad((0.0, 0.0, 0.5), 0.6)
    return plane_scene(lights, camera_looking_down(height=3.0, half_width=1.2, size=64), extra_tris=[occluder],
                       extra_materials=[{"base_color": (0.6, 0.3, 0.2)}])


def rmse(image, reference):
    return float(np.sqrt(((image[..., :3] - reference[..., :3]) ** 2).mean()))


def test_denoised_few_sample_render_is_closer_to_the_converged_one(device):
    scene = soft_shadow_scene()
    renderer = Renderer(device)
    converged = renderer.render(scene, RenderSettings(samples=512)).passes["Combined"]
    noisy = renderer.render(scene, RenderSettings(samples=2)).passes["Combined"]
    result = renderer.render(scene, RenderSettings(samples=2, denoise=True))
    denoised = result.passes["Combined"]
    assert result.stats["denoised"] and result.warnings == []
    assert rmse(denoised, converged) < 0.5 * rmse(noisy, converged)
    assert abs(denoised[..., :3].mean() / converged[..., :3].mean() - 1.0) < 0.03  # energy kept
    np.testing.assert_array_equal(denoised[..., 3], noisy[..., 3])  # alpha as rendered


def test_plan_names_the_denoiser_and_the_guides_are_returned_only_when_asked(device):
    renderer = Renderer(device)
    plain = renderer.render(soft_shadow_scene(), RenderSettings(samples=1, denoise=True))
    assert plain.stats["plan"][-1] == "denoise" and "denoise" in plain.stats["ms"]
    assert not set(DENOISING_PASSES) & set(plain.passes)
    kept = renderer.render(soft_shadow_scene(), RenderSettings(samples=1, denoise=True, denoising_passes=True))
    assert set(DENOISING_PASSES) <= set(kept.passes)
    off = renderer.render(soft_shadow_scene(), RenderSettings(samples=1))
    assert "denoise" not in off.stats["plan"] and off.stats["denoised"] is False


def test_non_finite_and_negative_input_gives_a_finite_non_negative_image():
    rng = np.random.default_rng(1)
    color = rng.random((32, 48, 4)).astype(np.float32)
    color[3, 5, 0], color[7, 9, 1], color[10, 11, 2], color[12, 13, 0] = np.nan, np.inf, -np.inf, -4.0
    albedo = np.full((32, 48, 3), 0.5, np.float32)
    albedo[0, 0] = np.nan
    normal = np.zeros((32, 48, 3), np.float32)
    normal[..., 2] = 1.0
    normal[1, 1] = np.inf
    out = denoise(color, albedo, normal, "fast")
    assert out.shape == color.shape and out.dtype == np.float32
    assert np.isfinite(out).all() and (out[..., :3] >= 0.0).all()
    np.testing.assert_array_equal(out[..., 3], color[..., 3])


@pytest.mark.parametrize("shape", [(1, 1, 4), (1, 37, 4), (3, 2, 4)])
def test_tiny_and_thin_images_denoise(shape):
    color = np.full(shape, 0.25, np.float32)
    guides = np.full(shape[:2] + (3,), 0.5, np.float32)
    out = denoise(color, guides, guides, "high")
    assert out.shape == shape and np.isfinite(out).all()


def test_a_missing_denoiser_is_a_warning_and_the_image_stays_as_rendered(device, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # import pyoidn raises ImportError
    assert "pyoidn" in unavailable()
    with pytest.raises(GpuGiError, match="pip install pyoidn"):
        denoise(np.zeros((4, 4, 4), np.float32), np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 3), np.float32))
    renderer = Renderer(device)
    settings = RenderSettings(samples=2, seed=3)
    noisy = renderer.render(soft_shadow_scene(), settings).passes["Combined"]
    result = renderer.render(soft_shadow_scene(), RenderSettings(samples=2, seed=3, denoise=True))
    assert result.stats["denoised"] is False
    assert [w for w in result.warnings if "pyoidn" in w and "not denoised" in w]
    np.testing.assert_array_equal(result.passes["Combined"], noisy)
