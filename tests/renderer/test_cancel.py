"""Stopping a render: ``should_stop`` is polled between every GI stage and
gather batch as well as between image batches; stopping at any poll raises
RenderCancelled, and the next render of the same renderer is unchanged."""

from __future__ import annotations

import dataclasses
import itertools
import time

import numpy as np
import pytest
from test_threads import GI as GI_REUSING, scene

from gpu_core.device.programs import Programs
from gpu_core.errors import RenderCancelled
from gpu_core.gi import gather
from gpu_core.renderer import Renderer

# GI with another cache setting: alternating the two, every render runs the
# GI cache stages again (a render with the same settings would reuse them,
# and one of the same lit scene would keep the records of the last view).
# Image batches of one size (the most pixels a launch may take, and a time
# aimed at that no batch reaches), so every render polls as often: batches
# sized by the measured time vary with the machine's load
GI = dataclasses.replace(GI_REUSING, cache_reuse=False, batch_pixels=64, batch_seconds=10.0)
OTHER = dataclasses.replace(GI, cache_alpha=GI.cache_alpha + 0.1)


def _polls(renderer, the_scene, settings) -> int:
    polls = []
    renderer.render(the_scene, settings, should_stop=lambda: polls.append(1) is None and False)
    return len(polls)


def test_every_gi_stage_and_gather_batch_is_followed_by_a_poll(device, monkeypatch):
    the_scene = scene(True, 20)  # a mirror: the caustic map and its stage too
    renderer = Renderer(device)
    renderer.render(the_scene, GI)  # programs ready: no poll while waiting for builds
    one_batch = _polls(renderer, the_scene, OTHER)
    # polls after compile, upload, photons, shading points, sample points, cut,
    # gather, interpolation, and the GI field before the image
    assert one_batch >= 9
    monkeypatch.setattr(gather, "_RAYS_PER_LAUNCH", 16 * 20)  # 20 cache points per batch: 4 batches
    assert _polls(renderer, the_scene, GI) == one_batch + 3


def test_a_render_whose_programs_are_built_waits_for_no_build(device, monkeypatch):
    """The builds are not waited for (nor polled for) when nothing is left to
    build, however long a look at the programs would take: the polls of a
    render do not depend on how fast a thread starts."""
    the_scene = scene(True, 20)
    renderer = Renderer(device)
    renderer.render(the_scene, GI)
    polls = _polls(renderer, the_scene, OTHER)
    build_all = Programs.build_all

    def slow_build_all(self, *args, **kwargs):
        time.sleep(0.3)
        return build_all(self, *args, **kwargs)

    monkeypatch.setattr(Programs, "build_all", slow_build_all)
    assert _polls(renderer, the_scene, GI) == polls


def test_stopping_at_any_poll_cancels_and_the_next_render_is_unchanged(device):
    the_scene = scene(True, 20)
    renderer = Renderer(device)
    expected = renderer.render(the_scene, GI).passes["Combined"]
    for stop_at in range(_polls(renderer, the_scene, OTHER)):
        calls = itertools.count()
        with pytest.raises(RenderCancelled):
            renderer.render(the_scene, OTHER, should_stop=lambda: next(calls) >= stop_at)
        np.testing.assert_array_equal(renderer.render(the_scene, GI).passes["Combined"], expected)


def test_stopping_a_view_that_keeps_the_records_of_the_last_one_leaves_the_next_render_unchanged(device):
    first, moved = scene(True, 20), scene(True, 20)
    moved.camera.matrix[0, 3] += 0.2
    fresh = Renderer(device)
    fresh.render(first, GI_REUSING)
    expected = fresh.render(moved, GI_REUSING)
    assert "cache_records_reused" in expected.stats["plan"]
    for stop_at in range(6):
        renderer = Renderer(device)
        renderer.render(first, GI_REUSING)
        calls = itertools.count()
        with pytest.raises(RenderCancelled):
            renderer.render(moved, GI_REUSING, should_stop=lambda: next(calls) >= stop_at)
        np.testing.assert_array_equal(renderer.render(moved, GI_REUSING).passes["Combined"],
                                      expected.passes["Combined"])
