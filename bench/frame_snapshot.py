"""One frame on any OpenCL device, without Blender: scenes exported once through
bpy, rendered wherever pyopencl runs.

A GPU machine need not have Blender (the bpy module needs Python 3.11), so
this benchmark comes in two halves:

    python bench/frame_snapshot.py save [--scenes ...] [--sizes 256 512]
    python bench/frame_snapshot.py run [--device gpu] [--repeats 3] [--tag TAG] [--watchdog S]

``save`` (with bpy) writes, for each scene of ``blend_scenes/``, the add-on's
own export of the scene (F12's: ``export_scene``) at each size and the
add-on's settings of each preset in GI mode, pickled into
``.cache/snapshots/NAME.pkl`` (plain gpu_core dataclasses and numpy arrays).

``run`` (numpy and pyopencl only) renders every snapshot through gpu_core's
Renderer on ``--device`` (a fresh renderer per render, as F12 has): one
warm-up, then the median of ``--repeats`` of the render call's wall time and
of each stage's milliseconds (the render's stats; the export is not in
them). Also, per scene at its first size: the image kernel's camera paths
per second in Reference mode at 16 samples, direct light only and with deep
bounces (12 and 12), on the kernel's own time; and for ``--cold-scenes``
the first Preview frame of a fresh process with every kernel cache empty
(ours, PoCL's and NVIDIA's). ``--no-denoise`` renders without the denoiser.
A measurement (one scene, size and preset, or one paths-per-second figure)
that takes longer than ``--watchdog`` seconds ends the process with the
stack of every thread, so a build or kernel that does not end shows where.
Writes bench/results/frame_snapshot[_TAG].json and .txt.
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from frame import stage_line  # noqa: E402  (frame.py loads Blender only when run)
from machine import describe  # noqa: E402

SNAPSHOTS = os.path.join(ROOT, ".cache", "snapshots")
PRESETS = ("draft", "preview", "final")
RESULTS = os.path.join(ROOT, "bench", "results")


# ---- save (bpy) ----------------------------------------------------------------------------


def save(scenes: list[str], sizes: list[int]) -> None:
    """Pickle the add-on's export and per-preset settings of each scene and size."""
    from bpy_render import load_bpy, open_scene

    bpy = load_bpy()
    from blender_addon.export import export_scene

    os.makedirs(SNAPSHOTS, exist_ok=True)
    for name in scenes:
        exports, settings = {}, {}
        for size in sizes:
            scene = open_scene(bpy, name, size)
            for preset in PRESETS:
                scene.gpugi.mode = "GI"
                scene.gpugi.preset = preset.upper()
                settings[preset] = scene.gpugi.render_settings(transparent=scene.render.film_transparent)
            exported = export_scene(bpy.context.evaluated_depsgraph_get())
            # the sizes differ in the camera only: the file holds the rest once
            exports[size] = exported if not exports else replace(next(iter(exports.values())), camera=exported.camera)
        path = os.path.join(SNAPSHOTS, f"{name}.pkl")
        with open(path, "wb") as f:
            pickle.dump(dict(scene=name, exports=exports, settings=settings), f)
        print(f"{path}: {exported.triangle_count} triangles, {os.path.getsize(path) / 2**20:.1f} MiB")


# ---- run (numpy and pyopencl) --------------------------------------------------------------


def load(path: str) -> dict:
    with open(path, "rb") as f:
        return pickle.load(f)


def render_once(device, scene, settings) -> tuple[float, dict]:
    """A fresh renderer's render call: its wall seconds and stage milliseconds."""
    from gpu_core.renderer import Renderer

    began = time.perf_counter()
    result = Renderer(device).render(scene, settings)
    return time.perf_counter() - began, result.stats["ms"]


def timed(device, scene, settings, repeats: int) -> dict:
    """Median wall seconds and stage milliseconds after a warm-up render."""
    runs = [render_once(device, scene, settings) for _ in range(repeats + 1)][1:]
    keys = list(dict.fromkeys(key for _, ms in runs for key in ms))
    return dict(seconds=statistics.median(s for s, _ in runs),
                ms={key: statistics.median(ms.get(key, 0.0) for _, ms in runs) for key in keys})


def paths_per_second(device, scene, settings, direct_only: bool, repeats: int) -> float:
    """Millions of camera paths per second of the image kernel (Reference mode, 16 samples)."""
    bounces = 0 if direct_only else 12
    settings = replace(settings, mode="reference", samples=16, max_bounces=bounces, diffuse_bounces=bounces)
    kernel = timed(device, scene, settings, repeats)["ms"]["render"] / 1e3
    return scene.camera.width * scene.camera.height * 16 / 1e6 / kernel


def cold(path: str, size: int, device_spec: str | None, no_denoise: bool) -> dict:
    """A fresh process's first Preview frame with every kernel cache empty."""
    with tempfile.TemporaryDirectory() as caches:
        env = dict(os.environ, POCL_CACHE_DIR=os.path.join(caches, "pocl"), CUDA_CACHE_DISABLE="1",
                   GPUGI_KERNEL_CACHE=os.path.join(caches, "kernels"))
        began = time.perf_counter()
        spec = ([] if device_spec is None else ["--device", device_spec]) + (["--no-denoise"] if no_denoise else [])
        run = subprocess.run([sys.executable, os.path.abspath(__file__), "first-frame", path, str(size), *spec],
                             env=env, capture_output=True, text=True, timeout=1800)
        seconds = time.perf_counter() - began
    if run.returncode != 0:
        raise RuntimeError(f"first frame of {path}: {run.stderr[-2000:]}")
    return dict(process_seconds=seconds, **json.loads(run.stdout.strip().splitlines()[-1]))


