"""Adaptive sampling (image.py, image.cl Image_adaptive_active): pixels
stop taking samples once their noise, measured as Cycles measures it, is
below the threshold; noisy pixels and their neighbours go on to the
samples setting."""

import dataclasses

import numpy as np
import pytest
from scenes_py import camera_looking_down, plane_scene, quad

from gpu_core.device.layout import IMAGE_JOB_DTYPE
from gpu_core.image import NOISE_SCALE, adaptive_rounds, film_bytes
from gpu_core.renderer import Renderer
from gpu_core.scene import LIGHT_AREA, LIGHT_POINT, Lights
from gpu_core.settings import RenderSettings

SIZE = 32


def noise_of(combined, even):
    """Cycles' per-pixel noise, on the host."""
    intensity = combined.sum()
    normalise = np.sqrt(intensity) if intensity < 1.0 else intensity
    return np.abs(combined - even).sum() / (1e-4 + normalise)


def active_after(device, combined, even, counts, threshold, limit):
    """Image_noise_of (every pixel just sampled), then Image_adaptive_active,
    over a window of per-pixel means (h, w, 3): the flags and the counter."""
    h, w = combined.shape[:2]
    job = np.zeros(1, IMAGE_JOB_DTYPE)
    job["window"] = (w, h, w * h, 0)
    job["sample_limit"] = limit
    rows = lambda rgb, wv: np.concatenate([rgb, wv[..., None]], -1).reshape(-1, 4).astype(np.float32)
    comb = device.to_device(rows(combined, np.ones((h, w))))
    film = device.to_device(rows(even, counts.astype(np.float64)))
    active, noise, counter = device.empty(4 * w * h), device.empty(4 * w * h), device.zeros(4)
    device.fill(active, 1, 4 * w * h)
    device.kernel("image.cl", "Image_noise_of", {})(w * h, job, comb, film, active, noise)
    device.kernel("image.cl", "Image_adaptive_active", {})(w * h, job, noise, film, np.float32(threshold), active,
                                                           counter)
    return device.read(active, (h, w), np.int32), int(device.read(counter, 1, np.int32)[0])


def test_noise_measure_matches_cycles_formula_on_both_sides_of_the_threshold(device):
    # dim pixel (normalised by the square root of its brightness) and bright one (by the brightness)
    for level in (0.25, 0.9):
        combined = np.full((1, 1, 3), level)
        even = combined + np.array([0.01, -0.02, 0.005])
        error = noise_of(combined[0, 0], even[0, 0])
        above, count_above = active_after(device, combined, even, np.full((1, 1), 4), error * 0.999, 16)
        below, count_below = active_after(device, combined, even, np.full((1, 1), 4), error * 1.001, 16)
        assert (above[0, 0], count_above, below[0, 0], count_below) == (1, 1, 0, 0)


def test_a_noisy_pixel_keeps_its_3x3_neighbourhood_sampling_until_the_limit(device):
    h, w = 5, 6
    combined = np.full((h, w, 3), 0.5)
    even = combined.copy()
    even[2, 3] += 0.2  # one noisy pixel
    counts = np.full((h, w), 8)
    active, count = active_after(device, combined, even, counts, 0.05, 16)
    expected = np.zeros((h, w), np.int32)
    expected[1:4, 2:5] = 1
    np.testing.assert_array_equal(active, expected)
    assert count == 9
    # a neighbour already at the sample limit takes no more
    counts[1, 2] = 16
    active, count = active_after(device, combined, even, counts, 0.05, 16)
    assert active[1, 2] == 0 and count == 8
    # a noisy pixel at the window's corner: its neighbourhood is clipped to the window
    even = combined.copy()
    even[0, 0] += 0.2
    active, count = active_after(device, combined, even, np.full((h, w), 8), 0.05, 16)
    assert count == 4 and active[:2, :2].all()


def test_only_the_pixels_that_took_samples_have_their_noise_measured_again(device):
    h, w = 4, 5
    rng = np.random.default_rng(2)
    combined, even = rng.uniform(0.1, 2.0, (h, w, 3)), rng.uniform(0.1, 2.0, (h, w, 3))
    job = np.zeros(1, IMAGE_JOB_DTYPE)
    job["window"] = (w, h, w * h, 0)
    rows = lambda rgb: np.concatenate([rgb, np.ones((h, w, 1))], -1).reshape(-1, 4).astype(np.float32)
    sampled = (np.indices((h, w)).sum(axis=0) % 2).astype(np.int32)  # a checkerboard took the round
    noise = device.to_device(np.full(h * w, -1.0, np.float32))
    device.kernel("image.cl", "Image_noise_of", {})(w * h, job, device.to_device(rows(combined)),
                                                    device.to_device(rows(even)), device.to_device(sampled), noise)
    kept = device.read(noise, (h, w), np.float32)
    expected = np.array([[noise_of(combined[y, x], even[y, x]) for x in range(w)] for y in range(h)])
    np.testing.assert_allclose(kept[sampled == 1], expected[sampled == 1], rtol=1e-5)
    assert (kept[sampled == 0] == -1.0).all()


def lit_plane(light):
    return plane_scene(Lights.make([light]), camera_looking_down(size=SIZE))


POINT = dict(kind=LIGHT_POINT, position=(0.3, 0.0, 1.0), power=(40,) * 3)


def area_light(side):
    """A square light of `side` facing down, 1.5 above the plane."""
    return dict(kind=LIGHT_AREA, position=(0.0, 0.0, 1.5), power=(60.0,) * 3, direction=(0, 0, -1),
                axis_u=(side, 0, 0), axis_v=(0, side, 0), shape=0)


