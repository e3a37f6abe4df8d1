"""The one-line summaries of a render's stats (blender_addon/status.py)."""

from blender_addon.status import format_samples, format_stage_times


def test_samples_line_says_fixed_counts_and_adaptive_means():
    assert format_samples({"samples": 16}) == "16 per pixel"
    adaptive = {"samples": 64, "adaptive": {"mean_samples": 24.64, "stopped_early": 0.843}}
    assert format_samples(adaptive) == "adaptive, 24.6 per pixel of 64 (84% of pixels stopped early)"


def test_stage_times_keep_the_order_the_stages_ran():
    assert format_stage_times({"kdtree": 25.4, "render": 3.0}) == "kdtree 25 ms, render 3 ms"
