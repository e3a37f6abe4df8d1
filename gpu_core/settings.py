"""Render settings: every knob that trades speed for accuracy lives here,
with the preset ladder (Draft, Preview, Final, Reference) that sets them."""

from __future__ import annotations

from dataclasses import dataclass, replace

# Render modes: "reference" is the path tracer (the in-house ground truth);
# "gi" traces direct light and specular paths and takes indirect diffuse
# light from photon maps, the irradiance cache and final gathering.
MODES = ("reference", "gi")


@dataclass
class RenderSettings:
    """What the renderer does; the add-on fills it from scene.gpugi."""

    mode: str = "reference"  # one of MODES
    samples: int = 16  # camera paths per pixel (anti-aliasing and light sampling)
    max_bounces: int = 8  # mirror/glass bounces followed from the camera
    light_samples: int = 1  # shadow rays per light at each diffuse point
    diffuse_bounces: int = 0  # path-traced diffuse bounces (0 = direct light only)
    seed: int = 0  # random sequence; change for a different noise pattern
    clamp: float = 0.0  # clamp of one sample's radiance; 0 = off
    transparent_background: bool = False  # film alpha 0 where the world is seen
    batch_pixels: int = 16384  # most pixels per kernel launch (bounds cancel latency)
    light_passes: bool = False  # also return the light passes (renderer.LIGHT_PASSES)
    denoising_passes: bool = False  # also return Denoising Albedo, Normal and Depth

    # Global-illumination knobs, read by the "gi" mode; the reference path
    # tracer ignores them.
    global_photons: int = 200_000  # photons emitted for the global map
    caustic_photons: int = 100_000  # photons emitted for the caustic map (traced only with mirrors or glass)
    photon_k: int = 50  # nearest photons in one density estimate
    cache_seeds: int = 1600  # irradiance-cache sample points (k-means seeds)
    gather_rays: int = 256  # final-gather rays per sample point
    cut_delta: float = 1.0  # illumination cut: split a node where |E~ - E| > delta * E
    cache_alpha: float = 0.6  # cache error weight of distance, times the scene's largest side

    def validated(self) -> "RenderSettings":
        """A copy with every field in its valid range."""
        return replace(
            self,
            mode=self.mode if self.mode in MODES else "reference",
            samples=max(1, int(self.samples)),
            max_bounces=max(0, int(self.max_bounces)),
            light_samples=max(1, int(self.light_samples)),
            diffuse_bounces=max(0, int(self.diffuse_bounces)),
            seed=int(self.seed) & 0xFFFFFFFF,
            clamp=max(0.0, float(self.clamp)),
            transparent_background=bool(self.transparent_background),
            batch_pixels=max(1, int(self.batch_pixels)),
            light_passes=bool(self.light_passes),
            denoising_passes=bool(self.denoising_passes),
            global_photons=max(0, int(self.global_photons)),
            caustic_photons=max(0, int(self.caustic_photons)),
            photon_k=max(1, int(self.photon_k)),
            cache_seeds=max(1, int(self.cache_seeds)),
            gather_rays=max(1, int(self.gather_rays)),
            cut_delta=max(0.0, float(self.cut_delta)),
            cache_alpha=max(0.0, float(self.cache_alpha)),
        )


# The preset ladder: each step costs more time and gives less error. Samples
# and bounces drive the path tracer (in GI mode samples still anti-alias and
# sample direct light); the photon, cache and gather values drive the GI mode
# (the seed paper's scenes used 100k-470k global and 100k-280k caustic
# photons, 1.6k-5k seeds, 250-500 gather rays).
PRESETS: dict[str, dict] = {
    "draft": dict(samples=4, max_bounces=4, diffuse_bounces=1, global_photons=50_000, caustic_photons=20_000,
                  photon_k=20, cache_seeds=400, gather_rays=64, cut_delta=2.0, cache_alpha=0.6),
    "preview": dict(samples=16, max_bounces=8, diffuse_bounces=2, global_photons=100_000, caustic_photons=50_000,
                    photon_k=32, cache_seeds=1000, gather_rays=128, cut_delta=1.5, cache_alpha=0.6),
    "final": dict(samples=64, max_bounces=8, diffuse_bounces=4, global_photons=250_000, caustic_photons=100_000,
                  photon_k=50, cache_seeds=1600, gather_rays=256, cut_delta=1.0, cache_alpha=0.6),
    "reference": dict(samples=1024, max_bounces=16, diffuse_bounces=16, global_photons=1_000_000,
                      caustic_photons=500_000, photon_k=100, cache_seeds=5000, gather_rays=512, cut_delta=0.5,
                      cache_alpha=0.6),
}


def preset(name: str, **overrides) -> RenderSettings:
    """Settings of a preset (see PRESETS), with any field overridden."""
    return RenderSettings(**{**PRESETS[name], **overrides})
