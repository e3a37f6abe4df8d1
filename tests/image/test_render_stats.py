"""What a render reports: stage times, the plan, batches, progress and budget errors."""

from types import SimpleNamespace

import numpy as np
import pytest
from scenes_py import camera_looking_down, plane_scene, quad

from gpu_core.errors import BudgetError
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_POINT, Lights
from gpu_core.settings import RenderSettings

SIZE = 24


def lit_plane(**kw):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.3, 0.0, 1.0), power=(40,) * 3)])
    return plane_scene(lights, camera_looking_down(size=SIZE), **kw)


def test_stats_report_each_stage_time_the_plan_and_the_counts(device):
    res = Renderer(device).render(lit_plane(), RenderSettings(samples=2))
    stats = res.stats
    assert list(stats["ms"]) == ["validate", "compile", "kdtree", "upload", "render"]
    assert all(ms >= 0.0 for ms in stats["ms"].values())
    assert stats["plan"] == ["validate", "kdtree", "upload", "direct_light"]
    assert (stats["triangles"], stats["lights"], stats["emissive_triangles"]) == (2, 1, 0)
    assert stats["device"] == device.name and stats["device_bytes"] > 0
    assert stats["dropped_degenerate_triangles"] == 0


def test_plan_lists_only_the_features_the_scene_uses(device):
    features = [
        (dict(base_color=(1, 1, 1), metallic=1.0, roughness=0.0), "specular_paths"),
        (dict(base_color=(1, 1, 1), transmission=1.0, roughness=0.0), "specular_paths"),
        (dict(base_color=(1, 1, 1), alpha=0.5), "alpha_shadows"),
        (dict(base_color=(0, 0, 0), emission=(1, 1, 1)), "mesh_lights"),
    ]
    for material, feature in features:
        scene = lit_plane(extra_tris=[quad((0, 0, 1.5), 0.5, flip=True)], extra_materials=[material])
        plan = Renderer(device).render(scene, RenderSettings(samples=1)).stats["plan"]
        assert feature in plan
        assert [f for _, f in features if f in plan and f != feature] == []
    # a texture is sampled only when a used material refers to it
    scene = lit_plane()
    scene.textures = [np.ones((2, 2, 4), np.float32)]
    assert "textures" not in Renderer(device).render(scene, RenderSettings(samples=1)).stats["plan"]
    scene.materials.texture_id[0] = 0
    assert "textures" in Renderer(device).render(scene, RenderSettings(samples=1)).stats["plan"]


def test_launches_stay_within_batch_pixels_and_batching_does_not_change_the_image(device):
    scene = lit_plane()
    small = Renderer(device).render(scene, RenderSettings(samples=2, batch_pixels=100))
    large = Renderer(device).render(scene, RenderSettings(samples=2, batch_pixels=1 << 20))
    assert small.stats["batches"] >= -(-SIZE * SIZE // 100)
    for name in ("Combined", "Depth", "Normal"):
        np.testing.assert_array_equal(small.passes[name], large.passes[name])


def test_a_shorter_batch_time_splits_the_image_into_more_launches_of_the_same_image(device):
    lights = Lights.make([dict(kind=LIGHT_POINT, position=(0.3, 0.0, 1.0), power=(40,) * 3)])
    scene = plane_scene(lights, camera_looking_down(size=96))
    short = Renderer(device).render(scene, RenderSettings(samples=16, batch_seconds=1e-3))
    long = Renderer(device).render(scene, RenderSettings(samples=16, batch_seconds=10.0))
    assert short.stats["batches"] > long.stats["batches"]
    np.testing.assert_array_equal(short.passes["Combined"], long.passes["Combined"])


def test_progress_rises_to_one_between_batches(device):
    fractions = []
    Renderer(device).render(lit_plane(), RenderSettings(samples=2, batch_pixels=64),
                            progress=lambda fraction, message: fractions.append(fraction))
    assert len(fractions) >= SIZE * SIZE // 64
    assert fractions == sorted(fractions) and fractions[-1] == 1.0


def test_seed_changes_the_noise_but_not_the_mean(device):
    scene = lit_plane(world=(0.3, 0.3, 0.3))
    a = Renderer(device).render(scene, RenderSettings(samples=4, seed=1)).passes["Combined"]
    b = Renderer(device).render(scene, RenderSettings(samples=4, seed=2)).passes["Combined"]
    assert not np.array_equal(a, b)
    assert abs(a[..., :3].mean() / b[..., :3].mean() - 1) < 0.02


def test_settings_are_clamped_to_their_valid_range():
    s = RenderSettings(samples=0, max_bounces=-1, light_samples=0, diffuse_bounces=-3, clamp=-1.0,
                       batch_pixels=0, seed=-1).validated()
    assert (s.samples, s.max_bounces, s.light_samples, s.diffuse_bounces, s.clamp, s.batch_pixels) == (1, 0, 1, 0, 0.0, 1)
    assert s.seed == 0xFFFFFFFF


def test_a_scene_too_large_for_the_device_is_refused_with_a_clear_message():
    tiny = SimpleNamespace(name="tiny device", global_mem_bytes=4096, max_alloc_bytes=1024)
    with pytest.raises(BudgetError, match="tiny device"):
        Renderer(tiny).render(lit_plane(), RenderSettings(samples=1))
