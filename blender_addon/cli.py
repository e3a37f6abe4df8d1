"""Command line: render a .blend with GPU GI through the bpy module.

    python -m blender_addon render FILE.blend -o OUT.png|OUT.exr [--frame N]
        [--preset draft|preview|final|reference] [--mode reference|gi]
        [--samples N] [--KNOB VALUE ...] [--resolution-percentage P] [--device SPEC]

Every knob of gpu_core's RenderSettings is an option (--global-photons,
--gather-rays, ...); they apply after --preset. Prints the mode, the
image's path, each stage's time and the bytes moved to and from the device;
while kernels compile (a first run), their count on stderr; on an error,
prints one line and exits non-zero.
"""

from __future__ import annotations

import argparse
import os
import sys

from gpu_core.settings import PRESETS, knobs

# output extension -> Blender file format
FORMATS = {".png": "PNG", ".exr": "OPEN_EXR", ".jpg": "JPEG", ".jpeg": "JPEG", ".tif": "TIFF", ".tiff": "TIFF"}


class CliError(Exception):
    """A one-line message for the user; the command exits with status 1."""


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="python -m blender_addon", description="Render .blend files with GPU GI.")
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render one frame of a .blend file to an image")
    render.add_argument("blend", help=".blend file to render")
    render.add_argument("-o", "--output", required=True, help="image to write: " + ", ".join(FORMATS))
    render.add_argument("--frame", type=int, default=None, help="frame to render (default: the file's current frame)")
    render.add_argument("--preset", choices=list(PRESETS), default=None,
                        help="speed/accuracy step: samples, bounces and the GI knobs (the options below apply after it)")
    for knob in knobs():
        _add_knob(render, knob)
    render.add_argument("--resolution-percentage", type=_bounded(int, 1), default=None,
                        help="scale of the file's resolution")
    render.add_argument("--device", default=None, help="OpenCL device: 'cpu', 'gpu', a platform name part or 'P:D'")
    return parser.parse_args(argv)


def _add_knob(parser, knob) -> None:
    """``--name`` for a RenderSettings knob, typed and bounded by its declaration."""
    meta = knob.metadata
    option = "--" + knob.name.replace("_", "-")
    if meta["items"]:
        parser.add_argument(option, choices=[value for value, _, _ in meta["items"]], default=None,
                            help=meta["description"])
        return
    if isinstance(knob.default, bool):
        parser.add_argument(option, action=argparse.BooleanOptionalAction, default=None,
                            help=f"{meta['description']} (default in Blender: {'on' if meta['blender_default'] else 'off'})")
        return
    kind = float if isinstance(knob.default, float) else int
    parser.add_argument(option, type=_bounded(kind, meta["minimum"], meta["maximum"]), default=None,
                        help=f"{meta['description']} (default {knob.default})")


def _bounded(kind, minimum=None, maximum=None):
    """An argparse type: ``kind`` within [minimum, maximum]."""
    def parse(text: str):
        value = kind(text)
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"{text} is outside {minimum}..{maximum}")
        return value
    return parse


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        stats, warnings, output = render_file(args)
    except CliError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    from .status import format_samples, format_stage_times, format_transfers, mode_line

    for warning in warnings:
        print(f"warning: {warning}")
    print(f"device: {stats.get('device', 'unknown')}")
    print(f"mode: {mode_line(stats)}")
    if "plan" in stats:
        print(f"plan: {', '.join(stats['plan'])}")
    print(f"stages: {format_stage_times(stats.get('ms', {}))}")
    if "samples" in stats:
        print(f"samples: {format_samples(stats)}")
    if "transfers" in stats:
        print(f"transfers: {format_transfers(stats['transfers'])}")
    print(f"image: {output}")
    return 0


def render_file(args) -> tuple[dict, list[str], str]:
    """Render ``args.blend`` to ``args.output``; returns (stats, warnings, output path)."""
    blend = os.path.abspath(args.blend)
    output = os.path.abspath(args.output)
    ext = os.path.splitext(output)[1].lower()
    if ext not in FORMATS:
        raise CliError(f"unsupported output extension '{ext}'; use one of {', '.join(FORMATS)}")
    if not os.path.isfile(blend):
        raise CliError(f"{args.blend} does not exist")

    from gpu_core.device import load_pip_drivers

    load_pip_drivers()  # before bpy: see gpu_core/device/pip_drivers.py
    import bpy

    from . import register
    from .final import LAST_RUN, STATUS_LISTENERS

    register()
    STATUS_LISTENERS[:] = [_CompileProgress()]
    try:
        bpy.ops.wm.open_mainfile(filepath=blend)
    except RuntimeError as err:
        raise CliError(f"cannot open {args.blend}: {_first_line(err)}") from err
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    if args.frame is not None:
        scene.frame_set(args.frame)
    if args.preset is not None:
        scene.gpugi.preset = args.preset.upper()
    for knob in knobs():
        value = getattr(args, knob.name)
        if value is not None:
            setattr(scene.gpugi, knob.name, value.upper() if isinstance(value, str) else value)
    if args.resolution_percentage is not None:
        scene.render.resolution_percentage = args.resolution_percentage
    if args.device is not None:
        scene.gpugi.device = args.device
    _set_output(scene.render, output, ext)
    os.makedirs(os.path.dirname(output), exist_ok=True)
    try:
        bpy.ops.render.render(write_still=True)
    except RuntimeError as err:
        raise CliError(LAST_RUN.get("error") or _first_line(err)) from err
    if LAST_RUN.get("error"):
        raise CliError(LAST_RUN["error"])
    if not os.path.isfile(output):
        raise CliError(f"no image was written to {args.output}")
    return LAST_RUN.get("stats", {}), LAST_RUN.get("warnings", []), output


class _CompileProgress:
    """Prints "compiling kernels 3/9" to stderr as the count changes: on one
    rewritten line in a terminal, a line each otherwise."""

    def __init__(self):
        self._last = ""
        self._tty = sys.stderr.isatty()

    def __call__(self, message: str) -> None:
        compiling = message.startswith("compiling kernels")
        if compiling and message != self._last:
            print(("\r" if self._tty else "") + message, end="" if self._tty else "\n", file=sys.stderr, flush=True)
        elif not compiling and self._last and self._tty:
            print(file=sys.stderr)  # end the rewritten line
        self._last = message if compiling else ""


def _set_output(render, output: str, ext: str) -> None:
    """Write a single image of the extension's format (EXR as 32-bit float) to ``output``."""
    settings = render.image_settings
    if hasattr(settings, "media_type"):
        settings.media_type = "IMAGE"
    settings.file_format = FORMATS[ext]
    if ext == ".exr":
        settings.color_depth = "32"
        settings.color_mode = "RGBA"
    render.use_file_extension = False
    render.filepath = output


def _first_line(err: Exception) -> str:
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__
