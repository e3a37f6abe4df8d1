"""Render passes: which ones a view layer asks for, under Blender's names.

The names are those Cycles registers, so compositor nodes (Denoise among
them) find the same sockets. One difference: our light passes include the
surface colour, so Diffuse/Glossy/Transmission Direct + Indirect, Emission
and Environment add up to Combined (Cycles divides the colour out into
Color passes, which this engine does not write).
"""

from __future__ import annotations

from typing import NamedTuple

from gpu_core.image import DENOISING_PASSES, LIGHT_PASSES


class PassSpec(NamedTuple):
    name: str  # Blender's pass name (the compositor socket)
    channels: str  # channel ids; their count is the pass width
    kind: str  # register_pass type: COLOR, VECTOR or VALUE
    toggle: str  # ViewLayer property that enables it ('' = always on)


# Every pass this engine can write, in the order Blender lists them.
PASSES = (
    PassSpec("Combined", "RGBA", "COLOR", ""),
    PassSpec("Depth", "Z", "VALUE", "use_pass_z"),
    PassSpec("Normal", "XYZ", "VECTOR", "use_pass_normal"),
    PassSpec("Diffuse Direct", "RGB", "COLOR", "use_pass_diffuse_direct"),
    PassSpec("Diffuse Indirect", "RGB", "COLOR", "use_pass_diffuse_indirect"),
    PassSpec("Glossy Direct", "RGB", "COLOR", "use_pass_glossy_direct"),
    PassSpec("Glossy Indirect", "RGB", "COLOR", "use_pass_glossy_indirect"),
    PassSpec("Transmission Direct", "RGB", "COLOR", "use_pass_transmission_direct"),
    PassSpec("Transmission Indirect", "RGB", "COLOR", "use_pass_transmission_indirect"),
    PassSpec("Emission", "RGB", "COLOR", "use_pass_emit"),
    PassSpec("Environment", "RGB", "COLOR", "use_pass_environment"),
    PassSpec("Caustics", "RGB", "COLOR", "gpugi.use_pass_caustics"),
    PassSpec("Denoising Normal", "XYZ", "VECTOR", "cycles.denoising_store_passes"),
    PassSpec("Denoising Albedo", "RGB", "COLOR", "cycles.denoising_store_passes"),
    PassSpec("Denoising Depth", "Z", "VALUE", "cycles.denoising_store_passes"),
)
LIGHT_PASS_NAMES = set(LIGHT_PASSES)
DENOISING_PASS_NAMES = set(DENOISING_PASSES)


def is_enabled(view_layer, spec: PassSpec) -> bool:
    """Whether the view layer asks for the pass; a toggle that does not
    exist (the Cycles add-on disabled, say) reads as off."""
    if not spec.toggle:
        return True
    owner = view_layer
    *path, prop = spec.toggle.split(".")
    for name in path:
        owner = getattr(owner, name, None)
    return bool(getattr(owner, prop, False))


def enabled_passes(view_layer) -> list[PassSpec]:
    """The passes the view layer asks for, Combined first."""
    return [spec for spec in PASSES if is_enabled(view_layer, spec)]


def wants_light_passes(view_layer) -> bool:
    return any(spec.name in LIGHT_PASS_NAMES for spec in enabled_passes(view_layer))


def wants_denoising_passes(view_layer) -> bool:
    return any(spec.name in DENOISING_PASS_NAMES for spec in enabled_passes(view_layer))
