"""A pixel's paths draw their first light sample and first BSDF direction
from one scrambled Sobol sequence (image.cl ImageStrata): 16 paths per
pixel miss the converged image by clearly less than a quarter of what one
path misses it by, the 1/sqrt(16) of independent samples."""

import numpy as np
from scenes_py import camera_looking_down, plane_scene, quad

from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_AREA, Lights
from gpu_core.settings import RenderSettings

SIZE = 32


def _error(image: np.ndarray, converged: np.ndarray) -> float:
    return float(np.sqrt(((image - converged) ** 2).mean()) / converged.mean())


def _errors(device, scene, **settings) -> tuple[float, float]:
    """Relative RMS error of 1 and of 16 paths per pixel against 4096."""
    def image(samples: int) -> np.ndarray:
        return Renderer(device).render(scene, RenderSettings(samples=samples, **settings)).passes["Combined"][..., :3]

    converged = image(4096)
    return _error(image(1), converged), _error(image(16), converged)


def _soft_shadow_scene():
    """A diffuse plane under a large square light, half of it shadowed by a
    square between them, seen from above (no edge in view to anti-alias)."""
    light = dict(kind=LIGHT_AREA, position=(0.0, 0.0, 2.0), power=(200.0,) * 3, direction=(0, 0, -1),
                 axis_u=(1.5, 0, 0), axis_v=(0, 1.5, 0), shape=0)
    blocker = quad((-0.8, 0.0, 1.0), 1.6)
    return plane_scene(Lights.make([light]), camera_looking_down(4.0, 2.0, SIZE),
                       extra_tris=[blocker], extra_materials=[{"base_color": (0.5, 0.5, 0.5), "name": "blocker"}])


def test_light_samples_of_a_pixel_are_stratified(device):
    one, sixteen = _errors(device, _soft_shadow_scene(), max_bounces=0, diffuse_bounces=0)
    assert sixteen < 0.6 * one / 4, (one, sixteen)


def test_light_samples_and_first_bounces_of_a_pixel_are_stratified(device):
    """A path tracer's first diffuse bounce as well (Reference mode)."""
    one, sixteen = _errors(device, _soft_shadow_scene(), mode="reference", max_bounces=0, diffuse_bounces=1)
    assert sixteen < 0.6 * one / 4, (one, sixteen)
