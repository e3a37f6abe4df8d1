"""Builds the stored Cycles references the GI tests compare against.

    python tests/references/make_references.py [--samples 4096] [--size 64]

Each scene of blend_scenes/ named below is rendered by Cycles (CPU) at
SIZE x SIZE pixels with its own film, Blender's default (a Blackman-Harris
filter 1.5 pixels wide, which GPU GI honours), no clamping,
no glossy filtering (Cycles blurs caustics by default), no adaptive
sampling or denoising, and bounce limits high enough that cutting paths
loses no visible light; the linear RGB image is stored as
NAME_SIZE.npy (float32, rows from the bottom) with the settings in
references.json.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
SCENES = ("cornell_box", "box_torus", "user_content")
BOUNCES = dict(max_bounces=64, diffuse_bounces=32, glossy_bounces=32, transmission_bounces=32,
               transparent_max_bounces=32)


def configure(scene, size: int, samples: int, box_filter: bool = False) -> None:
    """Cycles as the reference: no clamp, deep bounces, the scene's film
    (Blender's default) or, with ``box_filter``, a 1-pixel box (the
    benchmarks' time-against-error runs, made so before the filter was honoured)."""
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.use_border = False
    c = scene.cycles
    c.device, c.samples, c.seed = "CPU", samples, 0
    c.use_adaptive_sampling = c.use_denoising = False
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    if box_filter:
        c.pixel_filter_type, c.filter_width = "BOX", 1.0
    c.blur_glossy = 0.0
    for key, value in BOUNCES.items():
        setattr(c, key, value)


def render(bpy, scene) -> np.ndarray:
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth = "OPEN_EXR", "32"
    scene.render.use_file_extension = False
    with tempfile.TemporaryDirectory() as tmp:
        scene.render.filepath = os.path.join(tmp, "ref.exr")
        bpy.ops.render.render(write_still=True, scene=scene.name)
        img = bpy.data.images.load(scene.render.filepath)
        try:
            return np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)[..., :3]
        finally:
            bpy.data.images.remove(img)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=4096)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--only", nargs="*", default=list(SCENES))
    args = parser.parse_args()
    sys.path.insert(0, ROOT)
    import bpy

    meta_path = os.path.join(HERE, "references.json")
    meta = json.load(open(meta_path)) if os.path.exists(meta_path) else {}
    for name in args.only:
        bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "blend_scenes", f"{name}.blend"))
        scene = bpy.context.scene
        configure(scene, args.size, args.samples)
        image = render(bpy, scene)
        np.save(os.path.join(HERE, f"{name}_{args.size}.npy"), image)
        film = f"{scene.cycles.pixel_filter_type.lower().replace('_', '-')} {scene.cycles.filter_width:g} px"
        meta[f"{name}_{args.size}"] = dict(engine=f"Cycles {bpy.app.version_string}", samples=args.samples,
                                           size=args.size, filter=film, clamp=0, blur_glossy=0, **BOUNCES)
        print(f"{name}: mean {image.mean():.4f}")
    with open(meta_path, "w") as f:
        json.dump(meta, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
