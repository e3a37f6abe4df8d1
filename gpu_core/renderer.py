"""The renderer: plans the stages a scene needs, uploads it, runs the kernels.

One Renderer serves F12, ``blender -b`` and the viewport. ``render`` runs the
image kernel over the render window in batches; between batches it reports
progress and asks whether to stop, so Esc in Blender takes effect quickly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyopencl as cl

from . import kdtree
from .device import Device
from .errors import BudgetError, RenderCancelled
from .layout import CAMERA_DTYPE, LIGHT_DTYPE, MATERIAL_DTYPE, TEXTURE_INFO_DTYPE
from .scene import (
    AREA_ELLIPSE,
    CAMERA_ORTHO,
    LIGHT_AREA,
    LIGHT_POINT,
    LIGHT_SPOT,
    LIGHT_SUN,
    Scene,
    validate,
)
from .settings import MODES_AVAILABLE, RenderSettings

LIGHT_MESH = 4  # kernels/types.h: all emissive triangles as one light row
_BATCH_SECONDS = 0.1  # aimed duration of one kernel launch (cancel latency)
_FIRST_BATCH_PATHS = 1 << 14  # camera paths in the first launch, before any timing
_MIN_BATCH = 64
_RADIANCE_MAX = 1e30  # light radiance stays a finite float32

# Light passes in the kernel's order (kernels/render.cl PASS_*), named as
# Blender names them; all but Caustics add up to Combined.
LIGHT_PASSES = (
    "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect",
    "Transmission Direct", "Transmission Indirect", "Emission", "Environment", "Caustics",
)
DENOISING_PASSES = ("Denoising Albedo", "Denoising Normal", "Denoising Depth")
_OUTPUT_LIGHT_PASSES, _OUTPUT_DENOISING = 1, 2  # kernels/render.cl OUTPUT_*


@dataclass
class RenderResult:
    """Passes of the render window (rows from the bottom), stats and warnings."""

    passes: dict[str, np.ndarray]
    stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


class _Timer:
    """Milliseconds per named stage, in the order the stages ran."""

    def __init__(self):
        self.ms: dict[str, float] = {}

    def stage(self, name: str):
        timer = self

        class _Stage:
            def __enter__(self):
                self.start = time.perf_counter()

            def __exit__(self, *exc):
                timer.ms[name] = timer.ms.get(name, 0.0) + (time.perf_counter() - self.start) * 1e3

        return _Stage()


@dataclass
class _Uploaded:
    """Device-side scene: everything the image kernel reads."""

    tree: kdtree.KdTree
    normals: cl.Buffer
    uvs: cl.Buffer
    material_ids: cl.Buffer
    materials: cl.Buffer
    lights: cl.Buffer
    light_count: int
    emit_tris: cl.Buffer
    emit_cdf: cl.Buffer
    emit_count: int
    atlas: cl.Buffer
    texture_infos: cl.Buffer
    camera: cl.Buffer
    world: np.ndarray


class Renderer:
    """Renders gpu_core scenes on one OpenCL device."""

    def __init__(self, device: Device):
        self.device = device

    def render(
        self,
        scene: Scene,
        settings: RenderSettings | None = None,
        progress: Callable[[float, str], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> RenderResult:
        settings = (settings or RenderSettings()).validated()
        mode, mode_warning = _mode(settings)
        timer = _Timer()
        with timer.stage("validate"):
            scene = validate(scene)
        emit_tris, emit_cdf = _emissive_triangles(scene)
        plan, defines = _plan(scene, settings, len(emit_tris))
        self._check_budget(scene, settings)
        _check_stop(should_stop)

        # positions relative to the scene centre keep float32 precision far from the origin
        lo, hi = scene.bounds()
        center = 0.5 * (lo + hi)
        with timer.stage("kdtree"):
            tree = kdtree.build(self.device, (scene.triangles - center).astype(np.float32))
        _check_stop(should_stop)
        with timer.stage("upload"):
            up = self._upload(scene, center, tree, emit_tris, emit_cdf)
        with timer.stage("compile"):
            program = self.device.program("render.cl", defines)
        _check_stop(should_stop)
        with timer.stage("render"):
            passes, batches = self._run(program, up, scene, settings, progress, should_stop)
        stats = {
            "device": self.device.name,
            "mode": mode,
            "mode_requested": settings.mode,
            "plan": plan,
            "ms": timer.ms,
            "triangles": scene.triangle_count,
            "lights": len(scene.lights),
            "emissive_triangles": up.emit_count,
            "textures": len(scene.textures),
            "batches": batches,
            "samples": settings.samples,
            "light_samples": settings.light_samples,
            "device_bytes": _device_bytes(scene, settings),
            "kdtree": up.tree.stats,
            **scene.report.as_stats(),
        }
        warnings = list(scene.warnings) + ([mode_warning] if mode_warning else [])
        if self.device.fallback_message:
            warnings.append(self.device.fallback_message)
        return RenderResult(passes=passes, stats=stats, warnings=warnings)

    # -- upload ---------------------------------------------------------------

    def _check_budget(self, scene: Scene, settings: RenderSettings) -> None:
        """A clear error before any upload when the scene cannot fit the device."""
        dev = self.device
        need = _device_bytes(scene, settings)
        largest = max(scene.triangle_count * 48, _texels(scene) * 16)
        if need > dev.global_mem_bytes or largest > dev.max_alloc_bytes:
            raise BudgetError(
                f"the scene needs about {need / 2**20:.0f} MiB of device memory "
                f"(largest buffer {largest / 2**20:.0f} MiB); {dev.name} has "
                f"{dev.global_mem_bytes / 2**20:.0f} MiB ({dev.max_alloc_bytes / 2**20:.0f} MiB per buffer). "
                "Lower the resolution or texture sizes, or simplify the scene."
            )

    def _upload(self, scene: Scene, center: np.ndarray, tree: kdtree.KdTree,
                emit_tris: np.ndarray, emit_cdf: np.ndarray) -> _Uploaded:
        dev = self.device
        normals = np.zeros((scene.triangle_count * 3, 4), np.float32)
        normals[:, :3] = scene.normals.reshape(-1, 3)
        uvs = np.ascontiguousarray(scene.uvs.reshape(-1, 2), dtype=np.float32)
        lights = _light_table(scene, center, has_mesh_lights=len(emit_tris) > 0)
        atlas, infos = _texture_atlas(scene.textures)
        return _Uploaded(
            tree=tree,
            normals=dev.buffer(normals),
            uvs=dev.buffer(uvs),
            material_ids=dev.buffer(scene.material_ids),
            materials=dev.buffer(_material_table(scene)),
            lights=dev.buffer(lights),
            light_count=len(lights),
            emit_tris=dev.buffer(emit_tris),
            emit_cdf=dev.buffer(emit_cdf),
            emit_count=len(emit_tris),
            atlas=dev.buffer(atlas),
            texture_infos=dev.buffer(infos),
            camera=dev.buffer(_camera_struct(scene, center)),
            world=np.append(scene.world_color, 0.0).astype(np.float32),
        )

    # -- image kernel ---------------------------------------------------------

    def _run(self, program, up: _Uploaded, scene: Scene, settings: RenderSettings, progress, should_stop):
        dev = self.device
        x0, y0, x1, y1 = scene.camera.pixel_window
        w, h = x1 - x0, y1 - y0
        total = w * h
        outputs = _outputs(settings)
        combined, depth, normal = dev.empty(total * 16), dev.empty(total * 4), dev.empty(total * 16)
        # passes nobody asked for get a one-element stand-in the kernel never writes
        light = dev.empty(total * 16 * len(LIGHT_PASSES) if settings.light_passes else 16)
        albedo, feature_normal = (dev.empty(total * 16 if settings.denoising_passes else 16) for _ in range(2))
        world = up.world.copy()
        world[3] = 1.0 if settings.transparent_background else 0.0
        kernel = cl.Kernel(program, "Render_pixels")
        # the first launch is sized by its path count; later ones by the measured speed
        paths_per_pixel = settings.samples * settings.light_samples
        batch = int(np.clip(_FIRST_BATCH_PATHS // paths_per_pixel, _MIN_BATCH, settings.batch_pixels))
        start, batches = 0, 0
        while start < total:
            count = min(batch, total - start)
            began = time.perf_counter()
            kernel(
                dev.queue, (count,), None,
                *up.tree.kernel_args(), up.normals, up.uvs, up.material_ids, up.materials,
                up.lights, np.int32(up.light_count), up.emit_tris, up.emit_cdf, np.int32(up.emit_count),
                up.atlas, up.texture_infos, up.camera, world,
                np.array([w, h, count, start], np.int32), np.array([x0, y0], np.int32),
                np.int32(settings.samples), np.int32(settings.max_bounces), np.int32(settings.diffuse_bounces),
                np.int32(settings.light_samples), np.uint32(settings.seed), np.float32(settings.clamp),
                np.int32(outputs), combined, depth, normal, light, albedo, feature_normal,
            )
            dev.queue.finish()
            elapsed = time.perf_counter() - began
            start += count
            batches += 1
            if progress is not None:
                progress(start / total, f"rendered {start}/{total} pixels")
            if start < total:
                _check_stop(should_stop)
            scale = _BATCH_SECONDS / max(elapsed, 1e-4)
            batch = int(np.clip(count * min(scale, 4.0), _MIN_BATCH, settings.batch_pixels))

        def read(buf, shape: tuple) -> np.ndarray:
            host = np.empty(shape, np.float32)
            cl.enqueue_copy(dev.queue, host, buf)
            return host

        def rgb(buf) -> np.ndarray:
            return np.ascontiguousarray(read(buf, (h, w, 4))[..., :3])

        passes = {"Combined": read(combined, (h, w, 4)), "Depth": read(depth, (h, w, 1)), "Normal": rgb(normal)}
        if settings.light_passes:
            layers = read(light, (len(LIGHT_PASSES), h, w, 4))
            passes.update((name, np.ascontiguousarray(layers[i, ..., :3])) for i, name in enumerate(LIGHT_PASSES))
        if settings.denoising_passes:
            passes["Denoising Albedo"] = rgb(albedo)
            passes["Denoising Normal"] = rgb(feature_normal)
            passes["Denoising Depth"] = passes["Depth"].copy()
        return passes, batches


def _outputs(settings: RenderSettings) -> int:
    """The kernel's output flags for the passes the settings ask for."""
    light = _OUTPUT_LIGHT_PASSES if settings.light_passes else 0
    return light | (_OUTPUT_DENOISING if settings.denoising_passes else 0)


