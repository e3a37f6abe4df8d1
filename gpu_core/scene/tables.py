"""The scene as the kernels read it, on the host: material, light, texture
and camera tables in the shared struct layouts (device/layout.py), and the
emissive triangles sampled as one mesh light. Built once per scene, part by
part (``SceneTables``), and read by the plan, the upload and photon emission,
so all of them see the same lights in the same units."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..device.constants import (AREA_ELLIPSE, CAMERA_ORTHO, LIGHT_AREA, LIGHT_MESH, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN,
                                MATERIAL_GLASS, MATERIAL_GLOSSY, MATERIAL_PRINCIPLED, MATERIAL_TRANSPARENT,
                                TEXTURE_LUMINANCE)
from ..device.layout import CAMERA_DTYPE, LIGHT_DTYPE, MATERIAL_DTYPE, TEXTURE_INFO_DTYPE
from ..shading import microfacet_tables
from .model import LUMINANCE_WEIGHTS, PARTS, Scene

RADIANCE_MAX = 1e30  # light radiance stays a finite float32
# The device frame (positions relative to a centre) stays where it is while
# the centre of the scene's bounds moves by less than this share of their
# half-diagonal: an object moved a little keeps every other triangle's
# device coordinates, so the kd-tree held can be overlaid (accel/kdtree_overlay.py).
FRAME_SLACK = 0.25


@dataclass
class SceneTables:
    """Everything the kernels read about a validated scene but its triangles,
    in the device frame: positions relative to ``center``."""

    center: np.ndarray  # (3,) float64: the centre of the scene's bounds
    radius: float  # of the scene's bounding sphere (sun and world photons)
    materials: np.ndarray  # MATERIAL_DTYPE rows
    lights: np.ndarray  # LIGHT_DTYPE rows, a LIGHT_MESH row last when there are emissive triangles
    emitted: np.ndarray  # (L, 3) float64: the rgb watts each light row emits (emitted_power)
    emit_tris: np.ndarray  # int32 emissive triangle ids
    emit_cdf: np.ndarray  # float32 their inclusive CDF by power
    atlas: np.ndarray  # (T, 4) float32 texels of every texture
    texture_infos: np.ndarray  # TEXTURE_INFO_DTYPE rows
    camera: np.ndarray  # one CAMERA_DTYPE row
    triangle_bounds: np.ndarray  # (2, 3) min and max of the triangles (kept while the geometry is)


def frame_center(lo: np.ndarray, hi: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
    """The centre of the device frame for bounds [lo, hi]: their centre, or
    the ``previous`` frame's while that lies within FRAME_SLACK of it."""
    mid = 0.5 * (lo + hi)
    if previous is not None:
        if float(np.linalg.norm(mid - previous)) <= FRAME_SLACK * 0.5 * float(np.linalg.norm(hi - lo)):
            return previous
    return mid


def scene_tables(scene: Scene, previous: SceneTables | None = None, changed=PARTS) -> SceneTables:
    """The tables of a validated ``scene``; those of ``previous`` are kept
    where no part they are made from is in ``changed``."""
    if previous is not None and "geometry" not in changed:
        triangle_bounds = previous.triangle_bounds
    else:
        triangle_bounds = scene.triangle_bounds()
    lo, hi = scene.bounds(triangle_bounds)
    center = frame_center(lo, hi, None if previous is None else previous.center)
    moved = previous is None or not np.array_equal(center, previous.center)
    changed = set(PARTS) if moved else set(changed)
    # the bounding sphere about the frame's centre
    radius = max(float(np.linalg.norm(np.maximum(hi - center, center - lo))), 1e-6)
    old = previous if not moved else None
    if old is None or changed & {"geometry", "materials"}:
        emit_tris, emit_cdf = emissive_triangles(scene)
    else:
        emit_tris, emit_cdf = old.emit_tris, old.emit_cdf
    if old is None or "materials" in changed:
        materials = material_table(scene)
        atlas, infos = texture_atlas(scene.textures, scene.texture_closest)
    else:
        materials, atlas, infos = old.materials, old.atlas, old.texture_infos
    if old is None or changed & {"lights", "geometry", "materials"}:
        lights, emitted = light_table(scene, center, radius, emit_tris)
    else:
        lights, emitted = old.lights, old.emitted
    camera = camera_struct(scene, center) if old is None or "camera" in changed else old.camera
    return SceneTables(center, radius, materials, lights, emitted, emit_tris, emit_cdf, atlas, infos, camera,
                       triangle_bounds)


