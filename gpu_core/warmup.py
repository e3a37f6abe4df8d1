"""A first render's kernels compiled ahead, in a helper process.

PoCL compiles each program, and each kernel's work-group function at its
first launch, one at a time per process: a first render on two cores spent
24 s compiling on one of them. When some program of a render is missing
from the disk cache, ``start`` runs this module in a helper process on a
small copy of the render (the same scene and settings, so the same programs
and launch shapes, but a few pixels, photons and cache points), taking each
program from the disk cache as the render compiles it: while the render
builds its programs, the helper compiles the first stages' work-group
functions, and stays ahead, so the render finds them in PoCL's cache.
The render, once its programs are built, catches the helper up in its
photon stage, and walking the same stages the two would compile the same
kernels from there on; so the helper first runs what needs no photon
map (the shading points, their cache points, the image over an empty GI
field, and the interpolation and caustic estimate over stand-in records
and photons), compiling it while the render compiles its photon stage,
and only then its copy's render (on two cores a first frame 16.5-17.3 s,
against 19.7-21.1 s with the helper walking the stages as the render
does). The helper changes nothing the render computes; a helper that
fails costs nothing but its core.

The viewport warms the kernels only its edits launch the same way, on
its idle worker once a view has settled: its passes over the small copy
and over ``edited_copies`` of it (blender_addon/viewport.py
``warm_edit_kernels``).

    python -m gpu_core.warmup P:D < pickle of (scene, settings)
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from dataclasses import replace

import numpy as np

from .accel.kdtree_overlay import OVERLAY_SHARE
from .accel.point_tree import PointTree
from .device import Device
from .device.programs import compile_helpers, device_spec, start_helper, stop_helper
from .gi import caustics, cut, shading_points
from .gi.cache import interpolation, neighbours, samples
from .gi.pipeline import GiField
from .image import render_image
from .plan import Held, plan
from .scene.model import Scene
from .scene.upload import upload
from .scene.validate import validate
from .settings import RenderSettings

# the small copy: pixels on a side, and the counts that only size the work
SIDE = 16
SMALL = dict(samples=1, global_photons=2_000, caustic_photons=1_000, cache_seeds=20, gather_rays=16, denoise=False)
PROGRAM_WAIT = 300.0  # seconds the helper waits for a program the render compiles


def small_copy(scene: Scene, settings: RenderSettings) -> tuple[Scene, RenderSettings]:
    """The render at SIDE x SIDE pixels with SMALL counts (programs and
    launch shapes as the render's)."""
    camera = replace(scene.camera, width=SIDE, height=SIDE, border=None)
    return replace(scene, camera=camera), replace(settings, **SMALL)


# an edit's share of the triangles moved: well within what an overlay tree holds, so the move warms its kernels
MOVED_SHARE = OVERLAY_SHARE / 4
EDIT_TURN = np.radians(2.0)  # the view's turn about its own vertical axis


def edited_copies(scene: Scene) -> list[tuple[Scene, set[str]]]:
    """``scene`` edited as the viewport edits a scene, each edit applied to
    the one before, with the parts it changes: the view turned, the lights'
    power raised (where there are lights), the materials' colours changed,
    and a sixteenth of the triangles moved a little toward the centre of
    the scene's box (within it, so the device frame stays)."""
    edits = []
    turn = np.eye(4)
    c, s = np.cos(EDIT_TURN), np.sin(EDIT_TURN)
    turn[[0, 0, 2, 2], [0, 2, 0, 2]] = (c, s, -s, c)
    scene = replace(scene, camera=replace(scene.camera, matrix=np.asarray(scene.camera.matrix) @ turn))
    edits.append((scene, set()))
    if len(scene.lights.power):
        scene = replace(scene, lights=replace(scene.lights, power=np.asarray(scene.lights.power) * np.float32(1.5)))
        edits.append((scene, {"lights"}))
    if len(scene.materials.base_color):
        colours = np.asarray(scene.materials.base_color) * np.float32(0.9)
        scene = replace(scene, materials=replace(scene.materials, base_color=colours))
        edits.append((scene, {"materials"}))
    if scene.triangle_count:
        lo, hi = scene.bounds()
        rows = max(1, int(scene.triangle_count * MOVED_SHARE))
        triangles = np.array(scene.triangles, copy=True)
        triangles[:rows] += 1e-3 * (0.5 * (lo + hi) - triangles[:rows])
        edits.append((replace(scene, triangles=triangles), {"geometry"}))
    return edits


def start(device: Device, scene: Scene, settings: RenderSettings, programs: list) -> subprocess.Popen | None:
    """The helper process warming the kernels of a render of ``scene`` with
    ``settings`` (whose ``programs`` the plan lists), where it helps: a
    compiler that takes one program at a time, a second core, and a program
    missing from the disk cache; None otherwise or when it cannot start."""
    if (not compile_helpers(device.device) or (os.cpu_count() or 1) < 2
            or not device.programs.missing(programs)):
        return None
    spec = device_spec(device.device)
    if spec is None:
        return None
    try:
        data = pickle.dumps(small_copy(scene, settings))
    except (pickle.PicklingError, TypeError, AttributeError):
        return None
    return start_helper("gpu_core.warmup", spec, data)


def stop(process: subprocess.Popen | None) -> None:
    """End the helper (when the render is over, what it has not compiled is not needed)."""
    stop_helper(process)


def main() -> None:
    from .device import get_device

    scene, settings = pickle.load(sys.stdin.buffer)
    device = get_device(sys.argv[1])
    # PoCL keys a work-group function by its program, and two compiles of one
    # source are two programs: the helper links the render's own compiled
    # objects, as they reach the disk cache, so that its work-group functions
    # are the render's (and a later process's, which links the same objects)
    device.programs.wait_for_cache(PROGRAM_WAIT)
    render_small_copy(device, scene, settings)


def render_small_copy(device: Device, scene: Scene, settings: RenderSettings) -> None:
    """The helper's work: the stages of the small copy that need no photon
    map, then its render."""
    from .renderer import Renderer

    stages_ahead(device, scene, settings)
    Renderer(device, builds_up_front=False).render(scene, settings)


def stages_ahead(device: Device, scene: Scene, settings: RenderSettings) -> None:
    """What a GI render of ``scene`` runs that needs no photon map, run once
    on its own: its shading points, their cache points (where it gathers),
    its image over an empty GI field (no cache point anywhere; not where
    glossy paths read the cut, which needs the maps), the cache points'
    neighbour checks and interpolation over dark stand-in records, and the
    caustic estimates over a stand-in map (a photon at each shading point:
    on the grid, as caustics seen directly, and at points, as the cut's nodes)."""
    settings = settings.validated()
    if settings.mode != "gi":
        return
    scene = validate(scene)
    the_plan = plan(scene, settings, Held(), None, device)
    buffers = upload(device, scene, the_plan.tables, None, the_plan.changed, None, None, the_plan.tree_rows)
    window = scene.camera.pixel_window
    points = shading_points.trace(device, buffers, window, settings.max_bounces, settings.gi_subpixels,
                                  the_plan.scene_defines)
    chosen = None
    if points.count and "final_gather" in the_plan.stages:
        chosen = samples.select(device, points.pos, points.nrm, points.pixel, points.count, points.width,
                                points.height, min(settings.cache_seeds, points.count), settings.cache_alpha,
                                seed=settings.seed)
    if "glossy_cut" not in the_plan.stages:
        empty = device.zeros(16 * points.grid_size)
        render_image(device, buffers, scene, settings, the_plan.image_defines,
                     GiField(empty, empty, empty, empty, settings.gi_subpixels))
    if chosen is not None and chosen.count:
        m, dark = chosen.count, device.zeros(16 * chosen.count)
        checked = neighbours.check(device, chosen.pos, chosen.nrm, dark, device.to_device(np.ones(m, np.float32)), m)
        interpolation.interpolate_on_device(device, chosen.pos, chosen.nrm, dark, checked.radii, m, points.pos,
                                            points.nrm, points.count)
    if points.count and "caustics" in the_plan.stages:
        pos, nrm = points.positions, points.normals
        stand_in = PointTree.build(device, pos, np.full_like(pos, 1e-3), nrm, nrm, k_hint=settings.photon_k)
        caustics.irradiance(stand_in, points, settings.caustic_k)
        cut.caustic_irradiance(stand_in, points.pos, points.nrm, points.count, settings.caustic_k,
                               device.empty(16 * points.count))


if __name__ == "__main__":
    main()