def _mode(settings: RenderSettings) -> tuple[str, str | None]:
    """The mode that renders, and a warning when it is not the one asked for
    (a mode not built yet falls back to the reference path tracer)."""
    if settings.mode in MODES_AVAILABLE:
        return settings.mode, None
    return "reference", (f"render mode '{settings.mode}' (photon maps + irradiance cache) is not built yet; "
                         "rendered with the reference path tracer instead")


def _check_stop(should_stop) -> None:
    if should_stop is not None and should_stop():
        raise RenderCancelled("render cancelled")


def _plan(scene: Scene, settings: RenderSettings, emissive_count: int) -> tuple[list[str], dict]:
    """The stages and kernel features this scene needs, and their defines."""
    plan = ["validate", "kdtree", "upload", "direct_light"]
    defines = {}
    used = np.unique(scene.material_ids)
    m = scene.materials
    if ((m.metallic[used] > 0) | (m.transmission[used] > 0)).any():
        plan.append("specular_paths")
    if settings.diffuse_bounces > 0:
        plan.append("path_traced_indirect")
    if scene.textures and (m.texture_id[used] >= 0).any():
        plan.append("textures")
        defines["RENDER_HAS_TEXTURES"] = 1
    if emissive_count:
        plan.append("mesh_lights")
    if (m.alpha[used] < 1.0).any():
        plan.append("alpha_shadows")
        defines["RENDER_HAS_ALPHA"] = 1
    if settings.light_passes:
        plan.append("light_passes")
    if settings.denoising_passes:
        plan.append("denoising_passes")
    return plan, defines


