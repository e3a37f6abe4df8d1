"""Constants the host and the kernels share, declared once.

Every name in capitals below reaches every program as a ``-D NAME=value``
define (``defines()``), so no kernel file repeats a number the host also
knows. Host modules import the names from here (``scene`` re-exports the
light and camera kinds under their user-facing names).
"""

from __future__ import annotations

# kd-trees (triangle and point): KdNode.axis of a leaf, deepest levels
KD_LEAF = 3
KD_MAX_DEPTH = 64  # triangle tree: build limit and traversal stack
# leaf blocks (accel/kdtree_blocks.cl): triangles tested together, float4 rows a block
KD_BLOCK_LANES = 4
KD_BLOCK_ROWS = 10
POINT_TREE_MAX_DEPTH = 60  # point tree: build limit and kNN stack
POINT_BUILD_SMALL = 32  # points of a small point-tree node: the width of its bit masks
POINT_BUILD_CHUNK = 256  # points of a large point-tree node processed by one work item

# light rows (scene/tables.py, shading/lights.h)
LIGHT_POINT = 0
LIGHT_SPOT = 1
LIGHT_SUN = 2
LIGHT_AREA = 3
LIGHT_MESH = 4  # all emissive triangles, sampled as one light row
AREA_RECTANGLE = 0
AREA_ELLIPSE = 1

# material rows' shaders (shading/bsdf.h): the Principled BSDF, or the
# Glossy, Glass or Transparent shader node alone (a Transparent row has
# alpha 0 and its colour tints the light passing through it)
MATERIAL_PRINCIPLED = 0
MATERIAL_GLOSSY = 1
MATERIAL_GLASS = 2
MATERIAL_TRANSPARENT = 3
# Below this roughness a metal or glass lobe bends light into caustics: the
# photons it scatters are caustic photons (the caustic map) and its camera
# paths are followed as specular ones; above it, its light is glossy.
CAUSTIC_ROUGHNESS = 0.1
# a texture channel read by a value socket (Roughness, Metallic): 0-3 one of
# r, g, b, a, or the colour's luminance (Blender's colour-to-value conversion)
TEXTURE_LUMINANCE = 4

# cameras (shading/camera.h)
CAMERA_PERSP = 0
CAMERA_ORTHO = 1

# pixel filters (shading/pixel_filter.py), as Cycles' film has them
FILTER_BOX = 0
FILTER_GAUSSIAN = 1
FILTER_BLACKMAN_HARRIS = 2
FILTER_TABLE_SIZE = 256  # entries of the filter's inverse CDF the image kernel reads

# light passes of the image kernel, in the order of image.LIGHT_PASSES
PASS_DIFFUSE = 0  # +0 direct, +1 indirect
PASS_GLOSSY = 2
PASS_TRANSMISSION = 4
PASS_EMISSION = 6
PASS_ENVIRONMENT = 7
PASS_CAUSTICS = 8
PASS_SUMMED = 8  # passes before this one add up to Combined
PASS_COUNT = 9

# what the image kernel writes besides Combined, Depth and Normal (flags; the
# light passes are the plan's IMAGE_LIGHT_PASSES define)
OUTPUT_DENOISING = 1
OUTPUT_ADAPTIVE = 2  # adaptive sampling: only active pixels sampled, sums merged with earlier rounds

# photon tracing (photons/photon_trace.cl, photons/photon_emit.h)
PHOTON_PASS_GLOBAL = 0  # every diffuse hit but those of caustic paths
PHOTON_PASS_CAUSTIC = 1  # only paths light -> specular+ -> diffuse
PHOTON_PASS_ALL = 2  # every diffuse hit (no caustic map traced)
PHOTON_EMITTER_WORLD = -1  # emitter row of the world's radiance

# density-estimation filters (photons/photon_density.h)
PHOTON_FILTER_BOX = 0
PHOTON_FILTER_CONE = 1
PHOTON_FILTER_EPANECHNIKOV = 2

# stable radix sort of the device primitives: bits per pass, and the most work-items of the
# one-work-group sort (its digit table in local memory)
PRIM_RADIX_BITS = 4
PRIM_SORT_GROUP = 256


def defines() -> dict[str, int | str]:
    """Every constant of this module, as program defines (floats as float
    literals)."""
    return {name: f"{value!r}f" if isinstance(value, float) else value
            for name, value in globals().items() if name.isupper() and isinstance(value, (int, float))}
