"""Every struct the host and the kernels share, declared once.

A ``Struct`` lists its fields with OpenCL C types; from that one list come
the numpy dtype the host fills (offsets by OpenCL's alignment rules), the C
typedef every program sees through the generated header
``device/structs.h``, and the probe kernel with which a test checks, on the
device, that both agree (``float3`` is 16 bytes, so structs use ``float4``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# OpenCL C type -> (numpy scalar, lanes); a vector's size is also its alignment
_TYPES = {
    "float": (np.float32, 1), "int": (np.int32, 1), "uint": (np.uint32, 1),
    "float2": (np.float32, 2), "int2": (np.int32, 2),
    "float4": (np.float32, 4), "int4": (np.int32, 4),
}


@dataclass(frozen=True)
class Field:
    name: str
    ctype: str
    doc: str = ""
    count: int = 1  # an array of this many


class Struct:
    """One shared struct: its C name, doc line, fields, and the numpy twin."""

    def __init__(self, name: str, doc: str, fields: list[tuple]):
        self.name = name
        self.doc = doc
        self.fields = [Field(*f) for f in fields]
        self.dtype = self._dtype()

    def _dtype(self) -> np.dtype:
        names, formats, offsets, offset, align = [], [], [], 0, 4
        for f in self.fields:
            scalar, lanes = _TYPES[f.ctype]
            size = 4 * lanes
            offset = -(-offset // size) * size
            shape = tuple(s for s in (f.count, lanes) if s > 1)
            names.append(f.name)
            formats.append((scalar, shape) if shape else scalar)
            offsets.append(offset)
            offset += size * f.count
            align = max(align, size)
        itemsize = -(-offset // align) * align
        return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize})

    def c_declaration(self) -> str:
        lines = [f"/* {self.doc} ({self.dtype.itemsize} bytes) */", "typedef struct {"]
        for f in self.fields:
            array = f"[{f.count}]" if f.count > 1 else ""
            doc = f" /* {f.doc} */" if f.doc else ""
            lines.append(f"    {f.ctype} {f.name}{array};{doc}")
        lines.append(f"}} {self.name};")
        return "\n".join(lines)


KD_NODE = Struct("KdNode", "a kd-tree node in preorder: the left child of an inner node is the next node", [
    ("split", "float", "inner: the plane's position"),
    ("axis", "int", "0..2, or KD_LEAF"),
    ("child", "int", "inner: the right child; leaf: first slot of its index list"),
    ("count", "int", "leaf: entries in its index list; inner: 0"),
])

MATERIAL = Struct("Material", "a material row (shading/bsdf.h)", [
    ("base_color", "float4", "rgb; w = alpha"),
    ("emission", "float4", "rgb radiance (colour x strength)"),
    ("specular_tint", "float4", "rgb: Specular Tint; w: index of the specular layer (1 = none)"),
    ("specular_fss", "float4", "rgb: the specular layer's mean Fresnel over the hemisphere"),
    ("metallic", "float"),
    ("roughness", "float"),
    ("transmission", "float"),
    ("ior", "float"),
    ("texture", "int", "Base Color's texture: index into the texture table, -1 for none"),
    ("shader", "int", "MATERIAL_PRINCIPLED, MATERIAL_GLOSSY or MATERIAL_GLASS"),
    ("roughness_texture", "int", "Roughness's texture, -1 for none"),
    ("roughness_channel", "int", "its channel: 0-3 r, g, b, a; TEXTURE_LUMINANCE"),
    ("metallic_texture", "int", "Metallic's texture, -1 for none"),
    ("metallic_channel", "int", "its channel, as roughness_channel"),
    ("normal_texture", "int", "a tangent-space normal map, -1 for none"),
    ("normal_strength", "float", "the Normal Map node's Strength"),
    ("mix_next", "int", "a mix of surfaces: the chain's next row (after this one), -1 at its end"),
    ("mix_stop", "float", "the chance of using this row once the pick reached it (1 at the chain's end)"),
    ("mix_scale", "float", "what the BSDF and pass-through are scaled by: weight / chance of the pick"),
    ("mix_texture", "int", "a Mix Shader's Fac texture: mix_stop = 1 - its value, -1 for none"),
    ("mix_channel", "int", "its channel, as roughness_channel"),
    ("aniso_x", "float", "the metal and specular lobes' alpha along the tangent over roughness^2 (1: isotropic)"),
    ("aniso_y", "float", "and along the bitangent"),
    ("aniso_rotation", "float", "the tangent turned about the normal, in turns"),
    ("diffuse_roughness", "float", "the diffuse lobe's Oren-Nayar roughness (0: Lambert)"),
    ("single_scatter", "int", "1: GGX without Multiscatter GGX's energy compensation (Cycles' GGX distribution)"),
    ("pad", "int", "", 2),
])

LIGHT = Struct("Light", "a light row; derived values are computed on the host in float64", [
    ("position", "float4", "xyz (sun: unused)"),
    ("direction", "float4", "xyz unit: where it shines, the light's -Z"),
    ("axis_u", "float4", "area: full size along the light's X"),
    ("axis_v", "float4", "area: full size along the light's Y"),
    ("power", "float4", "rgb: watts (sun: W/m^2)"),
    ("radiance", "float4", "rgb radiance a ray sees on the light; 0 = not visible"),
    ("radius", "float", "point, spot: radius of the disk facing the receiver"),
    ("cos_half", "float", "spot: cos of half the cone; sun: cos of half the disk"),
    ("spot_smooth", "float", "spot: 1 / ((1 - cos_half) * blend), smoothstep scale"),
    ("sun_norm", "float", "sun: 2 / (1 + cos_half), so the disk gives S at normal incidence"),
    ("kind", "int", "LIGHT_*"),
    ("shape", "int", "area: AREA_RECTANGLE or AREA_ELLIPSE"),
    ("pick", "float", "inclusive CDF of picking this light for a shadow ray, by the power it emits"),
    ("pad", "int"),
])

CAMERA = Struct("Camera", "the camera", [
    ("right", "float4", "camera X axis in world space"),
    ("up", "float4", "camera Y axis"),
    ("back", "float4", "camera Z axis (it looks down -Z)"),
    ("origin", "float4", "position"),
    ("window", "float4", "x0, x1, y0, y1 on the plane z = -1 (ortho: scene units)"),
    ("kind", "int", "CAMERA_PERSP or CAMERA_ORTHO"),
    ("width", "int", "full image size in pixels"),
    ("height", "int"),
    ("pad0", "int"),
    ("clip_start", "float"),
    ("clip_end", "float"),
    ("pad1", "float", "", 2),
])

TEXTURE_INFO = Struct("TextureInfo", "a texture's place in the shared float4 atlas", [
    ("offset", "int"), ("width", "int"), ("height", "int"),
    ("closest", "int", "1: the nearest texel (Closest interpolation), 0: bilinear (Linear)"),
])

POINT_NODE = Struct("PointNode", "a point-tree node's payload, at its preorder index; the points of a "
                    "subtree are [first, first + count) in leaf order", [
    ("lo", "float4", "tight bounds of the subtree's points; w = r_p"),
    ("hi", "float4", "w unused"),
    ("power", "float4", "summed photon power (rgb)"),
    ("irradiance", "float4", "approximate irradiance E~_p (rgb)"),
    ("normal", "float4", "representative unit normal (0 when unknown); w = |mean photon normal|"),
    ("mean", "float4", "mean position of the subtree's points"),
    ("first", "int"),
    ("count", "int"),
    ("depth", "int", "root = 0"),
    ("pad", "int"),
])

BUILD_NODE = Struct("BuildNode", "a point-tree node under construction", [
    ("lo", "float4", "cell: inherited box (large), split of the root's tight box (small)"),
    ("hi", "float4"),
    ("start", "int", "first point of its segment, or of its small root's segment"),
    ("count", "int", "points below it"),
    ("mask", "uint", "small nodes: bit i = point start + i belongs to it"),
    ("root", "int", "small nodes: index of the small root; -1 in the large stage"),
    ("left", "int", "id of the left child (the right one is left + 1); -1 for a leaf"),
    ("axis", "int", "split axis, or BUILD_COUNT_SPLIT"),
    ("split", "float", "plane: left points < split <= right points (ties may go either way)"),
    ("depth", "int"),
])

CHUNK = Struct("Chunk", "up to BUILD_CHUNK points of one active large node", [
    ("slot", "int", "index in the active list"),
    ("start", "int", "first point"),
    ("count", "int"),
    ("rank", "int", "chunk number within its node"),
])

BUILD_SUMS = Struct("BuildSums", "sums over a subtree's points, gathered bottom-up", [
    ("lo", "float4"),
    ("hi", "float4"),
    ("power", "float4", "sum of Phi_i"),
    ("normal", "float4", "sum of n_i"),
    ("position", "float4", "sum of the positions"),
    ("moment", "float4", "per channel c: sum of w_i Phi_i[c]", 3),
])

PHOTON_EMITTER = Struct("PhotonEmitter", "one emitter's share of the photons", [
    ("power", "float4", "rgb power per photon; spot: before the falloff; mesh: unused"),
    ("light", "int", "row of the light table, or PHOTON_EMITTER_WORLD"),
    ("first", "int", "first photon index of this emitter"),
    ("count", "int", "its photons"),
    ("pad", "int"),
])

IMAGE_JOB = Struct("ImageJob", "what one launch of the image kernel renders", [
    ("window", "int4", "render window width, height; pixels in this launch; first pixel of the launch"),
    ("origin", "int2", "the window's lower-left pixel in the full image"),
    ("samples", "int", "camera paths per pixel"),
    ("max_bounces", "int", "specular bounces"),
    ("max_diffuse", "int", "path-traced diffuse bounces"),
    ("light_samples", "int", "shadow rays per light at a diffuse event"),
    ("seed", "uint"),
    ("clamp", "float", "largest radiance of one path; 0 = off"),
    ("outputs", "int", "OUTPUT_* flags"),
    ("gi_subpixels", "int", "GI mode: shading points per pixel side of the cache grid"),
    ("sample_start", "int", "number of the first camera path of each pixel (progressive refinement)"),
    ("sample_limit", "int", "adaptive sampling: samples a pixel takes at most over all rounds"),
])

STRUCTS = (KD_NODE, MATERIAL, LIGHT, CAMERA, TEXTURE_INFO, POINT_NODE, BUILD_NODE, CHUNK, BUILD_SUMS,
           PHOTON_EMITTER, IMAGE_JOB)


def structs_header() -> str:
    """The generated ``device/structs.h``: every shared typedef."""
    body = "\n\n".join(s.c_declaration() for s in STRUCTS)
    return ("/* Generated from gpu_core/device/layout.py: the structs the host fills. */\n"
            "#ifndef GPUGI_STRUCTS_H\n#define GPUGI_STRUCTS_H\n\n" + body + "\n\n#endif\n")


def probe_source() -> str:
    """A kernel writing, per struct, its size and every field's offset (in
    declaration order), then sizeof(float3)."""
    lines = ['#include "device/structs.h"',
             "#define LAYOUT_OFFSET(T, f) ((int)((size_t) & (((T *)0)->f)))",
             "__kernel void Layout_probe(__global int *out) {", "    int i = 0;"]
    for s in STRUCTS:
        lines.append(f"    out[i++] = sizeof({s.name});")
        lines += [f"    out[i++] = LAYOUT_OFFSET({s.name}, {f.name});" for f in s.fields]
    lines += ["    out[i++] = sizeof(float3);", "}"]
    return "\n".join(lines) + "\n"


# the numpy twins, by the names host code uses
KDNODE_DTYPE = KD_NODE.dtype
MATERIAL_DTYPE = MATERIAL.dtype
LIGHT_DTYPE = LIGHT.dtype
CAMERA_DTYPE = CAMERA.dtype
TEXTURE_INFO_DTYPE = TEXTURE_INFO.dtype
POINT_NODE_DTYPE = POINT_NODE.dtype
BUILD_NODE_DTYPE = BUILD_NODE.dtype
CHUNK_DTYPE = CHUNK.dtype
BUILD_SUMS_DTYPE = BUILD_SUMS.dtype
EMITTER_DTYPE = PHOTON_EMITTER.dtype
IMAGE_JOB_DTYPE = IMAGE_JOB.dtype


def float4_rows(vectors) -> np.ndarray:
    """(N, 3) vectors as (N, 4) float32 rows with w = 0 (float3 on the device is 16 bytes)."""
    vectors = np.asarray(vectors, np.float32).reshape(-1, 3)
    out = np.zeros((len(vectors), 4), np.float32)
    out[:, :3] = vectors
    return out


def rows_differ(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row (first axis) of two arrays of one shape and dtype, whether
    their bytes differ: one comparison per row, however wide."""
    count = len(a)
    row = np.dtype((np.void, a.itemsize * (a.size // count if count else 1)))
    return (np.ascontiguousarray(a).reshape(count, -1).view(row).ravel()
            != np.ascontiguousarray(b).reshape(count, -1).view(row).ravel())


def finite_rows(name: str, array, columns: int, dtype) -> np.ndarray:
    """``array`` as a contiguous (N, columns) array, or ValueError naming it."""
    arr = np.ascontiguousarray(np.asarray(array, dtype).reshape(-1, columns))
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ValueError(f"{name} holds NaN or infinite values")
    return arr
