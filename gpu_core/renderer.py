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
    CAMERA_ORTHO,
    LIGHT_AREA,
    LIGHT_SPOT,
    LIGHT_SUN,
    Scene,
    validate,
)
from .settings import RenderSettings

LIGHT_MESH = 4
_TARGET_BATCH_SECONDS = 0.12


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
    eps: float
    nbytes: int


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
        timer = _Timer()
        with timer.stage("validate"):
            scene = validate(scene)
        plan = ["validate", "kdtree", "direct_light"]
        if settings.diffuse_bounces > 0:
            plan.append("path_traced_indirect")
        if scene.textures:
            plan.append("textures")
        if _emissive_triangles(scene)[0].size:
            plan.append("mesh_lights")
        defines = {}
        if (scene.materials.alpha[np.unique(scene.material_ids)] < 1.0).any():
            plan.append("alpha_shadows")
            defines["RENDER_HAS_ALPHA"] = 1
        _check_stop(should_stop)
        with timer.stage("upload"):
            up = self._upload(scene, timer)
        _check_stop(should_stop)
        with timer.stage("compile"):
            program = self.device.program("render.cl", defines)
        with timer.stage("render"):
            passes, batches = self._run(program, up, scene, settings, progress, should_stop)
        stats = {
            "device": self.device.name,
            "plan": plan,
            "ms": timer.ms,
            "triangles": scene.triangle_count,
            "lights": len(scene.lights),
            "emissive_triangles": up.emit_count,
            "textures": len(scene.textures),
            "batches": batches,
            "samples": settings.samples,
            "device_bytes": up.nbytes,
            "kdtree": up.tree.stats,
            **scene.report.as_stats(),
        }
        warnings = list(scene.warnings)
        if self.device.fallback_message:
            warnings.append(self.device.fallback_message)
        return RenderResult(passes=passes, stats=stats, warnings=warnings)

    # -- upload ---------------------------------------------------------------

    def _upload(self, scene: Scene, timer: _Timer) -> _Uploaded:
        dev = self.device
        lo, hi = scene.bounds()
        center = 0.5 * (lo + hi)
        extent = float(max(np.max(hi - lo), 1e-30))
        # positions relative to the scene centre keep float32 precision far from the origin
        tris = (scene.triangles - center).astype(np.float32)
        with timer.stage("kdtree"):
            tree = kdtree.build(dev, tris)
        n = scene.triangle_count
        normals = np.zeros((n * 3, 4), np.float32)
        normals[:, :3] = scene.normals.reshape(-1, 3)
        uvs = np.ascontiguousarray(scene.uvs.reshape(-1, 2), dtype=np.float32)
        emit_tris, emit_cdf = _emissive_triangles(scene)
        lights = _light_table(scene, center, emit_count=len(emit_tris))
        atlas, infos = _texture_atlas(scene.textures)
        arrays = [normals, uvs, scene.material_ids, lights, atlas]
        nbytes = int(sum(a.nbytes for a in arrays) + tris.nbytes * 2)
        if nbytes > dev.global_mem_bytes:
            raise BudgetError(
                f"scene needs about {nbytes / 2**20:.0f} MiB of device memory, "
                f"{dev.name} has {dev.global_mem_bytes / 2**20:.0f} MiB"
            )
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
            eps=2e-5 * extent,
            nbytes=nbytes,
        )

    # -- image kernel ---------------------------------------------------------

    def _run(self, program, up: _Uploaded, scene: Scene, settings: RenderSettings, progress, should_stop):
        dev = self.device
        x0, y0, x1, y1 = scene.camera.pixel_window
        w, h = x1 - x0, y1 - y0
        total = w * h
        combined, depth, normal = dev.empty(total * 16), dev.empty(total * 4), dev.empty(total * 16)
        world = up.world.copy()
        world[3] = 1.0 if settings.transparent_background else 0.0
        kernel = cl.Kernel(program, "Render_pixels")
        start, batch, batches = 0, min(settings.batch_pixels, total), 0
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
                np.uint32(settings.seed),
                np.float32(up.eps), np.float32(settings.clamp),
                combined, depth, normal,
            )
            dev.queue.finish()
            elapsed = time.perf_counter() - began
            start += count
            batches += 1
            if progress is not None:
                progress(start / total, f"rendered {start}/{total} pixels")
            if start < total:
                _check_stop(should_stop)
            # size the next batch so one launch takes about _TARGET_BATCH_SECONDS
            scale = _TARGET_BATCH_SECONDS / max(elapsed, 1e-4)
            batch = int(np.clip(count * scale, 64, max(settings.batch_pixels, 64) * 16))
        out_c = np.empty((total, 4), np.float32)
        out_d = np.empty(total, np.float32)
        out_n = np.empty((total, 4), np.float32)
        for host, buf in ((out_c, combined), (out_d, depth), (out_n, normal)):
            cl.enqueue_copy(dev.queue, host, buf)
        passes = {
            "Combined": out_c.reshape(h, w, 4),
            "Depth": out_d.reshape(h, w, 1),
            "Normal": np.ascontiguousarray(out_n.reshape(h, w, 4)[..., :3]),
        }
        return passes, batches


