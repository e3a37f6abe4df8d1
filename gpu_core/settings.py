"""Render settings: every knob that trades speed for accuracy lives here."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RenderSettings:
    """What the renderer does; the add-on fills it from scene.gpugi."""

    samples: int = 16  # camera paths per pixel (anti-aliasing and light sampling)
    max_bounces: int = 8  # mirror/glass bounces followed from the camera
    light_samples: int = 1  # shadow rays per light at each diffuse point
    diffuse_bounces: int = 0  # path-traced diffuse bounces (0 = direct light only)
    seed: int = 0  # random sequence; change for a different noise pattern
    clamp: float = 0.0  # clamp of one sample's radiance; 0 = off
    transparent_background: bool = False  # film alpha 0 where the world is seen
    batch_pixels: int = 16384  # most pixels per kernel launch (bounds cancel latency)

    def validated(self) -> "RenderSettings":
        """A copy with every field in its valid range."""
        return RenderSettings(
            samples=max(1, int(self.samples)),
            max_bounces=max(0, int(self.max_bounces)),
            light_samples=max(1, int(self.light_samples)),
            diffuse_bounces=max(0, int(self.diffuse_bounces)),
            seed=int(self.seed) & 0xFFFFFFFF,
            clamp=max(0.0, float(self.clamp)),
            transparent_background=bool(self.transparent_background),
            batch_pixels=max(1, int(self.batch_pixels)),
        )
