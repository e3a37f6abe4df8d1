"""The image kernel's levers, measured: camera paths per second.

The image kernel in Reference mode (the path tracer GI mode's image stage
is) renders each scene at --size pixels and --samples samples, direct light
only (no bounce) and with deep bounces (12 and 12), timed on the kernel's
own stage (the render's "render" milliseconds, median of --repeats after a
warm-up). Scenes come from ``blend_scenes/`` through the add-on's export.
One lever at a time, from the defaults:

* the local size of the launch (the launch helper's fixed size, 64 on a CPU);
* the pixel order within a launch: strips of 1 (rows), 2, 4, 8, 16 rows;
* the light passes: summed per pass (Blender's light passes asked for) or
  in one sum, which keeps the path's private state small;
* many lights: the Cornell box lit by 1 to 64 point lights of the same total
  power, direct light, beside Cycles (its light tree picks one light per
  shadow ray; ours sends one shadow ray to every light).

    python bench/image_kernel.py [--scenes cornell_box box_torus caustics]
        [--size 256] [--samples 16] [--repeats 3] [--quick]

Writes bench/results/image_kernel[_quick].txt and .json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

from bpy_render import ROOT, load_bpy, open_scene, render
from machine import describe
from report import write_results

LOCAL_SIZES = (8, 16, 32, 64, 128, 256)
STRIPS = (1, 2, 4, 8, 16)
LIGHT_COUNTS = (1, 4, 8, 16, 64)


class Bench:
    """One device and one renderer per scene, with defines and local sizes to try."""

    def __init__(self, repeats: int, samples: int):
        import gpu_core.renderer as renderer_module
        from gpu_core.device import get_device

        self.device = get_device()
        self.repeats, self.samples = repeats, samples
        self.extra_defines: dict = {}
        original = renderer_module.plan

        def plan_with_extra(*args, **kwargs):  # the lever's defines on top of the plan's
            the_plan = original(*args, **kwargs)
            the_plan.image_defines.update(self.extra_defines)
            return the_plan

        renderer_module.plan = plan_with_extra

    def set_local_size(self, size: int) -> None:
        """Launch every kernel at ``size`` work-items from now on."""
        from gpu_core.device import kernels

        kernels._TARGET["cpu" if self.device.is_cpu else "gpu"] = size
        self.device._kernels.clear()

    def rate(self, scene, deep: bool, light_passes: bool = False) -> float:
        """Million camera paths per second of the image kernel."""
        from gpu_core.renderer import Renderer
        from gpu_core.settings import RenderSettings

        bounces = 12 if deep else 0
        settings = RenderSettings(mode="reference", samples=self.samples, max_bounces=bounces,
                                  diffuse_bounces=bounces, denoise=False, light_passes=light_passes)
        renderer = Renderer(self.device)
        seconds = []
        for run in range(self.repeats + 1):
            result = renderer.render(scene, settings)
            if run:
                seconds.append(result.stats["ms"]["render"] / 1e3)
        w, h = scene.camera.width, scene.camera.height
        return w * h * self.samples / 1e6 / statistics.median(seconds)


def exported(bpy):
    """The open .blend's scene as the add-on exports it."""
    from blender_addon.export import export_scene

    return export_scene(bpy.context.evaluated_depsgraph_get())


def point_lights(bpy, count: int) -> None:
    """Replace the open scene's lights by ``count`` point lights under the
    ceiling in a square grid, of the same total power (60 W, as its area light)."""
    for obj in [o for o in bpy.data.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(obj)
    side = int(round(count ** 0.5))
    for i in range(count):
        data = bpy.data.lights.new(f"point_{i}", "POINT")
        data.energy, data.shadow_soft_size = 60.0 / count, 0.05
        obj = bpy.data.objects.new(f"point_{i}", data)
        x, y = (i % side + 0.5) / side - 0.5, (i // side + 0.5) / side - 0.5
        obj.location = (x * 1.2, y * 1.2, 1.85)
        bpy.context.scene.collection.objects.link(obj)


def cycles_rate(bpy, scene, samples: int) -> float:
    """Million paths per second of Cycles' direct light (render call)."""
    sys.path.insert(0, os.path.join(ROOT, "tests", "references"))
    from make_references import configure

    size = scene.render.resolution_x
    configure(scene, size, samples, box_filter=True)
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0
    times = [render(bpy, scene, "CYCLES")[1] for _ in range(3)]
    return size * size * samples / 1e6 / statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "box_torus", "caustics"])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="the Cornell box at 64 px, one repeat")
    args = parser.parse_args()
    if args.quick:
        args.scenes, args.size, args.repeats = ["cornell_box"], 64, 1
    bpy = load_bpy()
    bench = Bench(args.repeats, args.samples)
    lines = [f"machine: {describe(bench.device)}; {args.size}x{args.size} px, {args.samples} spp; "
             f"M paths/s of the image kernel, medians of {args.repeats}"]
    print(lines[0], flush=True)
    rows = []

    def report(lever: str, value, name: str, deep: bool, rate: float) -> None:
        rows.append(dict(lever=lever, value=value, scene=name, deep=deep, rate=rate))
        line = f"{lever} {value} {name} {'deep' if deep else 'direct'}: {rate:.2f}"
        print(line, flush=True)
        lines.append(line)

    scenes = {}
    for name in args.scenes:
        open_scene(bpy, name, args.size)
        scenes[name] = exported(bpy)
    for size in LOCAL_SIZES:
        bench.set_local_size(size)
        for name, scene in scenes.items():
            for deep in (False, True):
                report("local_size", size, name, deep, bench.rate(scene, deep))
    bench.set_local_size(64)
    for strip in STRIPS:
        bench.extra_defines = {"IMAGE_STRIP": strip}
        for name, scene in scenes.items():
            for deep in (False, True):
                report("strip", strip, name, deep, bench.rate(scene, deep))
    bench.extra_defines = {}
    for light_passes in (False, True):
        for name, scene in scenes.items():
            for deep in (False, True):
                report("light_passes", light_passes, name, deep, bench.rate(scene, deep, light_passes))
    for count in LIGHT_COUNTS:
        scene = open_scene(bpy, "cornell_box", args.size)
        point_lights(bpy, count)
        ours = bench.rate(exported(bpy), False)
        theirs = cycles_rate(bpy, scene, args.samples)
        rows.append(dict(lever="lights", value=count, scene="cornell_box", deep=False, rate=ours, cycles=theirs))
        line = f"lights {count} cornell_box direct: {ours:.2f}, Cycles {theirs:.2f} ({ours / theirs:.2f}x)"
        print(line, flush=True)
        lines.append(line)
    write_results("image_kernel_quick" if args.quick else "image_kernel", dict(machine=lines[0], rows=rows), lines)


if __name__ == "__main__":
    main()
