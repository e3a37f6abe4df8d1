"""Render each scene with Cycles at low resolution and print how well it is exposed.

    python blend_scenes/check_exposure.py [FILE.blend ...]

Cycles renders each file (default: every .blend beside this script) at
64x64 with 16 samples, through the file's own view transform (AgX), to an
8-bit PNG. The table gives the mean display value (0..1) and the share of
pixels that are clipped (any channel above 0.99) or black (all below 0.02).
A well exposed scene has a mean of about 0.3-0.6 and few clipped pixels.
"""

from __future__ import annotations

import argparse
import glob
import os
import tempfile

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SIZE = 64
SAMPLES = 16


def display_pixels(path: str, png: str) -> np.ndarray:
    """``path`` rendered by Cycles, as display values (SIZE, SIZE, 3) in 0..1."""
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = SAMPLES
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.render.use_border = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.use_file_extension = False
    scene.render.filepath = png
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(png)
    try:
        return np.array(image.pixels[:], np.float32).reshape(SIZE, SIZE, 4)[..., :3]
    finally:
        bpy.data.images.remove(image)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("files", nargs="*", help=".blend files (default: every scene in this folder)")
    args = parser.parse_args(argv)
    files = args.files or sorted(glob.glob(os.path.join(HERE, "*.blend")))
    print(f"{'scene':22s} {'mean':>6s} {'clipped':>8s} {'black':>6s}")
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            px = display_pixels(path, os.path.join(tmp, "check.png"))
            clipped = (px.max(axis=2) > 0.99).mean()
            black = (px.max(axis=2) < 0.02).mean()
            print(f"{os.path.basename(path):22s} {px.mean():6.3f} {clipped:8.3f} {black:6.3f}")


if __name__ == "__main__":
    main()
