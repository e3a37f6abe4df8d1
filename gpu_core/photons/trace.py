"""Photon tracing (kernels/photon_trace.cl) into the global and caustic maps.

``trace_photon_maps(device, scene, global_photons, caustic_photons, seed)``
emits photons from every light, emissive triangle and an emitting world, in
proportion to power, traces them through the triangle kd-tree and builds
one point kd-tree per map: the caustic map holds the photons of paths
light -> specular+ -> diffuse, and the global map every other diffuse hit
(all of them when the caustic map is not traced). Photon power is in watts: the photons of a pass
carry, all together, the power the lights emit (Cycles' units, see
kernels/lights.h and kernels/photon_emit.h). Only the maps the scene needs
are traced; ``stats["maps"]`` says which were built and why.

Coordinates on the device (triangles, photons, the point trees) are
relative to ``PhotonMaps.center``, the centre of the scene's bounds, as in
the renderer.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import kdtree
from ..device import Device
from ..scene_tables import LIGHT_MESH, emissive_triangles, light_table, material_table, texture_atlas
from ..scene import LIGHT_AREA, LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, Scene, validate
from .kernels import Kernels
from .layout import EMITTER_DTYPE
from .point_tree import PointTree
from .point_tree_build import GROUP

PASS_GLOBAL, PASS_CAUSTIC, PASS_ALL = 0, 1, 2  # kernels/photon_trace.cl
EMITTER_WORLD = -1  # kernels/photon_emit.h
_STORE_GUESS = 3  # stored photons per emitted one, first guess of the global buffer


@dataclass
class PhotonMaps:
    """The two photon maps (None where not traced) and the statistics."""

    global_map: PointTree | None
    caustic_map: PointTree | None
    center: np.ndarray  # device coordinates are world positions minus this
    stats: dict = field(default_factory=dict)


@dataclass
class _SceneBuffers:
    """What the trace kernel reads about the scene (the renderer's upload
    has the same fields and can stand in for it)."""

    tree: kdtree.KdTree
    normals: cl.Buffer
    uvs: cl.Buffer
    material_ids: cl.Buffer
    materials: cl.Buffer
    lights: cl.Buffer
    emit_tris: cl.Buffer
    emit_cdf: cl.Buffer
    emit_count: int
    atlas: cl.Buffer
    texture_infos: cl.Buffer


def spot_power(power: np.ndarray, cos_half: float, spot_smooth: float) -> np.ndarray:
    """Power a spot light emits: P / (4 pi) times the integral of its
    smoothstep falloff over the sphere, 2 pi int smoothstep((c - cos_half) s) dc."""
    width = 1.0 - cos_half
    a = min(width * spot_smooth, 1.0)
    ramp = (a**3 - 0.5 * a**4) / spot_smooth  # the smoothstep's rise
    flat = max(width - 1.0 / spot_smooth, 0.0)  # where it is 1
    return np.asarray(power, np.float64) * 0.5 * (ramp + flat)


@dataclass
class Emitter:
    """One emitter: its light row (or EMITTER_WORLD), the rgb watts it
    emits, and the watts its photons carry before per-photon factors (a
    spot's photons cover its whole cone and the kernel applies the falloff)."""

    row: int
    power: np.ndarray
    carried: np.ndarray


def emitter_powers(scene: Scene, table: np.ndarray, emit_tris: np.ndarray, radius: float) -> list[Emitter]:
    """Every emitter with power; ``radius`` is the scene's bounding sphere
    (sun and world)."""
    out = []
    for row, light in enumerate(table):
        kind, power = int(light["kind"]), light["power"][:3].astype(np.float64)
        carried = None
        if kind in (LIGHT_POINT, LIGHT_AREA):
            total = power
        elif kind == LIGHT_SPOT:
            total = spot_power(power, float(light["cos_half"]), float(light["spot_smooth"]))
            carried = power * 0.5 * (1.0 - float(light["cos_half"]))  # P / (4 pi) x the cone's solid angle
        elif kind == LIGHT_SUN:
            total = power * np.pi * radius**2
        elif kind == LIGHT_MESH:
            total = _mesh_power(scene, emit_tris)
        else:
            continue
        if np.sum(total) > 0:
            out.append(Emitter(row, total, total if carried is None else carried))
    world = np.asarray(scene.world_color, np.float64)
    if np.sum(world) > 0:
        total = 4.0 * np.pi**2 * radius**2 * world
        out.append(Emitter(EMITTER_WORLD, total, total))
    return out


def _mesh_power(scene: Scene, emit_tris: np.ndarray) -> np.ndarray:
    """Both faces of every emissive triangle: sum of 2 pi A L_e."""
    tris = scene.triangles[emit_tris]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    emission = material_table(scene)["emission"][:, :3].astype(np.float64)[scene.material_ids[emit_tris]]
    return 2.0 * np.pi * (area[:, None] * emission).sum(axis=0)


def allocate(emitters: list[Emitter], photons: int) -> np.ndarray:
    """Emitter rows: photons in proportion to power (at least one each)."""
    table = np.zeros(len(emitters), EMITTER_DTYPE)
    if not emitters:
        return table
    weight = np.array([e.power.sum() for e in emitters])
    counts = np.maximum(1, np.rint(photons * weight / weight.sum())).astype(np.int64)
    table["first"] = np.concatenate([[0], np.cumsum(counts)[:-1]])
    table["count"] = counts
    table["light"] = [e.row for e in emitters]
    per_photon = np.array([e.carried for e in emitters]) / counts[:, None]
    table["power"][:, :3] = np.minimum(per_photon, np.finfo(np.float32).max)
    return table


def _needs_caustics(scene: Scene) -> bool:
    """Whether any triangle is specular (mirror or glass) enough to focus light."""
    used = np.unique(scene.material_ids)
    m = scene.materials
    return bool(((m.metallic[used] > 0) | (m.transmission[used] > 0)).any())


def _skipped(scene: Scene, emitters: list, global_photons: int, caustic_photons: int) -> dict[str, str]:
    """The maps this scene does not need, each with the reason."""
    if not emitters:
        return {name: "skipped: no light emits power" for name in ("global", "caustic")}
    if scene.triangle_count == 0:
        return {name: "skipped: no surfaces" for name in ("global", "caustic")}
    reasons = {}
    if global_photons <= 0:
        reasons["global"] = "skipped: zero photons asked for"
    if not _needs_caustics(scene):
        reasons["caustic"] = "skipped: no specular or transmissive surface"
    elif caustic_photons <= 0:
        reasons["caustic"] = "skipped: zero photons asked for"
    return reasons


def trace_photon_maps(
    device: Device,
    scene: Scene,
    global_photons: int = 100_000,
    caustic_photons: int = 100_000,
    seed: int = 0,
    max_bounces: int = 8,
    k_hint: float = 50.0,
    uploaded=None,
) -> PhotonMaps:
    """Trace both photon maps of ``scene`` with the given numbers of
    emitted photons; each map is a PointTree with photon attributes.
    ``max_bounces``: scattering events per path; ``k_hint``: the k the
    point trees are tuned for; ``uploaded``: the scene already on the
    device when the caller has it (the renderer's upload: kd-tree and
    tables in the same frame, the centre of the validated scene's bounds),
    so nothing is built or uploaded again."""
    ms: dict[str, float] = {}
    start = time.perf_counter()
    scene = validate(scene)
    lo, hi = scene.bounds()
    center = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
    emit_tris, emit_cdf = emissive_triangles(scene)
    table = light_table(scene, center, has_mesh_lights=len(emit_tris) > 0)
    emitters = emitter_powers(scene, table, emit_tris, radius)
    light_power = sum((e.power for e in emitters), np.zeros(3))
    ms["setup"] = (time.perf_counter() - start) * 1e3

    reasons = _skipped(scene, emitters, global_photons, caustic_photons)
    stats = {
        "maps": {},
        "light_power": light_power.tolist(),
        "emitters": len(emitters),
        "emitted": {},
        "stored": {},
        "dropped": {},
        "emitted_power": {},
        "mean_path_length": {},
        "ms": ms,
    }
    maps = {"global": None, "caustic": None}
    traced = [name for name in ("global", "caustic") if name not in reasons]
    if traced:
        buffers = uploaded
        if buffers is None:
            start = time.perf_counter()
            tree = kdtree.build(device, (scene.triangles - center).astype(np.float32))
            ms["kdtree"] = (time.perf_counter() - start) * 1e3
            start = time.perf_counter()
            buffers = _upload(device, scene, tree, table, emit_tris, emit_cdf)
            ms["upload"] = (time.perf_counter() - start) * 1e3
    for name in ("global", "caustic"):
        if name not in traced:
            stats["maps"][name] = reasons[name]
            continue
        count = global_photons if name == "global" else caustic_photons
        rows = allocate(emitters, count)
        # with a caustic map, the global map leaves its photons out (kernels/photon_trace.cl)
        pass_id = PASS_CAUSTIC if name == "caustic" else PASS_GLOBAL if "caustic" in traced else PASS_ALL
        start = time.perf_counter()
        stored, n_stored, asked, path = _trace(device, buffers, rows, radius, seed, pass_id, max_bounces)
        ms[f"trace_{name}"] = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        position, direction, power, normal = (a[:n_stored] for a in stored)
        maps[name] = PointTree.from_device(device, position, (power, direction, normal), k_hint=k_hint)
        ms[f"tree_{name}"] = (time.perf_counter() - start) * 1e3
        emitted = int(rows["count"].sum())
        stats["maps"][name] = "built" if name == "global" else "built: specular or transmissive surfaces present"
        stats["emitted"][name] = emitted
        stats["stored"][name] = n_stored
        stats["dropped"][name] = asked - n_stored  # past the device's largest buffer
        stats["emitted_power"][name] = path[:, :3].astype(np.float64).sum(axis=0).tolist()
        stats["mean_path_length"][name] = float(path[:, 3].astype(np.float64).mean()) if emitted else 0.0
    return PhotonMaps(global_map=maps["global"], caustic_map=maps["caustic"], center=center, stats=stats)


def _upload(device: Device, scene: Scene, tree: kdtree.KdTree, table: np.ndarray,
            emit_tris: np.ndarray, emit_cdf: np.ndarray) -> _SceneBuffers:
    """What the trace kernel reads besides the triangle tree ``tree``."""
    normals = np.zeros((scene.triangle_count * 3, 4), np.float32)
    normals[:, :3] = scene.normals.reshape(-1, 3)
    atlas, infos = texture_atlas(scene.textures)
    return _SceneBuffers(
        tree=tree,
        normals=device.buffer(normals),
        uvs=device.buffer(np.ascontiguousarray(scene.uvs.reshape(-1, 2), np.float32)),
        material_ids=device.buffer(scene.material_ids),
        materials=device.buffer(material_table(scene)),
        lights=device.buffer(table),
        emit_tris=device.buffer(emit_tris),
        emit_cdf=device.buffer(emit_cdf),
        emit_count=len(emit_tris),
        atlas=device.buffer(atlas),
        texture_infos=device.buffer(infos),
    )


def _trace(device: Device, buf: _SceneBuffers, rows: np.ndarray, radius: float, seed: int,
           pass_id: int, max_bounces: int):
    """One pass: the stored photons (position with its slot in w, incident
    direction, power, normal: device arrays in the kernel's order), how
    many were stored and how many asked to be, and per emitted photon its
    emitted power and surface hits (host array). A pass that stores more
    than the buffers hold runs again with room for all (same paths), up to
    the device's largest buffer."""
    queue = device.queue
    kernel = Kernels(device.program("photon_trace.cl")).Photon_trace
    n = int(rows["count"].sum())
    capacity = max(n * (1 if pass_id == PASS_CAUSTIC else _STORE_GUESS), 1)
    path = cla.empty(queue, (max(n, 1), 4), np.float32)
    counter = cla.empty(queue, 1, np.int32)
    emitter_buf = device.buffer(rows)
    sphere = np.array([0.0, 0.0, 0.0, radius], np.float32)
    while True:
        capacity = min(capacity, device.max_alloc_bytes // 16)
        stored = [cla.empty(queue, (capacity, 4), np.float32) for _ in range(4)]
        counter.fill(0)
        kernel(
            queue, (-(-n // GROUP) * GROUP,), (GROUP,), *buf.tree.kernel_args(), buf.normals, buf.uvs,
            buf.material_ids, buf.materials, buf.lights, buf.emit_tris, buf.emit_cdf,
            np.int32(buf.emit_count), buf.atlas, buf.texture_infos, emitter_buf, np.int32(len(rows)),
            sphere, np.int32(n), np.uint32(seed), np.int32(pass_id), np.int32(max_bounces),
            counter.data, np.int32(capacity), *(a.data for a in stored), path.data,
        )
        wanted = int(counter.get()[0])
        if wanted <= capacity or capacity >= device.max_alloc_bytes // 16:
            return stored, min(wanted, capacity), wanted, path.get()[:n]
        capacity = wanted
