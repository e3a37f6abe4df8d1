"""bench/gather_replay.py: a gather saved during a render replays alone to
the render's own outputs, whole or over a range of its samples."""

from __future__ import annotations

import os
import pickle
import sys

import numpy as np
from scenes_py import box_scene

from gpu_core.gi import gather
from gpu_core.renderer import Renderer
from gpu_core.settings import RenderSettings

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "bench"))
from gather_replay import LaunchRecorder, replay  # noqa: E402

GI = RenderSettings(mode="gi", samples=2, global_photons=20_000, caustic_photons=20_000, photon_k=20,
                    cache_seeds=80, gather_rays=16)


def test_a_saved_gather_replays_to_the_outputs_of_the_render_it_came_from(device, tmp_path):
    path = str(tmp_path / "launch.pkl")
    gathering = gather.gather_range
    with LaunchRecorder(path):
        result = Renderer(device).render(box_scene(mirror=True), GI)
    assert gather.gather_range is gathering
    with open(path, "rb") as f:
        launch = pickle.load(f)
    whole = replay(device, launch)
    gathered = result.stats["gi"]["gather"]
    assert whole["end"] - whole["first"] == gathered["samples"]
    assert whole["hits"].sum() == round(gathered["hit_fraction"] * gathered["samples"] * gathered["rays_per_sample"])
    assert np.isfinite(whole["irradiance"]).all() and whole["irradiance"].max() > 0.0
    part = replay(device, launch, 3, 7)
    np.testing.assert_array_equal(part["irradiance"], whole["irradiance"][3:7])
    np.testing.assert_array_equal(part["hits"], whole["hits"][3:7])
    one_bounce = replay(device, launch, max_specular=0)
    assert one_bounce["hits"].sum() < whole["hits"].sum()  # the mirror's reflections are gone
