"""Photon tracing (photon_trace.cl) into the global and caustic maps.

``trace_maps`` traces the maps the plan asks for from the scene already on
the device: photons leave every light, emissive triangle and an emitting
world in proportion to power (emit.py), are traced through the triangle
kd-tree, and each map becomes a point kd-tree with photon attributes. The
caustic map holds the photons of paths light -> specular+ -> diffuse, the
global map every other diffuse hit (all of them when no caustic map is
traced). Coordinates are in the device frame (``PhotonMaps.center``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..accel.point_tree import PointTree
from ..accel.point_tree_build import PROGRAM as POINT_TREE_BUILD
from ..device import Device, primitives
from ..device.constants import PHOTON_PASS_ALL, PHOTON_PASS_CAUSTIC, PHOTON_PASS_GLOBAL
from ..device.timer import StageTimer
from ..errors import GpuGiError
from ..scene.model import Scene
from ..scene.tables import SceneTables, scene_defines, scene_tables
from ..scene.upload import SceneBuffers, upload
from ..scene.validate import validate
from .aim import caustic_boxes, device_boxes
from .emit import MAPS, Emitter, allocate, emitter_powers, maps_needed

_PROGRAM = "photons/photon_trace.cl"
STORE_GUESS = 3  # stored photons per emitted one: the memory plan's estimate, and the buffer of a pass too small to sample
SAMPLE_STEP = 32  # every this many photons traced first, to size the global buffer
SAMPLE_MARGIN = 1.1  # the buffer holds this many times the sampled stores per photon
SAMPLE_MIN = 64  # fewest sampled photons that size the buffer
MAX_BOUNCES = 8  # scattering events of one photon path


@dataclass
class PhotonMaps:
    """The two photon maps (None where not traced) and the statistics."""

    global_map: PointTree | None
    caustic_map: PointTree | None
    center: np.ndarray  # device coordinates are world positions minus this
    stats: dict = field(default_factory=dict)
    # what is computed from the maps alone and kept with them: the
    # illumination cut by (k, threshold), the same for every view (gi/cut.py)
    derived: dict = field(default_factory=dict)


def programs(scene_defines: dict) -> list[tuple[str, dict]]:
    """The programs photon tracing builds."""
    return [(_PROGRAM, scene_defines), (POINT_TREE_BUILD, {})]


@dataclass
class PhotonSettings:
    """What photon tracing reads of the render settings."""

    global_photons: int
    caustic_photons: int
    seed: int = 0
    k_hint: float = 50.0  # the k the point trees are tuned for
    max_specular: int = 8  # specular bounces of a photon path
    max_bounces: int = MAX_BOUNCES  # scattering events of a photon path


def trace_maps(device: Device, buffers: SceneBuffers, emitters: list[Emitter], maps: dict[str, str],
               settings: PhotonSettings, scene_defines: dict | None = None,
               aim: np.ndarray | None = None) -> PhotonMaps:
    """Trace the maps that ``maps`` (the plan) says are built. ``aim``:
    world boxes holding every surface that can bounce light specularly
    (aim.caustic_boxes), outside which the caustic pass traces no photon;
    None traces them all."""
    timer = StageTimer(device.queue)
    light_power = sum((e.power for e in emitters), np.zeros(3))
    stats = {"maps": dict(maps), "light_power": light_power.tolist(), "emitters": len(emitters), "emitted": {},
             "stored": {}, "dropped": {}, "passes": {}, "emitted_power": {}, "mean_path_length": {}, "traced": {},
             "ms": timer.ms}
    if aim is not None and "caustic" in traced_maps(maps):
        stats["aim_boxes"] = len(aim)
    aim_boxes = device_boxes(aim, buffers.center) if aim is not None else None
    built = {name: None for name in MAPS}
    traced = traced_maps(maps)
    for name in traced:
        rows = allocate(emitters, settings.global_photons if name == "global" else settings.caustic_photons)
        # with a caustic map, the global map leaves its photons out (photon_trace.cl)
        pass_id = PHOTON_PASS_CAUSTIC if name == "caustic" else PHOTON_PASS_GLOBAL if "caustic" in traced else PHOTON_PASS_ALL
        with timer.stage(f"trace_{name}"):
            stored, n_stored, asked, path, passes, skipped = _trace(device, buffers, rows, pass_id, settings,
                                                                   scene_defines, aim_boxes)
        with timer.stage(f"tree_{name}"):
            position, direction, power, normal = (a[:n_stored] for a in stored)
            built[name] = PointTree.from_device(device, position, (power, direction, normal), k_hint=settings.k_hint)
        emitted = int(rows["count"].sum())
        stats["emitted"][name] = emitted
        stats["stored"][name] = n_stored
        stats["dropped"][name] = asked - n_stored  # past the device's largest buffer
        stats["passes"][name] = passes  # full traces: more than one where the sampled buffer size fell short
        stats["traced"][name] = emitted - skipped  # photons followed past their emitter (the caustic pass aims)
        stats["emitted_power"][name] = path[:3].tolist()
        stats["mean_path_length"][name] = float(path[3]) / emitted if emitted else 0.0
    return PhotonMaps(global_map=built["global"], caustic_map=built["caustic"], center=buffers.center, stats=stats)


def traced_maps(maps: dict[str, str]) -> list[str]:
    """The maps the plan's ``maps`` says are built, in tracing order."""
    return [name for name in MAPS if maps[name].startswith("built")]


