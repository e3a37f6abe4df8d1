"""One-line summaries of a render's stats for Blender's status bar and the command line."""

from __future__ import annotations


def mode_line(stats: dict) -> str:
    """The mode that rendered."""
    return stats.get("mode", "reference")


def format_stage_times(ms: dict) -> str:
    """'export 3 ms, kdtree 25 ms, ...' in the order the stages ran."""
    return ", ".join(f"{name} {value:.0f} ms" for name, value in ms.items())


def format_transfers(transfers: dict) -> str:
    """'to device 12.3 MB, to host 1.0 MB'."""
    return f"to device {transfers['to_device'] / 1e6:.1f} MB, to host {transfers['to_host'] / 1e6:.1f} MB"


def format_samples(stats: dict) -> str:
    """'16 per pixel', or with adaptive sampling 'adaptive, 24.6 per pixel of
    64 (84% of pixels stopped early)'."""
    adaptive = stats.get("adaptive")
    if not adaptive:
        return f"{stats.get('samples', 0)} per pixel"
    return (f"adaptive, {adaptive['mean_samples']:.1f} per pixel of {stats.get('samples', 0)} "
            f"({100 * adaptive['stopped_early']:.0f}% of pixels stopped early)")
