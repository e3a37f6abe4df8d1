"""One-line summaries of a render's stats for Blender's status bar and the command line."""

from __future__ import annotations


def mode_line(stats: dict) -> str:
    """The mode that rendered, and the one asked for when it fell back."""
    mode, requested = stats.get("mode", "reference"), stats.get("mode_requested", "reference")
    return mode if mode == requested else f"{requested} not built yet, rendered as {mode}"


def format_stage_times(ms: dict) -> str:
    """'export 3 ms, kdtree 25 ms, ...' in the order the stages ran."""
    return ", ".join(f"{name} {value:.0f} ms" for name, value in ms.items())
