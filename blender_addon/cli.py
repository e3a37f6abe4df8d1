"""Command line: render a .blend with GPU GI through the bpy module.

    python -m blender_addon render FILE.blend -o OUT.png|OUT.exr [--frame N]
"""

from __future__ import annotations

import argparse
import os
import sys

FORMATS = {".png": "PNG", ".exr": "OPEN_EXR", ".jpg": "JPEG", ".jpeg": "JPEG", ".tif": "TIFF", ".tiff": "TIFF"}


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="python -m blender_addon", description=__doc__.strip().splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    render = sub.add_parser("render", help="render one frame of a .blend file")
    render.add_argument("blend", help=".blend file to render")
    render.add_argument("-o", "--output", required=True, help="image to write (.png, .exr, .jpg, .tif)")
    render.add_argument("--frame", type=int, default=None, help="frame to render (default: the file's current frame)")
    render.add_argument("--samples", type=int, default=None, help="camera paths per pixel")
    render.add_argument("--resolution-percentage", type=int, default=None, help="scale of the file's resolution")
    render.add_argument("--device", default=None, help="OpenCL device spec (see README)")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    blend = os.path.abspath(args.blend)
    output = os.path.abspath(args.output)
    ext = os.path.splitext(output)[1].lower()
    if ext not in FORMATS:
        print(f"error: unsupported output extension {ext!r}; use one of {', '.join(FORMATS)}", file=sys.stderr)
        return 2
    if not os.path.isfile(blend):
        print(f"error: {blend} does not exist", file=sys.stderr)
        return 2

    import bpy

    from . import register
    from .final import LAST_RUN, format_stage_times

    register()
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    scene.render.engine = "GPUGI"
    if args.frame is not None:
        scene.frame_set(args.frame)
    if args.samples is not None:
        scene.gpugi.samples = args.samples
    if args.resolution_percentage is not None:
        scene.render.resolution_percentage = args.resolution_percentage
    if args.device is not None:
        scene.gpugi.device = args.device
    settings = scene.render.image_settings
    settings.file_format = FORMATS[ext]
    if ext == ".exr":
        settings.color_depth = "32"
    scene.render.use_file_extension = False
    scene.render.filepath = output
    os.makedirs(os.path.dirname(output), exist_ok=True)
    bpy.ops.render.render(write_still=True)
    if LAST_RUN.get("error"):
        print(f"error: {LAST_RUN['error']}", file=sys.stderr)
        return 1
    if not os.path.isfile(output):
        print(f"error: no image was written to {output}", file=sys.stderr)
        return 1
    stats = LAST_RUN.get("stats", {})
    for warning in LAST_RUN.get("warnings", []):
        print(f"warning: {warning}")
    print(f"device: {stats.get('device', '?')}")
    print(f"stages: {format_stage_times(stats.get('ms', {}))}")
    print(f"wrote {output}")
    return 0