def _check_stop(should_stop) -> None:
    if should_stop is not None and should_stop():
        raise RenderCancelled("render cancelled")


def _material_table(scene: Scene) -> np.ndarray:
    m = scene.materials
    table = np.zeros(len(m), MATERIAL_DTYPE)
    table["base_color"][:, :3] = np.clip(m.base_color, 0.0, 1.0)
    table["base_color"][:, 3] = np.clip(m.alpha, 0.0, 1.0)
    table["emission"][:, :3] = np.maximum(m.emission, 0.0)
    table["metallic"] = np.clip(m.metallic, 0.0, 1.0)
    table["roughness"] = np.clip(m.roughness, 0.0, 1.0)
    table["transmission"] = np.clip(m.transmission, 0.0, 1.0)
    table["ior"] = np.maximum(m.ior, 1e-3)
    table["texture"] = np.where(m.texture_id < len(scene.textures), m.texture_id, -1)
    return table


def _emissive_triangles(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Emissive triangle ids and their inclusive power CDF."""
    if scene.triangle_count == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.float32)
    emission = scene.materials.emission[scene.material_ids]
    luminance = emission @ np.array([0.2126, 0.7152, 0.0722])
    tris = scene.triangles
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    power = luminance * area
    ids = np.nonzero(power > 0)[0].astype(np.int32)
    if ids.size == 0:
        return ids, np.zeros(0, np.float32)
    cdf = np.cumsum(power[ids].astype(np.float64))
    cdf = (cdf / cdf[-1]).astype(np.float32)
    cdf[-1] = 1.0
    return ids, cdf


def _light_table(scene: Scene, center: np.ndarray, emit_count: int) -> np.ndarray:
    """The device light rows; emissive meshes add one LIGHT_MESH row."""
    lights = scene.lights
    count = len(lights) + (1 if emit_count else 0)
    table = np.zeros(count, LIGHT_DTYPE)
    n = len(lights)
    if n:
        direction = lights.direction / np.maximum(np.linalg.norm(lights.direction, axis=1, keepdims=True), 1e-30)
        table["position"][:n, :3] = lights.position - center
        table["position"][:n, 3] = np.maximum(lights.radius, 0.0)
        table["direction"][:n, :3] = direction
        half = 0.5 * np.clip(lights.spot_angle, 1e-4, np.pi)
        cos_half = np.cos(half)
        table["direction"][:n, 3] = np.where(lights.kind == LIGHT_SPOT, cos_half, -2.0)
        blend_width = (1.0 - cos_half) * np.clip(lights.spot_blend, 0.0, 1.0)
        table["axis_u"][:n, :3] = lights.axis_u
        table["axis_u"][:n, 3] = np.where(blend_width > 1e-12, 1.0 / np.maximum(blend_width, 1e-12), 1e12)
        table["axis_v"][:n, :3] = lights.axis_v
        table["axis_v"][:n, 3] = np.cos(0.5 * np.clip(lights.sun_angle, 0.0, np.pi))
        table["power"][:n, :3] = lights.power
        area = np.linalg.norm(np.cross(lights.axis_u, lights.axis_v), axis=1)
        table["power"][:n, 3] = np.where(lights.shape == 1, area * np.pi / 4.0, area)
        table["kind"][:n] = lights.kind
        table["shape"][:n] = lights.shape
        # a point of a zero-size area light cannot emit: treat it as black
        zero_area = (lights.kind == LIGHT_AREA) & (area <= 0)
        table["power"][:n, :3][zero_area] = 0.0
    if emit_count:
        table["kind"][n] = LIGHT_MESH
    table["pick_pdf"] = 1.0
    return table


def _texture_atlas(textures: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """All textures in one float4 array, and each one's offset and size."""
    infos = np.zeros(max(len(textures), 1), TEXTURE_INFO_DTYPE)
    chunks, offset = [], 0
    for i, tex in enumerate(textures):
        img = np.asarray(tex, np.float32)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 4, axis=2)
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