def _device_bytes(scene: Scene, settings: RenderSettings) -> int:
    """Device memory the render needs, kd-tree nodes estimated."""
    n = scene.triangle_count
    x0, y0, x1, y1 = scene.camera.pixel_window
    geometry = n * (48 + 48 + 24 + 4)  # verts, normals, uvs, material ids
    tree = n * 4 * 8 + n * 16  # leaf references and nodes, a generous estimate
    textures = _texels(scene) * 16
    layers = 36  # combined, depth, normal: bytes per pixel
    if settings.light_passes:
        layers += 16 * len(LIGHT_PASSES)
    if settings.denoising_passes:
        layers += 32
    film = (x1 - x0) * (y1 - y0) * layers
    return int(geometry + tree + textures + film + len(scene.lights) * LIGHT_DTYPE.itemsize)


def _material_table(scene: Scene) -> np.ndarray:
    m = scene.materials
    table = np.zeros(len(m), MATERIAL_DTYPE)
    table["base_color"][:, :3] = np.clip(np.nan_to_num(m.base_color), 0.0, 1.0)
    table["base_color"][:, 3] = np.clip(np.nan_to_num(m.alpha, nan=1.0), 0.0, 1.0)
    table["emission"][:, :3] = _emission(scene)
    table["metallic"] = np.clip(np.nan_to_num(m.metallic), 0.0, 1.0)
    table["roughness"] = np.clip(np.nan_to_num(m.roughness), 0.0, 1.0)
    table["transmission"] = np.clip(np.nan_to_num(m.transmission), 0.0, 1.0)
    table["ior"] = np.clip(np.nan_to_num(m.ior, nan=1.5), 1e-3, 1e3)
    table["texture"] = np.where(m.texture_id < len(scene.textures), m.texture_id, -1)
    return table


def _emission(scene: Scene) -> np.ndarray:
    """Material emission radiance, finite and not negative."""
    e = np.nan_to_num(np.asarray(scene.materials.emission, np.float64), nan=0.0, posinf=_RADIANCE_MAX)
    return np.clip(e, 0.0, _RADIANCE_MAX).astype(np.float32)


