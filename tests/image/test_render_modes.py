"""Render modes and the preset ladder."""

import dataclasses

import pytest

from gpu_core.settings import MODES, PRESETS, RenderSettings, preset

LADDER = ("draft", "preview", "final", "reference")
# knobs where a higher step costs more and gives less error
GROWING = ("samples", "diffuse_bounces", "global_photons", "caustic_photons", "photon_k", "cache_seeds",
           "gather_rays", "gi_subpixels")


def test_unknown_choices_are_validated_to_their_defaults():
    assert RenderSettings(mode="nonsense").validated().mode == "reference"
    assert RenderSettings(denoise_quality="ultra").validated().denoise_quality == "high"  # any choice: its default
    assert set(MODES) == {"reference", "gi"}


def test_presets_form_a_ladder():
    assert tuple(PRESETS) == LADDER
    fields = {f.name for f in dataclasses.fields(RenderSettings)}
    for name in LADDER:
        assert set(PRESETS[name]) <= fields
        assert set(GROWING) <= set(PRESETS[name])
    for lower, higher in zip(LADDER, LADDER[1:]):
        for knob in GROWING:
            assert PRESETS[lower][knob] <= PRESETS[higher][knob], (lower, higher, knob)
        assert PRESETS[lower]["cut_delta"] >= PRESETS[higher]["cut_delta"]  # a finer cut costs more
    assert PRESETS["reference"]["diffuse_bounces"] >= 16  # the ground truth follows light far
    # adaptive sampling: Final stops pixels at a lower noise than Preview; the ground truth takes every sample
    assert 0.0 < PRESETS["final"]["noise_threshold"] <= PRESETS["preview"]["noise_threshold"]
    assert PRESETS["reference"]["noise_threshold"] == 0.0


def test_preset_values_and_overrides():
    final = preset("final", seed=7)
    assert (final.samples, final.diffuse_bounces, final.seed) == (64, 4, 7)
    assert final.validated() == final
    with pytest.raises(KeyError):
        preset("ultra")
