"""The Rendered viewport, edit by edit, as a user drives it.

Through the add-on's own viewport path (``view_update_session``: the
incremental sync of the depsgraph's updates on this thread, then the
session's worker: coarse image, full resolution, accumulation) on any
``.blend``, looking through the scene camera at ``--size``, for the events

  open      the first view_update (everything exported)
  orbit     the view turned 10 degrees about the scene's vertical axis
  light     the first light's power x1.5 (then back)
  material  the first material's base colour changed (then back)
  move      the first mesh object moved by 1% of the scene's size (then back)

one JSON line each on standard output, the medians of ``--repeat`` runs:
{"event", "first_ms" (edit to the first image shown), "full_gi_ms" (to the
first full-resolution image), "main_thread_ms" (the sync on Blender's
thread), "plan" (the stages of the first full-resolution render),
"runs"}; then a line with the process's memory after 10, 100, 250, 500,
1,000 ... and ``--edits`` light edits in a row (each restarting the
worker), each sampled with the worker stopped (what stays held).

    python bench/viewport.py FILE.blend [--size 640x360] [--preset preview] [--repeat 3] [--edits 1000] [--settle]
                             [--viewport-samples N]

The session is the engine's, which compiles the edits' kernels on its idle
worker once a view has settled; ``--settle`` waits for that (and reports
the open's ``settled_ms``) before the first edit, as a user who looks at
the opened view first; without it the first orbit comes as soon as the
first full-resolution image is shown. ``--viewport-samples`` sets Viewport
Samples (0: until stopped; the view then never settles, and ``--settle``
waits for the warm-up it pauses for).

Writes bench/results/viewport_NAME.json and .txt.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import time
from types import SimpleNamespace

import numpy as np

from bpy_render import load_bpy
from machine import describe
from report import write_results


def rss_mb() -> float:
    """Resident memory of this process now (MiB)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


class Viewport:
    """A 3D view through the scene camera, driven as Blender drives the engine."""

    def __init__(self, bpy, width: int, height: int):
        from blender_addon.export.sync import SceneSync, read_updates
        from blender_addon.viewport import ViewportSession, warm_edit_kernels

        self.bpy, self.width, self.height = bpy, width, height
        self.warm_ups = 0  # warm-ups ended

        def warm_up(job, should_stop):  # the engine's, counted
            warm_edit_kernels(job, should_stop)
            self.warm_ups += 1

        self.session = ViewportSession(lambda: None, warm_up=warm_up)  # as the engine makes it
        self.sync = SceneSync()
        self.updates: list = []
        self._read_updates = read_updates
        bpy.app.handlers.depsgraph_update_post.append(self._capture)
        camera = bpy.context.scene.camera
        self.view = np.linalg.inv(np.array(camera.matrix_world, np.float64))
        depsgraph = bpy.context.evaluated_depsgraph_get()
        self.window = np.array(camera.calc_matrix_camera(depsgraph, x=width, y=height), np.float64)
        self.perspective = camera.data.type != "ORTHO"

    def _capture(self, scene, depsgraph):
        self.updates.extend(self._read_updates(depsgraph))

    def context(self):
        return SimpleNamespace(
            region=SimpleNamespace(width=self.width, height=self.height),
            region_data=SimpleNamespace(view_matrix=self.view, window_matrix=self.window,
                                        is_perspective=self.perspective),
            scene=self.bpy.context.scene)

    def update(self, first: bool = False) -> float:
        """The engine's view_update after an edit: ms on this thread."""
        from blender_addon.viewport import view_update_session

        began = time.perf_counter()
        updates, self.updates = (None if first else self.updates), []
        view_update_session(self.session, self.sync, self.context(), self.bpy.context.evaluated_depsgraph_get(),
                            lambda scene: 1, updates)
        return (time.perf_counter() - began) * 1e3

    def orbit(self, degrees: float, center) -> float:
        """Turn the view about the vertical axis through ``center``: ms on this thread."""
        from blender_addon.viewport import view_state

        a = np.radians(degrees)
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        to_center, back = np.eye(4), np.eye(4)
        to_center[:3, 3], back[:3, 3] = -np.asarray(center), center
        self.view = self.view @ back @ turn @ to_center
        began = time.perf_counter()
        self.session.update_view(view_state(self.context()))
        return (time.perf_counter() - began) * 1e3

    def wait(self, began: float, version0: int, timeout: float = 300.0) -> tuple[float, float, list]:
        """ms from ``began`` to the first image after version ``version0``
        and to the first full-resolution one, and the stages the edit ran."""
        first = full = None
        while time.perf_counter() - began < timeout:
            if self.session.error:
                raise RuntimeError(self.session.error)
            if first is None and self.session.latest()[1] > version0:
                first = (time.perf_counter() - began) * 1e3
            if self.session.samples > 0:
                full = (time.perf_counter() - began) * 1e3
                return first or full, full, self.session.first_plan
            time.sleep(0.002)
        raise RuntimeError("no full-resolution image in time")

    def settle(self, began: float, timeout: float = 300.0) -> float:
        """ms from ``began`` until the view has settled and the edit kernels'
        warm-up (the engine's, on the idle worker) has ended; in a view that
        never settles (Viewport Samples 0), until its warm-up between passes
        has ended."""
        while time.perf_counter() - began < timeout:
            if self.session.error:
                raise RuntimeError(self.session.error)
            idle = not self.session.busy or self.warm_ups > 0
            if idle and not self.session.warming:
                return (time.perf_counter() - began) * 1e3
            time.sleep(0.002)
        raise RuntimeError("the view did not settle in time")

    def close(self):
        self.session.stop()
        self.bpy.app.handlers.depsgraph_update_post.remove(self._capture)