def scene_defines(scene: Scene) -> dict:
    """The features every program reading ``scene`` is compiled with: only
    those it has (textures, see-through surfaces, mixes of surfaces, corner
    tangents for normal maps and anisotropy)."""
    has = {"SCENE_HAS_TEXTURES": scene.has_textures(), "SCENE_HAS_ALPHA": scene.has_alpha(),
           "SCENE_HAS_MIX": scene.has_mix(), "SCENE_HAS_TANGENTS": scene.has_tangents()}
    return {define: 1 for define, wanted in has.items() if wanted}


def material_table(scene: Scene) -> np.ndarray:
    m = scene.materials
    table = np.zeros(len(m), MATERIAL_DTYPE)
    table["base_color"][:, :3] = np.clip(np.nan_to_num(m.base_color), 0.0, 1.0)
    shader = np.where(np.isin(m.shader, (MATERIAL_GLOSSY, MATERIAL_GLASS, MATERIAL_TRANSPARENT)), m.shader,
                      MATERIAL_PRINCIPLED)
    # a Transparent row lets everything through, tinted by its colour
    table["base_color"][:, 3] = np.where(shader == MATERIAL_TRANSPARENT, 0.0,
                                         np.clip(np.nan_to_num(m.alpha, nan=1.0), 0.0, 1.0))
    table["emission"][:, :3] = emission_radiance(scene)
    table["shader"] = shader
    # the Glossy and Glass nodes are one lobe each
    table["metallic"] = np.where(shader == MATERIAL_GLOSSY, 1.0, np.where(
        shader == MATERIAL_PRINCIPLED, np.clip(np.nan_to_num(m.metallic), 0.0, 1.0), 0.0))
    table["transmission"] = np.where(shader == MATERIAL_GLASS, 1.0, np.where(
        shader == MATERIAL_PRINCIPLED, np.clip(np.nan_to_num(m.transmission), 0.0, 1.0), 0.0))
    table["roughness"] = np.clip(np.nan_to_num(m.roughness), 0.0, 1.0)
    table["ior"] = np.clip(np.nan_to_num(m.ior, nan=1.5), 1e-3, 1e3)
    table["texture"] = _texture_index(m.texture_id, scene)
    table["roughness_texture"] = _texture_index(m.roughness_texture, scene)
    table["roughness_channel"] = np.clip(m.roughness_channel, 0, TEXTURE_LUMINANCE)
    table["metallic_texture"] = np.where(shader == MATERIAL_PRINCIPLED, _texture_index(m.metallic_texture, scene), -1)
    table["metallic_channel"] = np.clip(m.metallic_channel, 0, TEXTURE_LUMINANCE)
    table["normal_texture"] = _texture_index(m.normal_texture, scene)
    table["normal_strength"] = np.clip(np.nan_to_num(m.normal_strength, nan=1.0), 0.0, 1e3)
    table["mix_next"] = m.next_rows()
    table["mix_stop"] = np.where(table["mix_next"] >= 0, np.clip(np.nan_to_num(m.mix_stop, nan=1.0), 0.0, 1.0), 1.0)
    table["mix_scale"] = np.clip(np.nan_to_num(m.mix_scale, nan=1.0), 0.0, 1e3)
    table["mix_texture"] = np.where(table["mix_next"] >= 0, _texture_index(m.mix_texture, scene), -1)
    table["mix_channel"] = np.clip(m.mix_channel, 0, TEXTURE_LUMINANCE)
    table["aniso_x"], table["aniso_y"] = anisotropic_scales(shader, m.anisotropy)
    table["aniso_rotation"] = np.nan_to_num(m.anisotropic_rotation) % 1.0
    table["diffuse_roughness"] = np.clip(np.nan_to_num(m.diffuse_roughness), 0.0, 1.0)
    table["single_scatter"] = (m.single_scatter != 0).astype(np.int32)
    level = np.where(shader == MATERIAL_PRINCIPLED, np.clip(np.nan_to_num(m.specular_ior_level), 0.0, 1e3), 0.0)
    tint = np.clip(np.nan_to_num(m.specular_tint, nan=1.0), 0.0, 1e3)
    table["specular_tint"][:, :3] = tint
    for row, (ior, lvl, row_tint) in enumerate(zip(table["ior"], level, tint)):
        eta, fss = specular_layer(float(ior), float(lvl), row_tint)
        table["specular_tint"][row, 3] = eta
        table["specular_fss"][row, :3] = fss
    return table


