"""gpu_core must work where bpy does not exist."""

import subprocess
import sys

from conftest import ROOT

MODULES = ["gpu_core", "gpu_core.device", "gpu_core.scene", "gpu_core.accel.kdtree", "gpu_core.renderer",
           "gpu_core.device.layout", "gpu_core.settings", "gpu_core.plan", "gpu_core.gi.pipeline"]


def test_gpu_core_imports_and_renders_with_bpy_absent():
    code = (
        "import sys; sys.modules['bpy'] = None\n"  # any 'import bpy' now raises ImportError
        + "".join(f"import {m}\n" for m in MODULES)
        + "assert sys.modules['bpy'] is None\n"
        + "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_gpu_core_sources_never_mention_bpy():
    import pathlib

    for path in pathlib.Path(ROOT, "gpu_core").rglob("*.py"):
        text = path.read_text()
        assert "import bpy" not in text and "from bpy" not in text, path
