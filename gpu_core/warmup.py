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
About where the render catches it up (gathering, on the Cornell box) the
two would compile the same kernels from then on; there the helper first
runs its copy's image stage once over an empty GI field, compiling the
image kernel, which the render needs last, while the render compiles the
GI stages' (a first frame on two cores 19.7-21.1 -> 18.5-19.2 s). The
helper changes nothing the render computes; a helper that fails costs
nothing but its core.

    python -m gpu_core.warmup P:D < pickle of (scene, settings)
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from dataclasses import replace

from .device import Device
from .device.programs import compile_helpers, device_spec, start_helper, stop_helper
from .scene.model import Scene
from .settings import RenderSettings

# the small copy: pixels on a side, and the counts that only size the work
SIDE = 16
SMALL = dict(samples=1, global_photons=2_000, caustic_photons=1_000, cache_seeds=20, gather_rays=16, denoise=False)
PROGRAM_WAIT = 300.0  # seconds the helper waits for a program the render compiles
IMAGE_AHEAD_AT = "gathering"  # the GI stage (as the status line names it) before which the image stage runs once


def small_copy(scene: Scene, settings: RenderSettings) -> tuple[Scene, RenderSettings]:
    """The render at SIDE x SIDE pixels with SMALL counts (programs and
    launch shapes as the render's)."""
    camera = replace(scene.camera, width=SIDE, height=SIDE, border=None)
    return replace(scene, camera=camera), replace(settings, **SMALL)


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
    """The helper's render of the small copy, its image stage run once
    ahead when the GI stages reach gathering."""
    from .renderer import Renderer

    ahead = []

    def progress(_fraction: float, text: str) -> None:
        if text == IMAGE_AHEAD_AT and not ahead:
            ahead.append(text)
            image_ahead(device, scene, settings)

    Renderer(device, builds_up_front=False).render(scene, settings, progress=progress)


def image_ahead(device: Device, scene: Scene, settings: RenderSettings) -> None:
    """The image stage of a GI render of ``scene`` over an empty GI field
    (no cache point anywhere), which compiles the image kernel as the
    render launches it; nothing where its glossy paths would read the cut
    (that needs the GI stages' cut)."""
    from .gi.pipeline import GiField
    from .image import render_image
    from .plan import Held, plan
    from .scene.upload import upload
    from .scene.validate import validate

    settings = settings.validated()
    scene = validate(scene)
    the_plan = plan(scene, settings, Held(), None, device)
    if settings.mode != "gi" or "glossy_cut" in the_plan.stages:
        return
    buffers = upload(device, scene, the_plan.tables, None, the_plan.changed, None, None, the_plan.tree_rows)
    x0, y0, x1, y1 = scene.camera.pixel_window
    empty = device.zeros(16 * (x1 - x0) * (y1 - y0) * settings.gi_subpixels ** 2)
    render_image(device, buffers, scene, settings, the_plan.image_defines,
                 GiField(empty, empty, empty, empty, settings.gi_subpixels))


if __name__ == "__main__":
    main()
