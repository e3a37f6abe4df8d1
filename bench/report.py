"""Where a benchmark leaves what it measured: bench/results/NAME.json (the
figures) and NAME.txt (the lines it printed)."""

from __future__ import annotations

import json
import os

from bpy_render import ROOT

RESULTS = os.path.join(ROOT, "bench", "results")


def write_results(name: str, data, lines: list[str]) -> None:
    """bench/results/NAME.json with ``data`` and NAME.txt with ``lines``."""
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, f"{name}.json"), "w") as f:
        json.dump(data, f, indent=1)
    with open(os.path.join(RESULTS, f"{name}.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
