"""Render settings: every knob that trades speed for accuracy, declared once.

Each field of ``RenderSettings`` carries its label, description, range and
panel in its metadata; the add-on makes its Blender properties, panels and
command-line options from them (blender_addon/properties.py, ui.py,
cli.py), so a knob is written here and nowhere else. ``PRESETS`` is the
ladder (Draft, Preview, Final, Reference) that sets them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

# Render modes: "reference" is the path tracer (the in-house ground truth);
# "gi" traces direct light and specular paths and takes indirect diffuse
# light from photon maps, the irradiance cache and final gathering.
MODES = ("reference", "gi")
_MODE_ITEMS = (
    ("reference", "Reference", "Path tracer: the ground truth, noisy until many samples; indirect light needs "
     "Diffuse Bounces above 0"),
    ("gi", "GI", "Photon maps, irradiance cache and final gathering: direct light and mirrors/glass traced, "
     "indirect light and caustics from photons; smooth at few samples"),
)
_DENOISE_QUALITY_ITEMS = (
    ("high", "High", "The best Open Image Denoise gives"),
    ("balanced", "Balanced", "Between High and Fast"),
    ("fast", "Fast", "About half High's time, a little more error"),
)
_GI_ONLY = " (GI mode only)"


def knob(default, label: str, description: str, *, panel: str = "", text: str = "", minimum=None, maximum=None,
         soft_max=None, items=None, blender_default=None):
    """A setting the user sees: shown in ``panel`` (with ``text`` as its
    short label there), bounded by ``minimum`` / ``maximum`` (and offered up
    to ``soft_max``), one of ``items`` for a choice. ``blender_default``: the
    add-on's default where it differs from the library's (mode: Blender
    users get GI, library callers the ground truth)."""
    meta = dict(label=label, description=description, panel=panel, text=text or label, minimum=minimum,
                maximum=maximum, soft_max=soft_max, items=items,
                blender_default=default if blender_default is None else blender_default)
    return field(default=default, metadata=meta)


def internal(default):
    """A setting the caller fills (from the scene or the render), not a knob."""
    return field(default=default)


@dataclass
class RenderSettings:
    """What the renderer does; the add-on fills it from scene.gpugi."""

    mode: str = knob("reference", "Mode", "How indirect light is computed", panel="mode", items=_MODE_ITEMS,
                     blender_default="gi")
    samples: int = knob(16, "Samples", "Camera paths per pixel (final render): anti-aliasing and light sampling",
                        panel="sampling", text="Render", minimum=1, soft_max=1024)
    preview_samples: int = knob(32, "Viewport Samples", "Camera paths per pixel the viewport accumulates after an "
                                "edit (0: until stopped)", panel="sampling", text="Viewport", minimum=0, soft_max=1024)
    noise_threshold: float = knob(0.0, "Noise Threshold", "Adaptive sampling: a pixel stops taking samples once "
                                  "its noise, as Cycles measures it, is below this (lower: less noise, more time; "
                                  "0: every pixel takes every sample)", panel="sampling", minimum=0.0, maximum=1.0,
                                  soft_max=0.5, blender_default=0.01)
    preview_noise_threshold: float = knob(0.0, "Viewport Noise Threshold", "The Rendered viewport's adaptive "
                                          "sampling: a pixel sits the later passes out once its noise is below "
                                          "this (0: every pixel takes every sample)", panel="sampling",
                                          text="Viewport Noise", minimum=0.0, maximum=1.0, soft_max=0.5,
                                          blender_default=0.01)
    min_samples: int = knob(0, "Min Samples", "Adaptive sampling: samples every pixel takes before its noise is "
                            "judged (0: a quarter of Samples, or of Viewport Samples in the viewport, at least 4)",
                            panel="sampling", minimum=0, soft_max=1024)
    seed: int = knob(0, "Seed", "Noise pattern", panel="sampling", minimum=0)
    clamp: float = knob(0.0, "Clamp", "Largest radiance of one sample (0 disables clamping)", panel="sampling",
                        minimum=0.0)
    denoise: bool = knob(False, "Denoise", "Final renders: Intel Open Image Denoise on the image, guided by the "
                         "albedo and normal of each pixel's first diffuse surface (as Cycles' OpenImageDenoise)",
                         panel="sampling", text="Denoise Render", blender_default=True)
    preview_denoise: bool = knob(False, "Denoise Viewport", "The Rendered viewport: denoised once its samples are "
                                 "done", panel="sampling", text="Denoise Viewport")
    denoise_quality: str = knob("high", "Denoising Quality", "Open Image Denoise's quality: High is about twice "
                                "as slow as Fast", panel="sampling", text="Quality", items=_DENOISE_QUALITY_ITEMS)
    max_bounces: int = knob(8, "Specular Bounces", "Mirror and glass bounces followed along camera, gather and "
                            "photon paths", panel="light_paths", text="Specular", minimum=0, maximum=64)
    diffuse_bounces: int = knob(0, "Diffuse Bounces", "Diffuse bounces path-traced after the first diffuse hit "
                                "(0 = direct light only; Reference mode)", panel="light_paths", text="Diffuse",
                                minimum=0, maximum=64)
    global_photons: int = knob(200_000, "Global Photons", "Photons emitted for the global photon map" + _GI_ONLY,
                               panel="gi", text="Photons Global", minimum=0, soft_max=5_000_000)
    caustic_photons: int = knob(100_000, "Caustic Photons", "Photons emitted for the caustic photon map (traced "
                                "only when the scene has mirrors or glass)" + _GI_ONLY, panel="gi", text="Caustic",
                                minimum=0, soft_max=5_000_000)
    photon_k: int = knob(50, "Photons per Estimate", "Nearest photons in one density estimate of the global map "
                         "(the illumination cut) (k)" + _GI_ONLY, panel="gi", minimum=1, maximum=1024, soft_max=500)
    caustic_k: int = knob(16, "Caustic Photons per Estimate", "Nearest caustic photons in one estimate of the "
                          "caustic map, of caustics seen directly and of the caustic light the cut carries (k): "
                          "fewer, sharper caustics and less darkening where a surface ends, more noise" + _GI_ONLY,
                          panel="gi", text="Caustic Photons per Estimate", minimum=1, maximum=1024, soft_max=200)
    cache_seeds: int = knob(1600, "Cache Points", "Irradiance-cache sample points (k-means seeds)" + _GI_ONLY,
                            panel="gi", minimum=1, soft_max=20_000)
    cache_iterations: int = knob(4, "Cache Iterations", "k-means iterations that move the cache points towards "
                                 "the middle of the shading points they stand for before gathering (an edit that "
                                 "moves them starts from the last ones and takes at most 2): more, the points "
                                 "spread more evenly; fewer, sooner" + _GI_ONLY, panel="gi", minimum=1,
                                 maximum=64, soft_max=16)
    gather_rays: int = knob(256, "Gather Rays", "Final-gather rays per cache point" + _GI_ONLY, panel="gi",
                            minimum=1, soft_max=2048)
    gi_subpixels: int = knob(1, "GI Points per Pixel Side", "Shading points per pixel side at which indirect "
                             "light and caustics are interpolated (1: one per pixel; 2: four, sharper along edges "
                             "and thin objects)" + _GI_ONLY, panel="gi", text="Points per Pixel Side", minimum=1,
                             maximum=4)
    cut_delta: float = knob(1.0, "Cut Threshold", "Illumination cut: a node is replaced by its children where its "
                            "approximate irradiance differs from the exact one by more than this fraction of it "
                            "(delta)" + _GI_ONLY, panel="gi", minimum=0.0, soft_max=4.0)
    cache_alpha: float = knob(0.6, "Cache Distance Weight", "Weight of distance against normal change when "
                              "grouping cache points (alpha, times the largest side of the box of the shading "
                              "points)" + _GI_ONLY, panel="gi", minimum=0.0, soft_max=10.0)
    cache_reuse: bool = knob(True, "Reuse Cache Across Views", "Keep the irradiance records in world space when only "
                             "the view changes: a new view gathers only where they do not cover it, and start "
                             "choosing cache points from the last render's after an edit (faster and steadier while "
                             "orbiting or moving objects; off: every view is cached from scratch, as a fresh render)"
                             + _GI_ONLY, panel="gi", text="Reuse Across Views")

    light_samples: int = internal(1)  # shadow rays per light at each diffuse point
    transparent_background: bool = internal(False)  # film alpha 0 where the world is seen
    batch_pixels: int = internal(16384)  # most pixels per kernel launch (bounds cancel latency)
    batch_seconds: float = internal(0.1)  # aimed duration of one image launch: what a stop or an edit waits for
    geometry_passes: bool = internal(True)  # return Depth and Normal (the viewport shows Combined alone)
    light_passes: bool = internal(False)  # also return the light passes (image.LIGHT_PASSES)
    denoising_passes: bool = internal(False)  # also return Denoising Albedo, Normal and Depth
    # the share of the photon counts a render traces when it cannot use the
    # maps held (the viewport's coarse image after an edit): held maps of
    # the full counts are still used or reweighted
    photon_share: float = internal(1.0)

    def validated(self) -> "RenderSettings":
        """A copy with every field in its valid range."""
        values = {}
        for f in fields(self):
            value = getattr(self, f.name)
            meta = f.metadata
            if meta.get("items"):
                value = value if value in [item[0] for item in meta["items"]] else f.default
            elif isinstance(f.default, bool):
                value = bool(value)
            elif isinstance(f.default, (int, float)):
                value = type(f.default)(value)
                low, high = meta.get("minimum"), meta.get("maximum")
                value = max(low, value) if low is not None else value
                value = min(high, value) if high is not None else value
            values[f.name] = value
        values["seed"] = int(self.seed) & 0xFFFFFFFF
        values["light_samples"] = max(1, int(self.light_samples))
        values["batch_pixels"] = max(1, int(self.batch_pixels))
        seconds = float(self.batch_seconds)
        values["batch_seconds"] = min(max(seconds, 1e-3), 10.0) if seconds == seconds else 0.1
        share = float(self.photon_share)
        values["photon_share"] = min(max(share, 1e-3), 1.0) if share == share else 1.0
        return replace(self, **values)


def knobs() -> list:
    """The dataclass fields the user sees (those with a label), in order."""
    return [f for f in fields(RenderSettings) if f.metadata.get("label")]


# The preset ladder: each step costs more time and gives less error. Samples
# and bounces drive the path tracer (in GI mode samples still anti-alias and
# sample direct light); the photon, cache and gather values drive the GI mode
# (the seed paper's scenes used 100k-470k global and 100k-280k caustic
# photons, 1.6k-5k seeds, 250-500 gather rays).
# Final interpolates at one GI point per pixel like Preview (and the default):
# four per pixel measured no lower error against Cycles at 12-45% more time
# (README, "Final against the front"). Preview and Final sample adaptively
# (Noise Threshold): at 0.005 Final's error against Cycles measured the same
# as taking every sample, at 18-40% less time; Reference takes every sample,
# as a ground truth should (README, "Adaptive sampling").
PRESETS: dict[str, dict] = {
    "draft": dict(samples=4, max_bounces=4, diffuse_bounces=1, global_photons=50_000, caustic_photons=20_000,
                  photon_k=20, caustic_k=12, cache_seeds=400, cache_iterations=4, gather_rays=64, gi_subpixels=1,
                  cut_delta=2.0, cache_alpha=0.6, noise_threshold=0.0, min_samples=0),
    "preview": dict(samples=16, max_bounces=8, diffuse_bounces=2, global_photons=100_000, caustic_photons=50_000,
                    photon_k=32, caustic_k=16, cache_seeds=1000, cache_iterations=4, gather_rays=128,
                    gi_subpixels=1, cut_delta=1.5, cache_alpha=0.6, noise_threshold=0.01, min_samples=0),
    "final": dict(samples=64, max_bounces=8, diffuse_bounces=4, global_photons=250_000, caustic_photons=100_000,
                  photon_k=50, caustic_k=16, cache_seeds=1600, cache_iterations=4, gather_rays=256, gi_subpixels=1,
                  cut_delta=1.0, cache_alpha=0.6, noise_threshold=0.005, min_samples=0),
    "reference": dict(samples=1024, max_bounces=16, diffuse_bounces=16, global_photons=1_000_000,
                      caustic_photons=500_000, photon_k=100, caustic_k=32, cache_seeds=5000, cache_iterations=4,
                      gather_rays=512, gi_subpixels=2, cut_delta=0.5, cache_alpha=0.6, noise_threshold=0.0,
                      min_samples=0),
}


def preset(name: str, **overrides) -> RenderSettings:
    """Settings of a preset (see PRESETS), with any field overridden."""
    return RenderSettings(**{**PRESETS[name], **overrides})
