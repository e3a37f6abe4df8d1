"""Where one frame's time goes on a device: kernels, launches, blocking reads
and allocations, per module of gpu_core, without Blender.

    python bench/frame_profile.py [--device gpu] [--scene cornell_box] [--preset preview] [--size 256] [--gpu-paths]
                                  [--orbit DEGREES]

Renders a snapshot of ``bench/frame_snapshot.py save`` (``.cache/snapshots/``)
through gpu_core's Renderer on a queue with profiling on: one warm-up
render, then a measured one. Per module (the innermost frame of gpu_core
outside ``device/`` that launched or read), it reports: kernel launches and
the host time spent enqueueing them, the kernels' own time on the device
(their profiling events: start to end), the device's idle time before
them (since every kernel before had ended: the host's turn between
kernels, after a blocking read or between launches), blocking reads and
the host time spent waiting in them (which includes every kernel queued
before), reads queued without blocking (``Device.read_later``: waited on
once more work is queued) and the host's wait on them, and device
allocations and their host time. Launches pyopencl makes itself (its scan
and sort kernels) are counted in the reads' waits, not in the kernels'
time. The render's wall time and its stages come last: where the kernels'
own time is a small part of the wall, the frame is launch- and read-bound.
``--gpu-paths`` makes gpu_core take a GPU's paths on any device (the
kd-tree built level by level, small point trees by a work-group, no leaf
blocks), so that a CPU counts the launches and reads a GPU frame makes.
``--orbit DEGREES`` profiles what the viewport's commonest edit costs
instead: one renderer renders the view, then the view turned DEGREES about
the vertical axis through the scene's centre (measured), as a held
renderer does after an orbit (the kd-tree, photon maps and cut kept, the
cache records of the view before reused where they cover).
Writes bench/results/frame_profile[_TAG].json and .txt.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np
import pyopencl as cl

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from frame_snapshot import SNAPSHOTS, load  # noqa: E402
from machine import describe  # noqa: E402

from gpu_core.device import Device, get_device  # noqa: E402
from gpu_core.device.device import PendingRead  # noqa: E402
from gpu_core.device import kernels as kernels_module  # noqa: E402
from gpu_core.renderer import Renderer  # noqa: E402

RESULTS = os.path.join(ROOT, "bench", "results")


def caller() -> str:
    """The innermost gpu_core frame outside device/ on the stack: 'module:function'
    (past a module's own launch wrapper, such as the point-tree build's, to the function that called it)."""
    frame = sys._getframe(2)
    while frame is not None:
        path = frame.f_code.co_filename
        outer = frame.f_back
        wrapper = frame.f_code.co_name == "launch" and outer is not None and outer.f_code.co_filename == path
        path = path.replace(os.sep, "/")
        if "/gpu_core/" in path and "/gpu_core/device/" not in path and not wrapper:
            return f"{path.split('/gpu_core/')[1]}:{frame.f_code.co_name}"
        frame = outer
    return "other"


class Profile:
    """Counters per module while installed: launches, reads, allocations."""

    def __init__(self):
        self.rows = collections.defaultdict(lambda: collections.Counter())
        self.events: list[tuple[str, str, cl.Event]] = []
        self.active = False

    def install(self) -> None:
        """Wrap the launch helper, blocking copies, waits on queued reads and buffer creation."""
        enqueue, copy, buffer, wait = cl.enqueue_nd_range_kernel, cl.enqueue_copy, Device.empty, PendingRead.wait
        profile = self

        def timed_enqueue(queue, kernel, *args, **kw):
            began = time.perf_counter()
            event = enqueue(queue, kernel, *args, **kw)
            if profile.active:
                ms, where = (time.perf_counter() - began) * 1e3, caller()
                profile.rows[where]["launches"] += 1
                profile.rows[where]["launch_ms"] += ms
                profile.events.append((where, kernel.function_name, event))
            return event

        def timed_copy(queue, dst, src, **kw):
            began = time.perf_counter()
            event = copy(queue, dst, src, **kw)
            if profile.active and isinstance(dst, np.ndarray) and kw.get("is_blocking", True):
                ms, where = (time.perf_counter() - began) * 1e3, caller()
                profile.rows[where]["reads"] += 1
                profile.rows[where]["read_wait_ms"] += ms
            return event

        def timed_wait(pending):
            began = time.perf_counter()
            values = wait(pending)
            if profile.active:
                ms, where = (time.perf_counter() - began) * 1e3, caller()
                profile.rows[where]["queued_reads"] += 1
                profile.rows[where]["queued_wait_ms"] += ms
            return values

        def timed_empty(device, nbytes):
            began = time.perf_counter()
            made = buffer(device, nbytes)
            if profile.active:
                ms, where = (time.perf_counter() - began) * 1e3, caller()
                profile.rows[where]["allocations"] += 1
                profile.rows[where]["allocation_ms"] += ms
            return made

        kernels_module.cl.enqueue_nd_range_kernel = timed_enqueue
        cl.enqueue_copy = timed_copy
        Device.empty = timed_empty
        PendingRead.wait = timed_wait

    def kernel_times(self) -> dict:
        """The device time of every recorded kernel, per module and per kernel
        name (ms); and per module the device's idle time before the kernels
        it launched (from the end of every kernel before to the start)."""
        per_kernel = collections.Counter()
        for where, name, event in self.events:
            ms = (event.profile.end - event.profile.start) * 1e-6
            self.rows[where]["kernel_ms"] += ms
            per_kernel[name] += ms
        done = None
        for where, _name, event in sorted(self.events, key=lambda e: e[2].profile.start):
            if done is not None and event.profile.start > done:
                self.rows[where]["idle_before_ms"] += (event.profile.start - done) * 1e-6
            done = event.profile.end if done is None else max(done, event.profile.end)
        return dict(per_kernel.most_common())


def profiling_device(spec: str | None) -> Device:
    """The device of ``spec`` with a queue that records kernel times."""
    plain = get_device(spec)
    queue = cl.CommandQueue(plain.context, properties=cl.command_queue_properties.PROFILING_ENABLE)
    return Device(context=plain.context, queue=queue, device=plain.device)


def orbited(scene, degrees: float):
    """The scene with its camera turned ``degrees`` about the vertical (z)
    axis through the centre of its triangles' box, as the viewport's orbit."""
    lo, hi = scene.triangles.reshape(-1, 3).min(axis=0), scene.triangles.reshape(-1, 3).max(axis=0)
    a = np.radians(degrees)
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    to_center, back = np.eye(4), np.eye(4)
    to_center[:3, 3], back[:3, 3] = -(lo + hi) / 2, (lo + hi) / 2
    camera = replace(scene.camera, matrix=back @ turn @ to_center @ np.asarray(scene.camera.matrix, np.float64))
    return replace(scene, camera=camera)


def table(rows: dict) -> str:
    """Per-module rows, the costliest first."""
    columns = ("launches", "launch_ms", "kernel_ms", "idle_before_ms", "reads", "read_wait_ms", "queued_reads",
               "queued_wait_ms", "allocations", "allocation_ms")
    lines = ["| module | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    cost = lambda r: (r["launch_ms"] + r["idle_before_ms"] + r["read_wait_ms"] + r["queued_wait_ms"]  # noqa: E731
                      + r["allocation_ms"])
    for where, row in sorted(rows.items(), key=lambda item: -cost(item[1])):
        cells = [f"{row[c]:.2f}" if c.endswith("_ms") else str(int(row[c])) for c in columns]
        lines.append(f"| {where} | " + " | ".join(cells) + " |")
    totals = [sum(r[c] for r in rows.values()) for c in columns]
    lines.append("| total | " + " | ".join(f"{t:.2f}" if c.endswith("_ms") else str(int(t))
                                          for c, t in zip(columns, totals)) + " |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="OpenCL device spec (default: GPUGI_DEVICE, else the CPU)")
    parser.add_argument("--scene", default="cornell_box")
    parser.add_argument("--preset", default="preview", choices=("draft", "preview", "final"))
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--tag", default="")
    parser.add_argument("--gpu-paths", action="store_true",
                        help="take the paths a GPU takes (the kd-tree built level by level, small point trees by "
                             "a work-group, no leaf blocks) on any device, to count what a GPU frame launches and "
                             "reads back without one")
    parser.add_argument("--orbit", type=float, default=None, metavar="DEGREES",
                        help="profile a held renderer's frame after the view turned this much about the vertical "
                             "axis (the viewport's orbit), not a fresh renderer's first frame")
    args = parser.parse_args()
    if args.gpu_paths:
        Device.is_cpu = property(lambda device: False)

    snapshot = load(os.path.join(SNAPSHOTS, f"{args.scene}.pkl"))
    scene, settings = snapshot["exports"][args.size], replace(snapshot["settings"][args.preset], denoise=False)
    device = profiling_device(args.device)
    about = describe(device)
    Renderer(device).render(scene, settings)  # warm-up: programs built, launch shapes seen
    renderer, measured = Renderer(device), scene
    if args.orbit is not None:  # the view before the orbit, rendered by the renderer measured
        renderer.render(scene, settings)
        measured = orbited(scene, args.orbit)

    profile = Profile()
    profile.install()
    profile.active = True
    began = time.perf_counter()
    result = renderer.render(measured, settings)
    wall_ms = (time.perf_counter() - began) * 1e3
    profile.active = False
    device.queue.finish()
    per_kernel = profile.kernel_times()

    rows = {where: dict(row) for where, row in profile.rows.items()}
    kernel_ms = sum(per_kernel.values())
    idle_ms = sum(row["idle_before_ms"] for row in profile.rows.values())
    paths = ", the GPU's paths" if args.gpu_paths else ""
    paths += f", after an orbit of {args.orbit:g} degrees" if args.orbit is not None else ""
    lines = [about, f"{args.scene} {args.size} {args.preset}{paths}, no denoiser: render call {wall_ms:.1f} ms; "
             f"our kernels' own device time {kernel_ms:.1f} ms, the device idle between them {idle_ms:.1f} ms",
             "stages (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in result.stats["ms"].items()),
             table(profile.rows),
             "costliest kernels (device ms): " + ", ".join(f"{k} {v:.2f}" for k, v in list(per_kernel.items())[:12])]
    text = "\n".join(lines)
    print(text)
    os.makedirs(RESULTS, exist_ok=True)
    name = os.path.join(RESULTS, "frame_profile" + (f"_{args.tag}" if args.tag else ""))
    with open(name + ".txt", "w") as f:
        f.write(text + "\n")
    with open(name + ".json", "w") as f:
        json.dump(dict(machine=about, scene=args.scene, size=args.size, preset=args.preset, orbit=args.orbit,
                       gpu_paths=args.gpu_paths, wall_ms=wall_ms,
                       stages=result.stats["ms"], modules=rows, kernels=per_kernel), f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
