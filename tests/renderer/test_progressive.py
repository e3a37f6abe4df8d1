"""Progressive refinement through one renderer: passes numbered by
``sample_start`` average to one render of all their samples, the GI cache
is computed once for a view and reused by every later pass, and a pass
stopped before its upload leaves its edits for the next one."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from test_threads import GI, REFERENCE, scene

from gpu_core.errors import RenderCancelled
from gpu_core.renderer import Renderer


@pytest.mark.parametrize("settings", [GI, REFERENCE], ids=["gi", "reference"])
def test_passes_numbered_by_sample_start_average_to_one_render_of_all_samples(device, settings):
    the_scene = scene(True, 16)
    renderer = Renderer(device)
    whole = renderer.render(the_scene, dataclasses.replace(settings, samples=8)).passes["Combined"]
    passes, start = [], 0
    for samples in (1, 1, 2, 4):
        result = renderer.render(the_scene, dataclasses.replace(settings, samples=samples), sample_start=start)
        passes.append((samples, result.passes["Combined"]))
        start += samples
    accumulated = sum(samples * image for samples, image in passes) / start
    np.testing.assert_allclose(accumulated, whole, rtol=1e-4, atol=1e-6)
    # and the passes are different samples, not the same ones again
    assert not np.array_equal(passes[0][1], passes[1][1])


def test_more_accumulated_samples_lower_the_variance_and_keep_the_mean(device):
    the_scene = scene(False, 24)
    renderer = Renderer(device)
    one = dataclasses.replace(REFERENCE, samples=1)
    images = [renderer.render(the_scene, one, sample_start=s).passes["Combined"][..., :3] for s in range(16)]
    few, many = np.mean(images[:2], axis=0), np.mean(images, axis=0)
    exact = np.mean([renderer.render(the_scene, one, sample_start=s).passes["Combined"][..., :3]
                     for s in range(16, 80)] + images, axis=0)  # 80 samples: nearly the expectation
    assert np.mean((many - exact) ** 2) < 0.5 * np.mean((few - exact) ** 2)
    assert abs(many.mean() - exact.mean()) < 0.02 * exact.mean()


def test_a_pass_after_the_first_reuses_the_gi_cache_and_gives_the_image_of_a_fresh_renderer(device):
    the_scene = scene(True, 16)
    renderer = Renderer(device)
    first = renderer.render(the_scene, GI)
    second = renderer.render(the_scene, GI, sample_start=GI.samples)
    assert not first.stats["gi"]["cache_reused"] and second.stats["gi"]["cache_reused"]
    assert "final_gather_reused" in second.stats["plan"] and "gather" not in second.stats["ms"]
    fresh = Renderer(device).render(the_scene, GI, sample_start=GI.samples)
    np.testing.assert_array_equal(second.passes["Combined"], fresh.passes["Combined"])


def test_edits_of_a_render_stopped_before_its_upload_reach_the_next_render(device):
    afresh = dataclasses.replace(GI, cache_reuse=False)  # cache points chosen afresh, as the fresh render's
    renderer = Renderer(device)
    renderer.render(scene(False, 16), afresh)
    moved = scene(True, 16)  # a mirror panel added: geometry and materials
    with pytest.raises(RenderCancelled):  # stopped at the first poll, before the upload
        renderer.render(moved, afresh, edits={"geometry", "materials"}, should_stop=lambda: True)
    after = renderer.render(moved, afresh, edits=set())
    assert "kdtree" in after.stats["plan"]
    np.testing.assert_array_equal(after.passes["Combined"], Renderer(device).render(moved, afresh).passes["Combined"])


def test_a_static_scene_gives_the_same_image_frame_after_frame_held_or_fresh(device):
    # photons, cache seeds and camera paths are seeded per photon, point and
    # pixel sample, never per frame: no flicker without an edit
    the_scene = scene(True, 16)
    held = Renderer(device)
    frames = [(held if i % 2 else Renderer(device)).render(the_scene, GI).passes["Combined"] for i in range(8)]
    for frame in frames[1:]:
        np.testing.assert_array_equal(frame, frames[0])


@pytest.mark.parametrize("settings", [GI, REFERENCE], ids=["gi", "reference"])
def test_accumulating_passes_continue_one_film_that_equals_one_render_of_all_samples(device, settings):
    the_scene = scene(True, 16)
    renderer = Renderer(device)
    whole = renderer.render(the_scene, dataclasses.replace(settings, samples=8)).passes["Combined"]
    start = 0
    for samples in (1, 1, 2, 4):
        result = renderer.render(the_scene, dataclasses.replace(settings, samples=samples), sample_start=start,
                                 accumulate=True)
        start += samples
        held = result.stats["accumulated"]
        assert (held["samples"], held["sample_start"], held["converged"]) == (start, 0, False)
        assert held["mean_samples"] == start
    np.testing.assert_allclose(result.passes["Combined"], whole, rtol=1e-4, atol=1e-6)


def test_an_accumulating_pass_that_does_not_follow_the_film_starts_a_new_one(device):
    the_scene, one = scene(False, 16), dataclasses.replace(REFERENCE, samples=1)
    renderer = Renderer(device)
    renderer.render(the_scene, one, accumulate=True)
    # numbered past the film's end: a film of its own, from that number on
    skipped = renderer.render(the_scene, one, sample_start=5, accumulate=True)
    assert skipped.stats["accumulated"]["sample_start"] == 5 and skipped.stats["accumulated"]["samples"] == 1
    np.testing.assert_array_equal(skipped.passes["Combined"],
                                  Renderer(device).render(the_scene, one, sample_start=5).passes["Combined"])
    # another view: a new film, even where the numbers follow on
    x0, x1, y0, y1 = the_scene.camera.window
    turned = dataclasses.replace(the_scene, camera=dataclasses.replace(the_scene.camera,
                                                                       window=(x0 + 0.1, x1 + 0.1, y0, y1)))
    moved = renderer.render(turned, one, sample_start=6, accumulate=True)
    assert moved.stats["accumulated"]["sample_start"] == 6 and moved.stats["accumulated"]["samples"] == 1
    # a new accumulation from 0 never continues the last one
    again = renderer.render(turned, one, accumulate=True)
    assert again.stats["accumulated"]["samples"] == 1


def test_a_noise_threshold_stops_settled_pixels_of_an_accumulating_film_until_it_converges(device):
    the_scene = scene(False, 16)
    renderer = Renderer(device)
    adaptive = dataclasses.replace(REFERENCE, samples=4, noise_threshold=0.05, min_samples=8)
    start, history = 0, []
    while start < 64:
        result = renderer.render(the_scene, adaptive, sample_start=start, accumulate=True)
        held = result.stats["accumulated"]
        history.append((held["samples"], held["mean_samples"], held["converged"]))
        if held["converged"]:
            break
        start += 4
    samples = [h[0] for h in history]
    mean = [h[1] for h in history]
    # every pixel takes the minimum; then fewer than all take each pass
    assert mean[1] == samples[1] == 8
    assert mean[-1] < samples[-1]
    # the image stays that of the samples taken: close to a full render of as many
    full = Renderer(device).render(the_scene, dataclasses.replace(REFERENCE, samples=64)).passes["Combined"]
    assert abs(result.passes["Combined"][..., :3].mean() / full[..., :3].mean() - 1.0) < 0.05


def test_the_viewports_passes_of_one_view_end_as_one_render_of_all_their_samples(device):
    from blender_addon.viewport import Job, ViewportSession

    the_scene = scene(True, 16)
    session = ViewportSession(lambda: None, make_renderer=lambda spec: Renderer(device))
    session.update_scene(Job(scene=the_scene, settings=dataclasses.replace(GI, samples=8), device_spec=None),
                         signature=("view", 0))
    deadline = time.time() + 60
    while session.busy and time.time() < deadline:
        time.sleep(0.01)
    image, _ = session.latest()
    session.stop()
    assert session.error is None and session.samples == 8
    whole = Renderer(device).render(the_scene, dataclasses.replace(GI, samples=8)).passes["Combined"]
    np.testing.assert_allclose(image, whole, rtol=1e-4, atol=1e-6)