@pytest.mark.parametrize("border", [None, (5, 3, 29, 20)])
def test_a_loose_threshold_stops_every_pixel_at_min_samples_with_the_same_image(device, border):
    scene = lit_plane(POINT)
    scene.camera = dataclasses.replace(scene.camera, border=border)  # a render window too
    adaptive = Renderer(device).render(scene, RenderSettings(samples=16, min_samples=4, noise_threshold=1.0,
                                                              denoising_passes=True, light_passes=True))
    plain = Renderer(device).render(scene, RenderSettings(samples=4, denoising_passes=True, light_passes=True))
    stats = adaptive.stats["adaptive"]
    assert stats["mean_samples"] == 4.0 and stats["stopped_early"] == 1.0 and stats["rounds"] == 1
    for name, values in plain.passes.items():
        np.testing.assert_array_equal(adaptive.passes[name], values, err_msg=name)


def test_a_tight_threshold_takes_every_sample_and_matches_the_full_render(device):
    # soft shadows of an area light: noisy everywhere at these counts
    scene = lit_plane(area_light(1.0))
    adaptive = Renderer(device).render(scene, RenderSettings(samples=16, min_samples=4, noise_threshold=1e-7,
                                                              light_passes=True))
    plain = Renderer(device).render(scene, RenderSettings(samples=16, light_passes=True))
    stats = adaptive.stats["adaptive"]
    assert stats["mean_samples"] == 16.0 and stats["stopped_early"] == 0.0 and stats["rounds"] == 4
    for name, values in plain.passes.items():
        # the same samples, their means merged round by round
        np.testing.assert_allclose(adaptive.passes[name], values, rtol=2e-5, atol=1e-6, err_msg=name)


def test_samples_go_to_the_noisy_part_and_beat_uniform_sampling_at_the_same_mean_count(device):
    # a blocker under a small area light: a penumbra around its shadow, flat light elsewhere
    blocker = quad((0.0, 0.0, 0.5), 0.3)
    scene = plane_scene(Lights.make([area_light(0.3)]), camera_looking_down(size=SIZE), extra_tris=[blocker],
                        extra_materials=[{"base_color": (0.8, 0.8, 0.8), "name": "blocker"}])
    result = Renderer(device).render(scene, RenderSettings(samples=64, min_samples=8, noise_threshold=0.01))
    stats = result.stats["adaptive"]
    assert 8.0 < stats["mean_samples"] < 32.0 and 0.0 < stats["stopped_early"] < 1.0
    # error against a converged image: well below that of every pixel taking the mean count
    converged = Renderer(device).render(scene, RenderSettings(samples=2048, seed=9)).passes["Combined"][..., :3]
    uniform = Renderer(device).render(scene, RenderSettings(samples=int(np.ceil(stats["mean_samples"]))))

    def error(result):
        return np.sqrt(np.mean((result.passes["Combined"][..., :3] - converged) ** 2))

    assert error(result) < 0.6 * error(uniform)


@pytest.mark.parametrize("threshold, min_samples, samples, expected", [
    (0.0, 0, 64, None),  # no threshold: off
    (0.01, 0, 64, (16, 16)),  # a quarter of the samples first
    (0.01, 0, 8, (4, 4)),  # at least 4
    (0.01, 8, 8, None),  # a minimum of every sample: off
    (0.01, 4, 1024, (4, 64)),  # rounds of at least samples / 16
])
def test_rounds_follow_min_samples_and_the_samples_setting(threshold, min_samples, samples, expected):
    settings = RenderSettings(samples=samples, min_samples=min_samples, noise_threshold=threshold).validated()
    assert adaptive_rounds(settings) == expected


def test_film_memory_counts_the_adaptive_buffers_and_the_threshold_matches_cycles_scale():
    window = (0, 0, 10, 10)
    plain, adaptive = RenderSettings(samples=16), RenderSettings(samples=16, noise_threshold=0.01)
    assert film_bytes(window, adaptive) - film_bytes(window, plain) == 100 * 20
    assert NOISE_SCALE == 5.0
    # out-of-range values are clamped, not trusted
    assert RenderSettings(noise_threshold=-1.0).validated().noise_threshold == 0.0
    assert RenderSettings(min_samples=-3).validated().min_samples == 0


@pytest.mark.parametrize("power", [1e-6, 1e6])
def test_dim_and_blinding_lights_stay_finite_and_within_the_sample_bounds(device, power):
    light = dict(area_light(0.3), power=(power,) * 3)
    scene = plane_scene(Lights.make([light]), camera_looking_down(size=SIZE), extra_tris=[quad((0.0, 0.0, 0.5), 0.3)],
                        extra_materials=[{"base_color": (0.8, 0.8, 0.8), "name": "blocker"}])
    result = Renderer(device).render(scene, RenderSettings(samples=32, min_samples=8, noise_threshold=0.01))
    assert np.isfinite(result.passes["Combined"]).all()
    assert 8.0 <= result.stats["adaptive"]["mean_samples"] <= 32.0
    # above a brightness of 1 the noise is taken relative to the brightness itself (overexposed,
    # as Cycles takes it): a blinding light stops pixels no later than the usual one
    if power > 1.0:
        reference = Renderer(device).render(dataclasses.replace(scene, lights=Lights.make([area_light(0.3)])),
                                            RenderSettings(samples=32, min_samples=8, noise_threshold=0.01))
        assert result.stats["adaptive"]["mean_samples"] <= reference.stats["adaptive"]["mean_samples"]