def scene_bounds(bpy):
    points = [np.array(o.matrix_world) @ np.append(c[:], 1.0) for o in bpy.context.scene.objects if o.type == "MESH"
              for c in o.bound_box]
    points = np.array(points)[:, :3] if points else np.zeros((1, 3))
    return points.mean(axis=0), float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def edits(bpy, size: float) -> dict:
    """Each edit event: a function of the run number (even: change, odd: back)."""
    light = next((o.data for o in bpy.context.scene.objects if o.type == "LIGHT"), None)
    material = next(iter(bpy.data.materials), None)
    mesh = next((o for o in bpy.context.scene.objects if o.type == "MESH"), None)

    def light_edit(run):
        light.energy *= 1.5 if run % 2 == 0 else 1 / 1.5

    def material_edit(run):
        node = material.node_tree.nodes.get("Principled BSDF") if material.node_tree else None
        socket = node.inputs["Base Color"] if node is not None else None
        color = (0.9, 0.3, 0.2, 1.0) if run % 2 == 0 else (0.3, 0.6, 0.9, 1.0)
        if socket is not None:
            socket.default_value = color
        else:
            material.diffuse_color = color

    def move_edit(run):
        mesh.location.x += 0.01 * size * (1 if run % 2 == 0 else -1)

    return {name: fn for name, fn, target in (("light", light_edit, light), ("material", material_edit, material),
                                             ("move", move_edit, mesh)) if target is not None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("blend")
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--preset", default="preview", choices=["draft", "preview", "final", "reference"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--edits", type=int, default=1000)
    parser.add_argument("--settle", action="store_true",
                        help="before the first edit, wait until the opened view has settled and the edit kernels' "
                             "warm-up has ended (as a user who looks at the image first)")
    parser.add_argument("--viewport-samples", type=int, default=None,
                        help="Viewport Samples (0: until stopped); default: the file's")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    bpy = load_bpy()
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    scene.gpugi.mode, scene.gpugi.preset = "GI", args.preset.upper()
    if args.viewport_samples is not None:
        scene.gpugi.preview_samples = args.viewport_samples
    center, size = scene_bounds(bpy)
    viewport = Viewport(bpy, width, height)
    name = os.path.splitext(os.path.basename(args.blend))[0]
    lines = [f"# {describe()}", f"# {name} at {width}x{height}, preset {args.preset}, Viewport Samples "
                                f"{scene.gpugi.preview_samples}, medians of {args.repeat} runs"]
    results = []

    def report(event: str, runs: list[dict]) -> None:
        line = {"event": event, **{k: round(statistics.median(r[k] for r in runs), 1)
                                   for k in ("first_ms", "full_gi_ms", "main_thread_ms")},
                "plan": runs[-1]["plan"], "runs": runs}
        results.append(line)
        lines.append(json.dumps(line))
        print(lines[-1], flush=True)

    began, version = time.perf_counter(), viewport.session.latest()[1]
    main_ms = viewport.update(first=True)
    first, full, plan = viewport.wait(began, version)
    opened = dict(first_ms=first, full_gi_ms=full, main_thread_ms=main_ms, plan=plan)
    if args.settle:
        opened["settled_ms"] = round(viewport.settle(began), 1)
    report("open", [opened])
    runs = []
    for run in range(args.repeat):
        began, version = time.perf_counter(), viewport.session.latest()[1]
        main_ms = viewport.orbit(10.0 if run % 2 == 0 else -10.0, center)
        first, full, plan = viewport.wait(began, version)
        runs.append(dict(first_ms=first, full_gi_ms=full, main_thread_ms=main_ms, plan=plan))
    report("orbit", runs)
    for event, edit in edits(bpy, size).items():
        runs = []
        for run in range(args.repeat):
            began, version = time.perf_counter(), viewport.session.latest()[1]
            edit(run)
            bpy.context.view_layer.update()
            main_ms = viewport.update()
            first, full, plan = viewport.wait(began, version)
            runs.append(dict(first_ms=first, full_gi_ms=full, main_thread_ms=main_ms, plan=plan,
                             sync=viewport.session.sync_stats))
        report(event, runs)
    light = edits(bpy, size).get("light")
    if light is not None and args.edits > 0:
        memory = {}
        checkpoints = {10, args.edits} | {n for n in (100, 250, 500, 1000, 2000, 3000) if n < args.edits}
        for run in range(args.edits):
            light(run)
            bpy.context.view_layer.update()
            viewport.update()
            if run + 1 in checkpoints:
                viewport.session.stop()  # what stays held, not what a running render holds for a while
                gc.collect()
                memory[run + 1] = round(rss_mb(), 1)
        line = {"event": "memory", "edits": args.edits, "rss_mb_after": memory,
                "growth_mb_after_10": round(memory[args.edits] - memory.get(10, memory[args.edits]), 1)}
        lines.append(json.dumps(line))
        print(lines[-1], flush=True)
        results.append(line)
    viewport.close()
    write_results(f"viewport_{name}", {"machine": describe(), "size": [width, height], "preset": args.preset,
                                       "events": results}, lines)


if __name__ == "__main__":
    main()
