"""One final gather, saved on one OpenCL device and replayed alone on any:
where GI frames fail on one driver and not on another (README, "On an
NVIDIA H100, a third round"), the same inputs run on both.

    python bench/gather_replay.py save [--device NVIDIA] [--seconds 120] [--watchdog 30]
    python bench/gather_replay.py run LAUNCH [--device cpu] [--samples FIRST END]
                                            [--max-specular K] [--out FILE.npz]
    python bench/gather_replay.py compare A.npz B.npz

``save`` renders the snapshots of ``bench/frame_snapshot.py save`` (box
with torus and Cornell box at Draft and Final, 64² and 256², a new seed
each frame) on --device until --seconds have passed, and before every
gather (``gpu_core.gi.gather.gather_range``: its three kernels and the sort
between them) writes what it is given (each buffer read back whole, each
scalar, the program's defines) to ``.cache/gather_launch.pkl``: when a
kernel of it faults, the file holds it; when one does not end, the
watchdog ends the process after --watchdog seconds with every thread's
stack, and the file holds it too. Without a failure the file is removed.

``run`` runs a saved gather alone on --device, over all its samples or
``--samples FIRST END``, with its own bounce limit or ``--max-specular``,
and prints its time and each output's sums; ``--out`` keeps each sample's
irradiance, harmonic hit distance and hit count. ``compare`` prints where
two such files differ. (A test replays a saved gather against the render
it came from.)
"""

from __future__ import annotations

import argparse
import faulthandler
import os
import pickle
import sys
import time
from dataclasses import fields, replace

import numpy as np
import pyopencl as cl

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from gpu_core.device import get_device  # noqa: E402
from gpu_core.device.device import Device  # noqa: E402
from gpu_core.gi import gather  # noqa: E402

LAUNCH = os.path.join(ROOT, ".cache", "gather_launch.pkl")
SNAPSHOTS = os.path.join(ROOT, ".cache", "snapshots")
JOBS = [("box_torus", "draft", 64), ("box_torus", "draft", 256), ("cornell_box", "final", 256),
        ("box_torus", "final", 128), ("cornell_box", "draft", 64)]


# ---- save ----------------------------------------------------------------------------------


def _host(device: Device, arg):
    """A kernel argument as it can be saved: a buffer's bytes, else itself."""
    if isinstance(arg, cl.MemoryObjectHolder):
        host = np.empty(arg.get_info(cl.mem_info.SIZE), np.uint8)
        cl.enqueue_copy(device.queue, host, arg)
        return ("buffer", host)
    return arg


class LaunchRecorder:
    """While active, every gather (gather.gather_range) first writes its
    inputs to ``path`` (the queue finished before they are read back)."""

    def __init__(self, path: str):
        self.path = path

    def __enter__(self):
        self._gather_range = gather.gather_range
        recorder = self

        def gather_range(device, job, first, end, out, should_stop=None):
            recorder.write(device, job, first, end, out.count)
            return recorder._gather_range(device, job, first, end, out, should_stop)

        gather.gather_range = gather_range
        return self

    def __exit__(self, *exc):
        gather.gather_range = self._gather_range

    def write(self, device: Device, job: gather.GatherJob, first: int, end: int, m: int) -> None:
        device.queue.finish()
        saved = {f.name: getattr(job, f.name) for f in fields(job)}
        saved.update(scene_args=[_host(device, a) for a in job.scene_args],
                     cut_args=[_host(device, a) for a in job.cut_args], positions=_host(device, job.positions),
                     normals=_host(device, job.normals))
        with open(self.path, "wb") as f:
            pickle.dump(dict(job=saved, first=first, end=end, samples=m), f)


def save(device_spec: str | None, seconds: float, watchdog: float) -> None:
    """Frames until --seconds pass, each gather launch saved before it runs."""
    from gpu_core.renderer import Renderer

    device = get_device(device_spec)
    os.makedirs(os.path.dirname(LAUNCH), exist_ok=True)
    began, frame = time.perf_counter(), 0
    with LaunchRecorder(LAUNCH):
        while time.perf_counter() - began < seconds:
            name, preset, size = JOBS[frame % len(JOBS)]
            with open(os.path.join(SNAPSHOTS, f"{name}.pkl"), "rb") as f:
                snapshot = pickle.load(f)
            scene = snapshot["exports"][256]
            scene = replace(scene, camera=replace(scene.camera, width=size, height=size, border=None))
            settings = replace(snapshot["settings"][preset], denoise=False, seed=frame)
            # the first frames compile their programs
            faulthandler.dump_traceback_later(watchdog + (300 if frame < len(JOBS) else 0), exit=True)
            start = time.perf_counter()
            result = Renderer(device).render(scene, settings)
            faulthandler.cancel_dump_traceback_later()
            print(f"frame {frame} {name} {preset} {size}²: {(time.perf_counter() - start) * 1e3:.0f} ms, "
                  f"gather {result.stats['ms'].get('gather', 0.0):.0f} ms", flush=True)
            frame += 1
    os.remove(LAUNCH)
    print(f"{frame} frames, no gather failed", flush=True)