def _trace(device: Device, buf: SceneBuffers, rows: np.ndarray, pass_id: int, settings: PhotonSettings,
           scene_defines: dict | None, aim_boxes: np.ndarray | None):
    """One pass: the stored photons (position with its slot in w, incident
    direction, power, normal: device arrays in the key order), how many
    were stored and how many asked to be, the sums over the emitted photons
    of their power (rgb) and surface hits, how many full traces ran and how
    many photons the caustic pass skipped (``aim_boxes``: device boxes,
    aim.device_boxes; None: none skipped).
    The buffers are sized by _first_capacity; a trace that stores more than
    they hold runs again with room for all (same paths), up to the device's
    largest buffer."""
    kernel = device.kernel(_PROGRAM, "Photon_trace", scene_defines)
    n = int(rows["count"].sum())
    path = device.array(max(n, 1) * 4, np.float32).reshape(max(n, 1), 4)
    counter = device.empty(8)  # stores asked for, photons skipped
    emitter_buf = device.to_device(rows)
    aim_count = len(aim_boxes) // 2 if aim_boxes is not None else -1
    aim_buf = device.to_device(aim_boxes if aim_count > 0 else np.zeros((2, 4), np.float32))
    sphere = np.array([0.0, 0.0, 0.0, buf.radius], np.float32)
    largest = device.max_alloc_bytes // 16
    stride = settings.max_bounces + 1  # stores of one photon path, at most
    if n * stride >= 1 << 32:
        raise GpuGiError(f"{n} photons of up to {stride} hits each are more than one map can order; "
                         "lower the photon count")

    def launch(step: int, capacity: int) -> tuple[list, object, np.ndarray]:
        """Every step-th photon traced into buffers of ``capacity``; the
        buffers, the keys and the counters (stores asked for, photons
        skipped)."""
        stored = [device.array(capacity * 4, np.float32).reshape(capacity, 4) for _ in range(4)]
        keys = device.empty(4 * capacity)
        device.fill(counter, 0, 8)
        kernel(-(-n // step), *buf.kernel_args(), emitter_buf, np.int32(len(rows)), sphere, aim_buf,
               np.int32(aim_count), np.int32(n),
               np.uint32(settings.seed), np.int32(pass_id), np.int32(settings.max_bounces),
               np.int32(settings.max_specular), counter, np.int32(capacity), *(a.data for a in stored), keys,
               np.uint32(stride), path.data, np.int32(step))
        return stored, keys, device.read(counter, 2, np.int32)

    capacity = _first_capacity(n, pass_id, stride, lambda step, room: int(launch(step, min(room, largest))[2][0]))
    passes = 0
    while True:
        capacity = max(min(capacity, largest), 1)
        stored, keys, (wanted, skipped) = launch(1, capacity)
        passes += 1
        if wanted <= capacity or capacity >= largest:
            count = int(min(wanted, capacity))
            ordered = _in_key_order(device, stored, keys, count, n * stride, scene_defines)
            return ordered, count, int(wanted), _path_sums(device, path, n), passes, int(skipped)
        capacity = int(wanted)


def _first_capacity(n: int, pass_id: int, stride: int, sample) -> int:
    """Room for the stores of n photons: one each in the caustic pass (it
    stops at its first store); elsewhere the stores per photon of every
    SAMPLE_STEP-th photon, traced first by ``sample(step, room)`` (-> stores
    asked), with a margin, so that a closed, bright scene (three or more
    stores per photon) is not traced twice; STORE_GUESS each for a pass too
    small to sample."""
    if pass_id == PHOTON_PASS_CAUSTIC:
        return n
    sampled = -(-n // SAMPLE_STEP)
    if sampled < SAMPLE_MIN:
        return n * STORE_GUESS
    per_photon = sample(SAMPLE_STEP, sampled * stride) / sampled  # stores past the room are counted too
    return int(np.ceil(n * per_photon * SAMPLE_MARGIN)) + SAMPLE_MIN  # a few more where the sample saw few


def _in_key_order(device: Device, stored: list, keys, count: int, key_bound: int, scene_defines) -> list:
    """The stored photons sorted by key: the order of the paths that stored
    them, whatever order the device ran them in."""
    _, order = primitives.sort_pairs(device, keys, None, count, key_bound)
    out = [device.array(max(count, 1) * 4, np.float32).reshape(max(count, 1), 4) for _ in range(4)]
    device.kernel(_PROGRAM, "Photon_reorder", scene_defines)(count, order, np.int32(count), *(a.data for a in stored),
                                              *(a.data for a in out))
    return out


def _path_sums(device: Device, path, n: int) -> np.ndarray:
    """Sums of the per-photon (power rgb, hits) rows, reduced on the device (float64)."""
    if n == 0:
        return np.zeros(4)
    return primitives.sum_float4(device, path.data, n)


def trace_photon_maps(device: Device, scene: Scene, global_photons: int = 100_000, caustic_photons: int = 100_000,
                      seed: int = 0, max_bounces: int = MAX_BOUNCES, k_hint: float = 50.0,
                      max_specular: int = 8, aimed: bool = True) -> PhotonMaps:
    """The photon maps of a scene on its own (tests and benchmarks): it is
    validated, its tables built and uploaded, and the maps it needs traced
    (caustic photons aimed at the specular surfaces unless ``aimed`` is
    False)."""
    scene = validate(scene)
    tables: SceneTables = scene_tables(scene)
    buffers = upload(device, scene, tables)
    emitters = emitter_powers(scene, tables)
    maps = maps_needed(emitters, scene.triangle_count, scene.has_specular(), global_photons, caustic_photons)
    aim = caustic_boxes(scene, tables.materials) if aimed and "caustic" in traced_maps(maps) else None
    return trace_maps(device, buffers, emitters, maps,
                      PhotonSettings(global_photons, caustic_photons, seed, k_hint, max_specular, max_bounces),
                      scene_defines(scene), aim)