def first_frame(path: str, size: int, device_spec: str | None, no_denoise: bool) -> None:
    """(In the fresh process) one Preview render; prints its time and stages."""
    from gpu_core.device import get_device

    snapshot = load(path)
    settings = snapshot["settings"]["preview"]
    if no_denoise:
        settings = replace(settings, denoise=False)
    seconds, ms = render_once(get_device(device_spec), snapshot["exports"][size], settings)
    print(json.dumps(dict(seconds=seconds, ms=ms)))


def guarded(seconds: float, measure, *args):
    """``measure(*args)``, ending the process with every thread's stack
    (faulthandler, which needs no interpreter lock) after ``seconds``."""
    faulthandler.dump_traceback_later(seconds, exit=True)
    try:
        return measure(*args)
    finally:
        faulthandler.cancel_dump_traceback_later()


def run(device_spec: str | None, repeats: int, tag: str, presets: list[str], scenes: list[str] | None,
        cold_scenes: list[str], no_denoise: bool, watchdog: float) -> None:
    """Render every snapshot; print and write the figures."""
    from gpu_core.device import get_device

    device = get_device(device_spec)
    if device.fallback_message:  # the device asked for is not there: measure nothing else
        sys.exit(device.fallback_message)
    lines = [f"machine: {describe(device)}; GI mode; medians of {repeats} warm renders; export not included"]
    print(lines[0], flush=True)
    paths = sorted(os.path.join(SNAPSHOTS, name) for name in os.listdir(SNAPSHOTS)
                   if name.endswith(".pkl") and (scenes is None or name[:-4] in scenes))
    rows, firsts, rates = [], [], []

    def say(line: str) -> None:
        print(line, flush=True)
        lines.append(line)

    for path in paths:
        snapshot = load(path)
        name, settings = snapshot["scene"], snapshot["settings"]
        if no_denoise:
            settings = {preset: replace(chosen, denoise=False) for preset, chosen in settings.items()}
        for index, (size, scene) in enumerate(sorted(snapshot["exports"].items())):
            if index == 0:
                if name in cold_scenes:
                    first = cold(path, size, device_spec, no_denoise)
                    firsts.append(dict(scene=name, size=size, **first))
                    say(f"{name} {size} first frame, empty caches: process {first['process_seconds']:.1f} s, "
                        f"render {first['seconds']:.2f} s ({stage_line(first['ms'])})")
                for direct_only in (True, False):
                    rate = guarded(watchdog, paths_per_second, device, scene, settings["preview"], direct_only,
                                   repeats)
                    rates.append(dict(scene=name, size=size, direct_only=direct_only, mpaths=rate))
                    say(f"{name} {size} image kernel, {'direct light' if direct_only else 'deep bounces'}, "
                        f"16 spp: {rate:.2f} M paths/s")
            for preset in presets:
                result = guarded(watchdog, timed, device, scene, settings[preset], repeats)
                rows.append(dict(scene=name, size=size, preset=preset, **result))
                say(f"{name} {size} {preset}: {result['seconds'] * 1e3:.0f} ms; {stage_line(result['ms'])}")
    os.makedirs(RESULTS, exist_ok=True)
    stem = os.path.join(RESULTS, "frame_snapshot" + (f"_{tag}" if tag else ""))
    with open(stem + ".json", "w") as f:
        json.dump(dict(machine=lines[0], rows=rows, first_frames=firsts, paths=rates), f, indent=1)
    with open(stem + ".txt", "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {stem}.json and .txt")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = parser.add_subparsers(dest="verb", required=True)
    scenes = sorted(name[:-6] for name in os.listdir(os.path.join(ROOT, "blend_scenes")) if name.endswith(".blend"))
    saving = verbs.add_parser("save", help="export the scenes through bpy into .cache/snapshots/")
    saving.add_argument("--scenes", nargs="+", default=scenes, choices=scenes)
    saving.add_argument("--sizes", nargs="+", type=int, default=[256, 512])
    running = verbs.add_parser("run", help="render the snapshots on an OpenCL device")
    running.add_argument("--device", default=None,
                         help="OpenCL device spec (default: GPUGI_DEVICE or the automatic choice)")
    running.add_argument("--scenes", nargs="+", help="only these scenes (default: every snapshot)")
    running.add_argument("--cold-scenes", nargs="*", default=["cornell_box"],
                         help="scenes whose first frame with empty caches is timed (default: the Cornell box)")
    running.add_argument("--repeats", type=int, default=3)
    running.add_argument("--presets", nargs="+", default=list(PRESETS), choices=PRESETS)
    running.add_argument("--no-denoise", action="store_true",
                         help="render without the denoiser (the scenes' Denoise setting otherwise)")
    running.add_argument("--tag", default="", help="suffix of the output files")
    running.add_argument("--watchdog", type=float, default=600.0,
                         help="seconds one measurement may take before the process ends with every thread's stack")
    first = verbs.add_parser("first-frame", help=argparse.SUPPRESS)
    first.add_argument("path")
    first.add_argument("size", type=int)
    first.add_argument("--device", default=None)
    first.add_argument("--no-denoise", action="store_true")
    args = parser.parse_args()
    if args.verb == "save":
        save(args.scenes, args.sizes)
    elif args.verb == "run":
        run(args.device, args.repeats, args.tag, args.presets, args.scenes, args.cold_scenes, args.no_denoise,
            args.watchdog)
    else:
        first_frame(args.path, args.size, args.device, args.no_denoise)


if __name__ == "__main__":
    main()