# ---- run and compare ---------------------------------------------------------------------------


def replay(device, launch: dict, first: int | None = None, end: int | None = None,
           max_specular: int | None = None) -> dict:
    """Run a saved gather alone: each sample's outputs (first .. end)."""
    flags = cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR

    def on_device(arg):
        return cl.Buffer(device.context, flags, hostbuf=arg[1]) if isinstance(arg, tuple) else arg

    saved = launch["job"]
    job = gather.GatherJob(**{**saved, "scene_args": [on_device(a) for a in saved["scene_args"]],
                              "cut_args": [on_device(a) for a in saved["cut_args"]],
                              "positions": on_device(saved["positions"]), "normals": on_device(saved["normals"])})
    if max_specular is not None:
        job.max_specular = int(max_specular)
    first = launch["first"] if first is None else first
    end = launch["end"] if end is None else end
    m = launch["samples"]
    out = gather.GatherResult(device, device.empty(16 * m), device.empty(4 * m), device.empty(4 * m),
                              device.empty(48 * m), m)
    gather.gather_range(device, job, first, min(first + 1, end), out)  # builds the programs, untimed
    device.queue.finish()
    began = time.perf_counter()
    gather.gather_range(device, job, first, end, out)
    device.queue.finish()
    seconds = time.perf_counter() - began
    return dict(first=first, end=end, seconds=seconds, irradiance=out.irradiance[first:end],
                distance=out.harmonic_distance[first:end], hits=device.read(out.hits, m, np.int32)[first:end])


def run(path: str, device_spec: str | None, samples, max_specular: int | None, out: str | None) -> None:
    device = get_device(device_spec)
    with open(path, "rb") as f:
        launch = pickle.load(f)
    first, end = samples if samples else (None, None)
    result = replay(device, launch, first, end, max_specular)
    rays = launch["job"]["strata"] ** 2
    print(f"{device.name}: samples {result['first']}..{result['end']} in {result['seconds'] * 1e3:.1f} ms; "
          f"irradiance finite {bool(np.isfinite(result['irradiance']).all())}, sum "
          f"{float(result['irradiance'].sum()):.6g}; rays reaching a diffuse surface "
          f"{result['hits'].sum() / (rays * len(result['hits'])):.5f}")
    if out:
        np.savez(out, **{k: v for k, v in result.items()}, device=device.name)


def compare(a_path: str, b_path: str) -> None:
    a, b = np.load(a_path), np.load(b_path)
    assert int(a["first"]) == int(b["first"]) and int(a["end"]) == int(b["end"]), "not the same samples"
    first = int(a["first"])
    hits = np.flatnonzero(a["hits"] != b["hits"])
    scale = np.maximum(np.abs(a["irradiance"]).max(axis=1), 1e-30)
    rel = np.abs(a["irradiance"] - b["irradiance"]).max(axis=1) / scale
    print(f"{a['device']} against {b['device']}: hit counts differ at {len(hits)} of {len(rel)} samples; "
          f"irradiance rel. difference median {np.median(rel):.2e}, max {rel.max():.2e}")
    for i in np.argsort(-rel)[:10]:
        print(f"  sample {first + i}: hits {a['hits'][i]} / {b['hits'][i]}, irradiance {a['irradiance'][i]} / "
              f"{b['irradiance'][i]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    saving = sub.add_parser("save")
    saving.add_argument("--device", default=None)
    saving.add_argument("--seconds", type=float, default=120.0)
    saving.add_argument("--watchdog", type=float, default=30.0)
    running = sub.add_parser("run")
    running.add_argument("launch")
    running.add_argument("--device", default=None)
    running.add_argument("--samples", nargs=2, type=int, metavar=("FIRST", "END"))
    running.add_argument("--max-specular", type=int)
    running.add_argument("--out")
    comparing = sub.add_parser("compare")
    comparing.add_argument("a")
    comparing.add_argument("b")
    args = parser.parse_args()
    if args.command == "save":
        save(args.device, args.seconds, args.watchdog)
    elif args.command == "run":
        run(args.launch, args.device, args.samples, args.max_specular, args.out)
    else:
        compare(args.a, args.b)


if __name__ == "__main__":
    main()