def _emissive_triangles(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Emissive triangle ids and their inclusive CDF by power (luminance x area)."""
    if scene.triangle_count == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.float32)
    emission = _emission(scene).astype(np.float64)[scene.material_ids]
    luminance = emission @ np.array([0.2126, 0.7152, 0.0722])
    tris = scene.triangles
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    power = luminance * area
    ids = np.nonzero(power > 0)[0].astype(np.int32)
    if ids.size == 0:
        return ids, np.zeros(0, np.float32)
    cdf = np.cumsum(power[ids])
    cdf = (cdf / cdf[-1]).astype(np.float32)
    cdf[-1] = 1.0
    return ids, cdf


def _light_table(scene: Scene, center: np.ndarray, has_mesh_lights: bool) -> np.ndarray:
    """Device light rows in Cycles' units (see kernels/lights.h); emissive
    meshes add one LIGHT_MESH row. Derived values are computed in float64."""
    lights = scene.lights
    n = len(lights)
    table = np.zeros(n + (1 if has_mesh_lights else 0), LIGHT_DTYPE)
    if has_mesh_lights:
        table["kind"][n] = LIGHT_MESH
    if not n:
        return table
    kind = lights.kind
    power = _finite(lights.power)
    direction = _finite(lights.direction)
    length = np.linalg.norm(direction, axis=1, keepdims=True)
    direction = np.where(length > 0, direction / np.where(length > 0, length, 1.0), [0.0, 0.0, -1.0])
    axis_u, axis_v = _finite(lights.axis_u), _finite(lights.axis_v)
    radius = np.maximum(_finite(lights.radius), 0.0)

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
    cos_spot = np.cos(0.5 * np.clip(_finite(lights.spot_angle), 0.0, np.pi))
    cos_half[spot] = cos_spot[spot]
    blend_width = (1.0 - cos_spot) * np.clip(_finite(lights.spot_blend), 0.0, 1.0)
    spot_smooth = np.where(blend_width > 1e-12, 1.0 / np.maximum(blend_width, 1e-12), 1e30)

    # sun: a disk of directions with radiance S / (pi sin^2(half angle))
    sun = kind == LIGHT_SUN
    half = 0.5 * np.clip(_finite(lights.sun_angle), 0.0, np.pi)
    cos_half[sun] = np.cos(half[sun])
    sun_disk = sun & (half > 0)
    radiance[sun_disk] = power[sun_disk] / (np.pi * np.sin(half[sun_disk, None]) ** 2)
    sun_norm = np.where(sun, 2.0 / (1.0 + cos_half), 1.0)

    table["position"][:n, :3] = _finite(lights.position - center)
    table["direction"][:n, :3] = direction
    table["axis_u"][:n, :3] = axis_u
    table["axis_v"][:n, :3] = axis_v
    table["power"][:n, :3] = power
    table["radiance"][:n, :3] = np.clip(np.nan_to_num(radiance, nan=0.0, posinf=_RADIANCE_MAX), 0.0, _RADIANCE_MAX)
    table["radius"][:n] = radius
    table["cos_half"][:n] = cos_half
    table["spot_smooth"][:n] = spot_smooth
    table["sun_norm"][:n] = sun_norm
    table["kind"][:n] = kind
    table["shape"][:n] = lights.shape
    return table


def _finite(values) -> np.ndarray:
    """float64 copy with NaN and infinities replaced by 0."""
    return np.nan_to_num(np.asarray(values, np.float64), nan=0.0, posinf=0.0, neginf=0.0)


def _texels(scene: Scene) -> int:
    """Texels of all textures: the atlas holds one float4 each."""
    return sum(int(np.prod(np.shape(t)[:2])) for t in scene.textures)


def _texture_atlas(textures: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All textures in one float4 array, and each one's offset and size."""
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
        infos[i] = (offset, img.shape[1], img.shape[0], 0)
        chunks.append(img.reshape(-1, 4))
        offset += img.shape[0] * img.shape[1]
    atlas = np.concatenate(chunks) if chunks else np.zeros((1, 4), np.float32)
    return np.ascontiguousarray(atlas, np.float32), infos


def _camera_struct(scene: Scene, center: np.ndarray) -> np.ndarray:
    cam = scene.camera
    m = np.asarray(cam.matrix, np.float64)
    axes = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0, keepdims=True)
    out = np.zeros(1, CAMERA_DTYPE)
    out["right"][0, :3] = axes[:, 0]
    out["up"][0, :3] = axes[:, 1]
    out["back"][0, :3] = axes[:, 2]
    out["origin"][0, :3] = m[:3, 3] - center
    out["window"][0] = cam.window
    out["kind"] = 1 if cam.kind == CAMERA_ORTHO else 0
    out["width"], out["height"] = cam.width, cam.height
    out["clip_start"], out["clip_end"] = cam.clip_start, cam.clip_end
    return out
