"""The renderer: plans the stages a scene needs, uploads it, runs the kernels.

One Renderer serves F12, ``blender -b`` and the viewport. ``render`` runs the
image kernel over the render window in batches; between batches it reports
progress and asks whether to stop, so Esc in Blender takes effect quickly.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pyopencl as cl

from . import gi, kdtree, scene_tables
from .device import Device
from .errors import BudgetError, RenderCancelled
from .layout import CAMERA_DTYPE, LIGHT_DTYPE
from .scene import CAMERA_ORTHO, Scene, validate
from .settings import RenderSettings

_BATCH_SECONDS = 0.1  # aimed duration of one kernel launch (cancel latency)
_FIRST_BATCH_PATHS = 1 << 14  # camera paths in the first launch, before any timing
_MIN_BATCH = 64

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
        self._photon_reuse = None  # gi.PhotonReuse, made by the first GI render
        self._tree: tuple[bytes, kdtree.KdTree] | None = None  # the last triangles' digest and kd-tree

    def render(
        self,
        scene: Scene,
        settings: RenderSettings | None = None,
        progress: Callable[[float, str], None] | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> RenderResult:
        settings = (settings or RenderSettings()).validated()
        mode = settings.mode
        timer = _Timer()
        with timer.stage("validate"):
            scene = validate(scene)
        emit_tris, emit_cdf = scene_tables.emissive_triangles(scene)
        plan, defines = _plan(scene, settings, len(emit_tris))
        self._check_budget(scene, settings)
        _check_stop(should_stop)

        # positions relative to the scene centre keep float32 precision far from the origin
        lo, hi = scene.bounds()
        center = 0.5 * (lo + hi)
        tree = self._kdtree(scene, center, timer, plan)
        _check_stop(should_stop)
        with timer.stage("upload"):
            up = self._upload(scene, center, tree, emit_tris, emit_cdf)
        # GI mode: indirect light and caustics cached at shading points first; the
        # path tracer then gives direct light and specular paths, and reads the cache
        field_ = None
        if mode == "gi":
            if progress is not None:
                progress(0.0, "global illumination")
            field_ = self._gi_field(scene, up, settings, timer, plan)
            defines["RENDER_GI"] = 1
            _check_stop(should_stop)
        traced = replace(settings, diffuse_bounces=0) if mode == "gi" else settings
        with timer.stage("compile"):
            program = self.device.program("render.cl", defines)
        _check_stop(should_stop)
        with timer.stage("render"):
            passes, batches = self._run(program, up, scene, traced, progress, should_stop, field_)
        stats = {
            "device": self.device.name,
            "mode": mode,
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
        if field_ is not None:
            stats["gi"] = {key: value for key, value in field_.stats.items() if key != "ms"}
        warnings = list(scene.warnings)
        if self.device.fallback_message:
            warnings.append(self.device.fallback_message)
        return RenderResult(passes=passes, stats=stats, warnings=warnings)

    def _kdtree(self, scene: Scene, center: np.ndarray, timer: _Timer, plan: list[str]) -> kdtree.KdTree:
        """The scene's kd-tree: the last render's when the triangles did not
        change (the plan then says kdtree_reused), else built."""
        digest = hashlib.blake2b(np.ascontiguousarray(scene.triangles).tobytes(), digest_size=16).digest()
        if self._tree is not None and self._tree[0] == digest:
            plan[plan.index("kdtree")] = "kdtree_reused"
            return self._tree[1]
        with timer.stage("kdtree"):
            tree = kdtree.build(self.device, (scene.triangles - center).astype(np.float32))
        self._tree = (digest, tree)
        return tree

    def upload(self, scene: Scene) -> tuple[Scene, _Uploaded]:
        """The validated scene and its device copy, kd-tree built, in the
        kernels' frame (positions relative to the centre of the bounds):
        what the stage kernels (shading points, gathering) read."""
        scene = validate(scene)
        lo, hi = scene.bounds()
        center = 0.5 * (lo + hi)
        tree = kdtree.build(self.device, (scene.triangles - center).astype(np.float32))
        return scene, self._upload(scene, center, tree, *scene_tables.emissive_triangles(scene))

    # -- global illumination ----------------------------------------------------

    def _gi_field(self, scene: Scene, up: _Uploaded, settings: RenderSettings, timer: _Timer,
                  plan: list[str]) -> gi.GiField:
        """Indirect and caustic irradiance at the shading points, from photon
        maps and the irradiance cache (gi.py); its stages go into the timer
        and the plan."""
        if self._photon_reuse is None:
            self._photon_reuse = gi.PhotonReuse()
        field_ = gi.render_gi(self.device, scene, up, scene.camera.pixel_window, settings, self._photon_reuse)
        for stage, ms in field_.stats["ms"].items():
            timer.ms[stage] = ms
        plan += gi.plan(field_.stats)
        return field_

    # -- upload ---------------------------------------------------------------

    def _check_budget(self, scene: Scene, settings: RenderSettings) -> None:
        """A clear error before any upload when the scene cannot fit the device."""
        dev = self.device
        need = _device_bytes(scene, settings)
        largest = max(scene.triangle_count * 48, scene_tables.texels(scene) * 16)
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
        lights = scene_tables.light_table(scene, center, has_mesh_lights=len(emit_tris) > 0)
        atlas, infos = scene_tables.texture_atlas(scene.textures)
        return _Uploaded(
            tree=tree,
            normals=dev.buffer(normals),
            uvs=dev.buffer(uvs),
            material_ids=dev.buffer(scene.material_ids),
            materials=dev.buffer(scene_tables.material_table(scene)),
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

    def _run(self, program, up: _Uploaded, scene: Scene, settings: RenderSettings, progress, should_stop,
             field_: gi.GiField | None = None):
        dev = self.device
        x0, y0, x1, y1 = scene.camera.pixel_window
        w, h = x1 - x0, y1 - y0
        total = w * h
        outputs = _outputs(settings)
        combined, depth, normal = dev.empty(total * 16), dev.empty(total * 4), dev.empty(total * 16)
        # passes nobody asked for get a one-element stand-in the kernel never writes
        light = dev.empty(total * 16 * len(LIGHT_PASSES) if settings.light_passes else 16)
        albedo, feature_normal = (dev.empty(total * 16 if settings.denoising_passes else 16) for _ in range(2))
        # the GI cache the kernel reads (RENDER_GI); stand-ins it never reads otherwise
        gi_buffers = [dev.buffer(a) for a in (field_.positions, field_.normals, field_.indirect, field_.caustics)] \
            if field_ is not None else [dev.empty(16)] * 4
        gi_sub = np.int32(field_.subpixels if field_ is not None else 1)
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
                np.int32(outputs), combined, depth, normal, light, albedo, feature_normal, *gi_buffers, gi_sub,
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
    textures = scene_tables.texels(scene) * 16
    layers = 36  # combined, depth, normal: bytes per pixel
    if settings.light_passes:
        layers += 16 * len(LIGHT_PASSES)
    if settings.denoising_passes:
        layers += 32
    film = (x1 - x0) * (y1 - y0) * layers
    return int(geometry + tree + textures + film + len(scene.lights) * LIGHT_DTYPE.itemsize)


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
