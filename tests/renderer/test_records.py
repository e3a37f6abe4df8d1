"""Irradiance records kept in world space across views of one lit scene:
a new view interpolates from them and chooses and gathers new cache points
only where they leave its shading points uncovered."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_threads import GI, scene

import gpu_core.renderer as renderer_module
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights

SETTINGS = dataclasses.replace(GI, cache_seeds=200, gather_rays=64, samples=4)


def _views(shift: float = 0.2):
    first, moved = scene(True, 48), scene(True, 48)
    moved.camera.matrix[0, 3] += shift
    return first, moved


def test_a_new_view_keeps_the_records_and_gathers_only_where_they_leave_gaps(device):
    first, moved = _views()
    renderer = Renderer(device)
    before = renderer.render(first, SETTINGS)
    after = renderer.render(moved, SETTINGS)
    records = after.stats["gi"]["records"]
    assert "cache_records_reused" in after.stats["plan"] and after.stats["gi"]["photons_reused"]
    assert records["kept"] == before.stats["gi"]["records"]["new"] == before.stats["gi"]["sample_points"]
    assert records["uncovered"] < 0.05 and records["new"] < 0.1 * SETTINGS.cache_seeds
    # the image is the fresh render's up to the choice of cache points (measured: mean 0.3%, p95 5%)
    fresh = Renderer(device).render(moved, SETTINGS).passes["Combined"][..., :3]
    kept = after.passes["Combined"][..., :3]
    assert abs(kept.mean() / fresh.mean() - 1.0) < 0.02
    assert np.percentile(np.abs(kept - fresh) / np.maximum(fresh, 1e-3), 95) < 0.1


def test_a_coarse_pass_after_a_full_one_reads_its_denser_records(device):
    # the viewport's coarse pass (a 16th of the cache points) after a full
    # pass of another view: the full pass's records cover it
    first, moved = _views()
    coarse = dataclasses.replace(SETTINGS, cache_seeds=SETTINGS.cache_seeds // 16)
    renderer = Renderer(device)
    before = renderer.render(first, SETTINGS)
    after = renderer.render(moved, coarse)
    records = after.stats["gi"]["records"]
    assert "cache_records_reused" in after.stats["plan"]
    assert records["kept"] == before.stats["gi"]["sample_points"] > coarse.cache_seeds
    assert records["new"] <= coarse.cache_seeds
    fresh = Renderer(device).render(moved, SETTINGS).passes["Combined"][..., :3]
    kept = after.passes["Combined"][..., :3]
    assert np.isfinite(kept).all() and abs(kept.mean() / fresh.mean() - 1.0) < 0.02


def test_with_reuse_off_every_view_is_the_fresh_render(device):
    first, moved = _views()
    off = dataclasses.replace(SETTINGS, cache_reuse=False)
    renderer = Renderer(device)
    renderer.render(first, off)
    after = renderer.render(moved, off)
    assert "cache_records_reused" not in after.stats["plan"]
    np.testing.assert_array_equal(after.passes["Combined"], Renderer(device).render(moved, off).passes["Combined"])


def test_an_edit_of_the_lit_scene_drops_the_records(device):
    first, moved = _views()
    brighter = dataclasses.replace(moved, lights=Lights.make([dict(kind=LIGHT_POINT, position=(0.2, 0.1, 0.5),
                                                                   power=(300,) * 3)]))
    renderer = Renderer(device)
    renderer.render(first, SETTINGS)
    after = renderer.render(brighter, SETTINGS)
    assert "cache_records_reused" not in after.stats["plan"] and after.stats["gi"]["records"]["kept"] == 0
    assert after.stats["gi"]["records"]["new"] == after.stats["gi"]["sample_points"]
    # every point is gathered again; k-means starts from the last view's cache points (test_held_samples.py)
    assert after.stats["gi"]["selection"]["warm_start"]
    fresh = Renderer(device).render(brighter, SETTINGS).passes["Combined"][..., :3]
    kept = after.passes["Combined"][..., :3]
    assert abs(kept.mean() / fresh.mean() - 1.0) < 0.02
    assert np.percentile(np.abs(kept - fresh) / np.maximum(fresh, 1e-3), 95) < 0.1


def test_records_beyond_the_cap_are_not_held_and_the_next_view_starts_afresh(device, monkeypatch):
    first, moved = _views()
    monkeypatch.setattr(renderer_module, "RECORDS_CAP", 0)
    renderer = Renderer(device)
    renderer.render(first, SETTINGS)
    assert "cache_records_reused" not in renderer.render(moved, SETTINGS).stats["plan"]


@pytest.mark.parametrize("shift", [0.05, 0.5])
def test_kept_records_give_finite_irradiance_everywhere(device, shift):
    first, moved = _views(shift)
    renderer = Renderer(device)
    renderer.render(first, SETTINGS)
    image = renderer.render(moved, SETTINGS).passes["Combined"]
    assert np.isfinite(image).all() and image[..., :3].min() >= 0.0