def anisotropic_scales(shader: np.ndarray, anisotropy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """alpha_x and alpha_y over roughness^2, as Cycles stretches its lobes:
    Principled (Anisotropic a in 0..1) by the aspect sqrt(1 - 0.9 a), x
    over it and y times it; the Glossy node (Anisotropy a in -0.99..0.99)
    by 1 - a and its reciprocal (x the shorter for a > 0); glass none. The
    product stays 1: the lobes' albedo tables read roughness^2 as before."""
    a = np.nan_to_num(np.asarray(anisotropy, np.float64))
    principled = np.sqrt(1.0 - 0.9 * np.clip(a, 0.0, 1.0))
    glossy = np.clip(a, -0.99, 0.99)
    glossy_x = np.where(glossy < 0.0, 1.0 / (1.0 + glossy), 1.0 - glossy)
    x = np.where(shader == MATERIAL_PRINCIPLED, 1.0 / principled, np.where(shader == MATERIAL_GLOSSY, glossy_x, 1.0))
    return x.astype(np.float32), (1.0 / x).astype(np.float32)


def _texture_index(ids: np.ndarray, scene: Scene) -> np.ndarray:
    """Texture indices of a column, -1 where none or out of the table."""
    return np.where((ids >= 0) & (ids < len(scene.textures)), ids, -1).astype(np.int32)


def specular_layer(ior: float, level: float, tint) -> tuple[float, np.ndarray]:
    """The index of Principled's dielectric specular layer for Specular IOR
    Level ``level`` (Cycles: F0 of the IOR times 2 level; 1 = no layer), and
    its mean Fresnel over the hemisphere with F0 tinted by ``tint``."""
    f0 = microfacet_tables.f0_from_ior(ior) * 2.0 * level
    if f0 <= 0.0:
        return 1.0, np.zeros(3, np.float32)
    eta = float(microfacet_tables.ior_from_f0(f0))
    eta = 1.0 / eta if ior < 1.0 else eta
    real0 = microfacet_tables.f0_from_ior(eta)
    s = np.clip((microfacet_tables.fresnel_average(eta) - real0) / max(1.0 - real0, 1e-7), 0.0, 1.0)
    tinted = np.minimum(real0 * np.asarray(tint, np.float64), 1.0)
    return eta, (tinted + (1.0 - tinted) * s).astype(np.float32)


def emission_radiance(scene: Scene) -> np.ndarray:
    """Material emission radiance, finite and not negative."""
    e = np.nan_to_num(np.asarray(scene.materials.emission, np.float64), nan=0.0, posinf=RADIANCE_MAX)
    return np.clip(e, 0.0, RADIANCE_MAX).astype(np.float32)


def emissive_triangles(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Emissive triangle ids and their inclusive CDF by power (luminance x area)."""
    if scene.triangle_count == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.float32)
    # each material's luminance, the weighted sum written out (not ``@``: OpenBLAS's threads
    # would take it from 3,072 materials on and spin beside the kernels)
    e, (r, g, b) = emission_radiance(scene).astype(np.float64), LUMINANCE_WEIGHTS
    luminance = (e[:, 0] * r + e[:, 1] * g + e[:, 2] * b)[scene.material_ids]
    lit = np.flatnonzero(luminance > 0)  # the areas of emissive triangles only
    tris = scene.triangles[lit]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    power = luminance[lit] * area
    ids = lit[power > 0].astype(np.int32)
    if ids.size == 0:
        return ids, np.zeros(0, np.float32)
    cdf = np.cumsum(power[power > 0])
    cdf = (cdf / cdf[-1]).astype(np.float32)
    cdf[-1] = 1.0
    return ids, cdf


def light_table(scene: Scene, center: np.ndarray, radius: float,
                emit_tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Device light rows in Cycles' units (see shading/lights.h) and the
    rgb watts each emits; the emissive triangles ``emit_tris`` add one
    LIGHT_MESH row. Derived values are computed in float64. Each row's pick
    is the inclusive CDF of choosing it for a shadow ray, in proportion to
    the power it emits."""
    lights = scene.lights
    n = len(lights)
    table = np.zeros(n + (1 if len(emit_tris) else 0), LIGHT_DTYPE)
    if len(emit_tris):
        table["kind"][n] = LIGHT_MESH
    if n:
        _light_rows(scene, center, table)
    emitted = emitted_power(scene, table, radius, emit_tris)
    # weights relative to the strongest light, so the sum stays finite
    weight = np.nan_to_num(emitted.sum(axis=1), nan=0.0, posinf=1e300)
    if len(table) and weight.max() > 0:
        weight = weight / weight.max()
        table["pick"] = np.cumsum(weight) / weight.sum()
        table["pick"][-1] = 1.0
    return table, emitted


def _light_rows(scene: Scene, center: np.ndarray, table: np.ndarray) -> None:
    """Fill the first rows of ``table`` from the scene's lights."""
    lights = scene.lights
    n = len(lights)
    kind = lights.kind
    power = finite(lights.power)
    direction = finite(lights.direction)
    length = np.linalg.norm(direction, axis=1, keepdims=True)
    direction = np.where(length > 0, direction / np.where(length > 0, length, 1.0), [0.0, 0.0, -1.0])
    axis_u, axis_v = finite(lights.axis_u), finite(lights.axis_v)
    radius = np.maximum(finite(lights.radius), 0.0)

    # area lights: radiance P / (pi A), A of the rectangle or ellipse
    area = np.linalg.norm(np.cross(axis_u, axis_v), axis=1)
    area = np.where(lights.shape == AREA_ELLIPSE, area * np.pi / 4.0, area)
    is_area = kind == LIGHT_AREA
    power[is_area & ~(area > 0)] = 0.0  # a zero-size area light emits nothing
    radiance = np.zeros_like(power)
    with np.errstate(divide="ignore", invalid="ignore"):
        radiance[is_area] = power[is_area] / (np.pi * area[is_area, None])
        # point and spot lights: a disk of radius r with radiance P / (4 pi^2 r^2)
        disk = ((kind == LIGHT_POINT) | (kind == LIGHT_SPOT)) & (radius > 0)
        radiance[disk] = power[disk] / (4.0 * np.pi**2 * radius[disk, None] ** 2)

    # spot cone: cos of the half angle and the smoothstep scale of the blend
    cos_half = np.ones(n)
    spot = kind == LIGHT_SPOT
    cos_spot = np.cos(0.5 * np.clip(finite(lights.spot_angle), 0.0, np.pi))
    cos_half[spot] = cos_spot[spot]
    blend_width = (1.0 - cos_spot) * np.clip(finite(lights.spot_blend), 0.0, 1.0)
    spot_smooth = np.where(blend_width > 1e-12, 1.0 / np.maximum(blend_width, 1e-12), 1e30)

    # sun: a disk of directions with radiance S / (pi sin^2(half angle))
    sun = kind == LIGHT_SUN
    half = 0.5 * np.clip(finite(lights.sun_angle), 0.0, np.pi)
    cos_half[sun] = np.cos(half[sun])
    sun_disk = sun & (half > 0)
    radiance[sun_disk] = power[sun_disk] / (np.pi * np.sin(half[sun_disk, None]) ** 2)
    sun_norm = np.where(sun, 2.0 / (1.0 + cos_half), 1.0)

    table["position"][:n, :3] = finite(lights.position - center)
    table["direction"][:n, :3] = direction
    table["axis_u"][:n, :3] = axis_u
    table["axis_v"][:n, :3] = axis_v
    table["power"][:n, :3] = power
    table["radiance"][:n, :3] = np.clip(np.nan_to_num(radiance, nan=0.0, posinf=RADIANCE_MAX), 0.0, RADIANCE_MAX)
    table["radius"][:n] = radius
    table["cos_half"][:n] = cos_half
    table["spot_smooth"][:n] = spot_smooth
    table["sun_norm"][:n] = sun_norm
    table["kind"][:n] = kind
    table["shape"][:n] = lights.shape


def emitted_power(scene: Scene, table: np.ndarray, radius: float, emit_tris: np.ndarray) -> np.ndarray:
    """(N, 3) float64: the rgb watts each light row emits. A sun's is what
    falls on the scene's bounding disk (radius ``radius``); the mesh row's,
    both faces of every emissive triangle."""
    out = np.zeros((len(table), 3))
    for row, light in enumerate(table):
        kind, power = int(light["kind"]), light["power"][:3].astype(np.float64)
        if kind in (LIGHT_POINT, LIGHT_AREA):
            out[row] = power
        elif kind == LIGHT_SPOT:
            out[row] = spot_power(power, float(light["cos_half"]), float(light["spot_smooth"]))
        elif kind == LIGHT_SUN:
            out[row] = power * np.pi * radius**2
        elif kind == LIGHT_MESH:
            out[row] = mesh_power(scene, emit_tris)
    return out


def spot_power(power: np.ndarray, cos_half: float, spot_smooth: float) -> np.ndarray:
    """Power a spot light emits: P / (4 pi) times the integral of its
    smoothstep falloff over the sphere, 2 pi int smoothstep((c - cos_half) s) dc."""
    width = 1.0 - cos_half
    a = min(width * spot_smooth, 1.0)
    ramp = (a**3 - 0.5 * a**4) / spot_smooth  # the smoothstep's rise
    flat = max(width - 1.0 / spot_smooth, 0.0)  # where it is 1
    return np.asarray(power, np.float64) * 0.5 * (ramp + flat)


def mesh_power(scene: Scene, emit_tris: np.ndarray) -> np.ndarray:
    """Both faces of every emissive triangle: sum of 2 pi A L_e."""
    tris = scene.triangles[emit_tris]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    emission = emission_radiance(scene).astype(np.float64)[scene.material_ids[emit_tris]]
    return 2.0 * np.pi * (area[:, None] * emission).sum(axis=0)


def finite(values) -> np.ndarray:
    """float64 copy with NaN and infinities replaced by 0."""
    return np.nan_to_num(np.asarray(values, np.float64), nan=0.0, posinf=0.0, neginf=0.0)


def texels(scene: Scene) -> int:
    """Texels of all textures: the atlas holds one float4 each."""
    return sum(int(np.prod(np.shape(t)[:2])) for t in scene.textures)


def texture_atlas(textures: list[np.ndarray], closest=()) -> tuple[np.ndarray, np.ndarray]:
    """All textures in one float4 array, and each one's offset, size and
    filter (``closest[i]``: the nearest texel; bilinear where not given)."""
    infos = np.zeros(max(len(textures), 1), TEXTURE_INFO_DTYPE)
    chunks, offset = [], 0
    for i, tex in enumerate(textures):
        img = np.asarray(tex, np.float32)
        if img.ndim == 2:
            img = img[..., None]
        if img.shape[2] == 1:
            img = np.concatenate([np.repeat(img, 3, axis=2), np.ones(img.shape[:2] + (1,), np.float32)], axis=2)
        if img.shape[2] == 3:
            img = np.concatenate([img, np.ones(img.shape[:2] + (1,), np.float32)], axis=2)
        img = np.nan_to_num(img[..., :4], nan=0.0, posinf=0.0, neginf=0.0)
        infos[i] = (offset, img.shape[1], img.shape[0], int(bool(closest[i])) if i < len(closest) else 0)
        chunks.append(img.reshape(-1, 4))
        offset += img.shape[0] * img.shape[1]
    atlas = np.concatenate(chunks) if chunks else np.zeros((1, 4), np.float32)
    return np.ascontiguousarray(atlas, np.float32), infos


def camera_struct(scene: Scene, center: np.ndarray) -> np.ndarray:
    """The camera row in the device frame (positions relative to ``center``)."""
    cam = scene.camera
    m = np.asarray(cam.matrix, np.float64)
    axes = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    out = np.zeros(1, CAMERA_DTYPE)
    out["right"][0, :3] = axes[:, 0]
    out["up"][0, :3] = axes[:, 1]
    out["back"][0, :3] = axes[:, 2]
    out["origin"][0, :3] = m[:3, 3] - center
    out["window"][0] = cam.window
    out["kind"] = CAMERA_ORTHO if cam.kind == CAMERA_ORTHO else 0
    out["width"], out["height"] = cam.width, cam.height
    out["clip_start"], out["clip_end"] = cam.clip_start, cam.clip_end
    return out
