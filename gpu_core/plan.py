"""The plan of a render, decided before anything runs.

``plan(scene, settings, held, edits)`` reads the validated scene, the
settings, what the renderer already holds on the device from earlier
renders (``Held``) and the edits since then, and decides: the scene parts
to upload, the stages that run and what they reuse (and why), the kernel
features the scene needs, the photon maps, the programs to build, and the
device memory all of it takes, GI included, so that a budget error comes
before any kernel fails. The stages read the plan; none decides again, but
for one thing only tracing tells: the cache points of an earlier render are
kept when the shading points come out the same (gi/cache/samples.py
HeldSamples; the stats' plan then names ``sample_points_reused``). The
render stats print it (``Plan.stages``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .errors import BudgetError
from .gi import cut as gi_cut
from .gi import gather as gi_gather
from .gi import pipeline as gi_pipeline
from .image import film_bytes
from .image import programs as image_programs
from .photons import reweight as photon_reweight
from .photons import trace as photon_trace
from .photons.emit import Emitter, emitter_powers, maps_needed, reweight_scales
from .accel import kdtree_blocks, kdtree_build, kdtree_overlay
from .device.primitives import programs as primitives_programs
from .scene.model import PARTS, Scene, part_digests
from .scene.tables import SceneTables, scene_tables
from .scene.tables import scene_defines as scene_program_defines
from .settings import RenderSettings

# settings photon tracing reads, the counts first: a change traces the maps again
_PHOTON_KNOBS = ("global_photons", "caustic_photons", "seed", "photon_k", "max_bounces")
# scene parts the photon maps are made from; the last two only weigh the
# photons when no light moves (photons/reweight.py)
_PHOTON_PARTS = ("geometry", "materials", "lights", "world")
_PHOTON_PATH_KEY = len(_PHOTON_KNOBS) + 2  # the photon key's knobs, geometry and materials
# settings the GI cache reads beyond the photon maps': a change runs its stages again
_CACHE_KNOBS = ("gi_subpixels", "cache_seeds", "cache_alpha", "cache_iterations", "cut_delta", "gather_rays",
                "caustic_k")
# cache knobs outside the records key's shared part: the grid (records are in world space) and
# the number of cache points (ordered: a view reads records gathered from at least as many)
_RECORDS_OWN = ("gi_subpixels", "cache_seeds")


@dataclass
class Held:
    """What a renderer keeps on the device between renders, as the plan
    sees it: each part's digest and generation (bumped at every change),
    the tables uploaded, and the keys of the photon maps and of the GI
    cache (irradiance on the shading-point grid) held."""

    digests: dict | None = None  # part -> digest of what is uploaded (None: unknown)
    generations: dict = field(default_factory=lambda: {part: 0 for part in PARTS})
    tables: SceneTables | None = None
    photon_key: tuple | None = None
    photon_emitters: list | None = None  # the emitters of the photon maps held, as traced or last reweighted
    photon_lights: object = None  # and the light table they were traced with
    cache_key: tuple | None = None
    records_keys: tuple = ()  # of the cache records held (views of a lit scene)
    tree_base: object = None  # (N, 3, 3) triangles the held kd-tree's base was built over (world positions)


@dataclass
class Plan:
    """What one render does."""

    mode: str
    stages: list[str]  # stages and features in order; "_reused" where kept from an earlier render
    changed: set[str]  # scene parts uploaded
    digests: dict  # the scene's part digests (None for a part the caller named as edited: not hashed)
    generations: dict  # part generations after this render's changes
    tables: SceneTables
    emitters: list[Emitter]
    photon_maps: dict[str, str]  # map -> "built..." or "skipped: why"
    photon_counts: tuple  # (global, caustic) photons emitted for the maps this render uses
    photons_reused: bool  # the maps held are used again
    photon_scales: object  # (E, 4) float32 when the maps held are reweighted for new light powers, else None
    photon_key: tuple | None  # of the maps this render uses
    cache_reused: bool  # the GI cache held (same view, scene and settings) is used again
    cache_key: tuple | None  # of the GI cache this render uses
    records_reused: bool  # cache records of an earlier view of the same lit scene are kept
    records_key: tuple | None  # of the cache records this render leaves
    records_source: tuple | None  # of the held cache records it reads (None: none)
    scene_defines: dict  # program features of every kernel that reads the scene
    image_defines: dict  # the image kernel's, scene features included
    programs: list[tuple[str, dict]]  # every program the render builds
    device_bytes: int
    largest_buffer: int
    reuse: dict = field(default_factory=dict)  # what is kept, and why
    tree_rows: object = None  # triangles moved since the held base tree, when an overlay tree holds them

    @property
    def builds_tree(self) -> bool:
        """The whole kd-tree is built (not kept, nor overlaid)."""
        return "kdtree" in self.stages

    @property
    def reweights_photons(self) -> bool:
        return self.photon_scales is not None

    @property
    def traces_photons(self) -> bool:
        return (not self.photons_reused and not self.reweights_photons
                and any(v.startswith("built") for v in self.photon_maps.values()))

    def check_budget(self, device) -> None:
        """A clear error before any upload when the render cannot fit the device."""
        if self.device_bytes > device.global_mem_bytes or self.largest_buffer > device.max_alloc_bytes:
            raise BudgetError(
                f"the render needs about {self.device_bytes / 2**20:.0f} MiB of device memory "
                f"(largest buffer {self.largest_buffer / 2**20:.0f} MiB); {device.name} has "
                f"{device.global_mem_bytes / 2**20:.0f} MiB ({device.max_alloc_bytes / 2**20:.0f} MiB per buffer). "
                "Lower the resolution, texture sizes or photon counts, or simplify the scene."
            )


def changed_parts(scene: Scene, held: Held, edits: set[str] | None) -> tuple[set[str], dict | None]:
    """The parts that differ from what is held (all when nothing is), and
    the scene's part digests; ``edits`` (named by the caller, who knows what
    it changed) skips the hashing of every part but the camera, which is
    always compared (it is small, and views change without an edit)."""
    if edits is not None:
        camera = part_digests(scene, ("camera",))["camera"]
        if held.tables is None or held.digests is None:
            return set(PARTS), {part: None for part in PARTS} | {"camera": camera}
        named = set(edits) & set(PARTS)
        # an edited part's digest is unknown until hashed; the others' stay
        digests = {part: None if part in named else held.digests[part] for part in PARTS} | {"camera": camera}
        return named | ({"camera"} if camera != held.digests["camera"] else set()), digests
    digests = part_digests(scene)
    if held.digests is None or held.tables is None:
        return set(PARTS), digests
    return {part for part in PARTS if held.digests[part] is None or digests[part] != held.digests[part]}, digests


def plan(scene: Scene, settings: RenderSettings, held: Held | None = None, edits: set[str] | None = None,
         device=None) -> Plan:
    """The plan of rendering the validated ``scene`` with validated
    ``settings`` after what ``held`` says is on the device."""
    held = held or Held()
    changed, digests = changed_parts(scene, held, edits)
    tables = scene_tables(scene, held.tables, changed)
    if held.tables is not None and (tables.center != held.tables.center).any():
        changed = set(PARTS)  # the frame moved: everything is uploaded again
    generations = {part: held.generations[part] + (part in changed) for part in PARTS}
    tree_rows = None
    if "geometry" in changed and held.tables is not None and (tables.center == held.tables.center).all():
        tree_rows = kdtree_overlay.moved_rows(held.tree_base, scene.triangles)
    tree_stage = "kdtree_reused" if "geometry" not in changed else "kdtree" if tree_rows is None else "kdtree_overlay"
    stages = ["validate", tree_stage, "upload", "direct_light"]
    stages += _features(scene, settings, tables)
    scene_defines = scene_program_defines(scene)
    image_defines = dict(scene_defines)
    if "light_passes" in stages:
        image_defines["IMAGE_LIGHT_PASSES"] = 1
    emitters, maps, photon_key, reuse, reused, scales, counts = [], {}, None, {}, False, None, (0, 0)
    cache_key, cache_reused, records_key, records_source, records_reused = None, False, None, None, False
    if settings.mode == "gi":
        image_defines["IMAGE_GI"] = 1
        emitters = emitter_powers(scene, tables)
        counts, specular = (settings.global_photons, settings.caustic_photons), scene.has_specular()
        choice = (scene, settings, tables, generations, held, emitters, specular)
        maps, photon_key, reused, scales, why = _photon_choice(*choice, counts)
        if not reused and scales is None and settings.photon_share < 1.0:
            # the maps are traced anyway: a share of them (a quick image)
            counts = tuple(max(1, round(c * settings.photon_share)) if c > 0 else 0 for c in counts)
            maps, photon_key, reused, scales, why = _photon_choice(*choice, counts)
        if why:
            reuse["photons"] = why
        cache_key = (photon_key + tuple(getattr(settings, k) for k in _CACHE_KNOBS)
                     + tuple(generations[p] for p in PARTS))
        cache_reused = cache_key == held.cache_key
        if cache_reused:
            reuse["gi_cache"] = "neither the view, the scene nor the GI settings changed"
        # records hold for every view of the lit scene: the cache key but the camera and grid,
        # the number of cache points last (a view may read records of more)
        records_key = (photon_key + tuple(getattr(settings, k) for k in _CACHE_KNOBS if k not in _RECORDS_OWN)
                       + (settings.cache_seeds,))
        if settings.cache_reuse and not cache_reused:
            records_source = _records_source(records_key, held.records_keys)
        records_reused = records_source is not None
        if records_reused:
            reuse["cache_records"] = ("only the view changed: records in world space are kept"
                                      + ("" if records_source == records_key else
                                         f" (those of {records_source[-1]} cache points, a finer pass's)"))
        stages += _gi_stages(maps, "_reused" if reused else "_reweighted" if scales is not None else "",
                             cache_reused, records_reused)
        if "glossy" in stages and maps["global"].startswith("built"):
            # glossy paths read the cut where they land on diffuse surfaces
            stages.append("glossy_cut")
            image_defines.update(IMAGE_GLOSSY_CUT=1, **gi_cut.image_lookup_defines())
    if settings.denoise:
        stages.append("denoise")
    if "geometry" not in changed:
        reuse["kdtree"] = "the triangles did not change"
    elif tree_rows is not None:
        reuse["kdtree"] = (f"{len(tree_rows)} of {scene.triangle_count} triangles moved: the tree held is kept "
                           "and joined with a tree over them")
    the_plan = Plan(
        mode=settings.mode, stages=stages, changed=changed, digests=digests, generations=generations, tables=tables,
        emitters=emitters, photon_maps=maps, photon_counts=counts, photons_reused=reused, photon_scales=scales,
        photon_key=photon_key, cache_reused=cache_reused, cache_key=cache_key, records_reused=records_reused, records_key=records_key,
        records_source=records_source, scene_defines=scene_defines,
        image_defines=image_defines, programs=[], device_bytes=0, largest_buffer=0, reuse=reuse, tree_rows=tree_rows)
    the_plan.device_bytes, the_plan.largest_buffer = _device_bytes(scene, settings, the_plan)
    if device is not None and hasattr(device, "device"):
        the_plan.programs = _programs(device, settings, the_plan)
    return the_plan


def _photon_choice(scene: Scene, settings: RenderSettings, tables: SceneTables, generations: dict, held: Held,
                   emitters: list[Emitter], specular: bool, counts: tuple) -> tuple:
    """The photon maps of ``counts`` (global, caustic) photons: which are
    built, their key, whether the maps held are those (reused) or can be
    reweighted to them (the factors), and why."""
    maps = maps_needed(emitters, scene.triangle_count, specular, *counts)
    key = counts + tuple(getattr(settings, k) for k in _PHOTON_KNOBS[2:]) + tuple(generations[p] for p in _PHOTON_PARTS)
    if key == held.photon_key:
        return maps, key, True, None, "neither the lit scene nor the photon settings changed"
    if (held.photon_key is not None and held.photon_key[:_PHOTON_PATH_KEY] == key[:_PHOTON_PATH_KEY]
            and held.photon_emitters is not None):
        scales = reweight_scales(held.photon_emitters, held.photon_lights, emitters, tables.lights)
        if scales is not None:
            return maps, key, False, scales, "only the lights' power or colour changed: the photons are reweighted"
    return maps, key, False, None, ""


def _features(scene: Scene, settings: RenderSettings, tables: SceneTables) -> list[str]:
    """The kernel features this scene and these settings need."""
    features = []
    if scene.has_specular():
        features.append("specular_paths")
    if scene.has_glossy():
        features.append("glossy")
    if settings.diffuse_bounces > 0 and settings.mode != "gi":
        features.append("path_traced_indirect")
    if scene.has_textures():
        features.append("textures")
    if scene.has_tangents():
        features.append("corner_tangents")
    if len(tables.emit_tris):
        features.append("mesh_lights")
    if scene.has_alpha():
        features.append("alpha_shadows")
    if scene.has_mix():
        features.append("mixed_surfaces")
    if settings.light_passes:
        features.append("light_passes")
    if settings.denoising_passes:
        features.append("denoising_passes")
    return features


def _records_source(key: tuple, held_keys: tuple) -> tuple | None:
    """The held cache records a view of ``key`` reads: its own, else those
    of the same lit scene and knobs gathered from more cache points (a
    viewport's coarse pass after a full one: records at least as dense),
    the densest; None when neither is held."""
    if key in held_keys:
        return key
    finer = [held for held in held_keys if held[:-1] == key[:-1] and held[-1] > key[-1]]
    return max(finer, key=lambda held: held[-1]) if finer else None


def _gi_stages(maps: dict[str, str], photons: str, cache_reused: bool, records_reused: bool) -> list[str]:
    """The GI stages: the photon maps traced (``photons`` "") or held
    ("_reused", "_reweighted"), then the cache
    stages where there is light (cache points and gathering only where the
    records kept leave gaps), and caustics where there is a caustic map
    (each "_reused" when the cache held is used again)."""
    stages = [f"{name}_photons{photons}" for name in ("global", "caustic") if maps[name].startswith("built")]
    cache = []
    if maps["global"].startswith("built"):
        cache += ["shading_points", *(["cache_records_reused"] if records_reused else []), "sample_points",
                  "illumination_cut", "final_gather", "interpolation"]
    elif maps["caustic"].startswith("built"):
        cache.append("shading_points")
    if maps["caustic"].startswith("built"):
        cache.append("caustics")
    return stages + [stage + ("_reused" if cache_reused and not stage.endswith("_reused") else "") for stage in cache]


# device bytes per item, generous estimates (the kd-tree's own arrays vary with the scene)
_TRIANGLE_BYTES = 48 + 48 + 24 + 4 + 4 * 8 + 16  # corners, normals, uvs, material, leaf references and nodes
_TANGENT_BYTES = 48  # corner tangents, where a scene has them
_BLOCK_BYTES = kdtree_blocks.BLOCK_BYTES  # leaf blocks (on a CPU device; 0.5-0.66 a triangle measured on meshes)
_STORED_PHOTON_BYTES = 4 * 16 + 4 * 16 + 16  # trace buffers, tree points and attributes, a node share
_GRID_SLOT_BYTES = 4 * 16 + 16 + 16 + 8 + 4 + 16 + 24  # grid, compacted point, cache work arrays


def _device_bytes(scene: Scene, settings: RenderSettings, the_plan: Plan) -> tuple[int, int]:
    """Device memory of the render (GI included), and its largest buffer."""
    tables = the_plan.tables
    n = scene.triangle_count
    texels = len(tables.atlas) * 16
    window = scene.camera.pixel_window
    film = film_bytes(window, settings)
    per_triangle = _TRIANGLE_BYTES + (_TANGENT_BYTES if len(scene.tangents) else 0)
    need = n * per_triangle + min(n * _BLOCK_BYTES, kdtree_blocks.MAX_BYTES) + texels + film + tables.lights.nbytes \
        + tables.materials.nbytes
    largest = max(n * 48, texels, film)
    if settings.mode == "gi":
        x0, y0, x1, y1 = window
        slots = (x1 - x0) * (y1 - y0) * settings.gi_subpixels**2
        stored = 0
        if the_plan.photon_maps.get("global", "").startswith("built"):
            stored += photon_trace.STORE_GUESS * settings.global_photons
        if the_plan.photon_maps.get("caustic", "").startswith("built"):
            stored += settings.caustic_photons
        need += stored * _STORED_PHOTON_BYTES + slots * _GRID_SLOT_BYTES
        if "final_gather" in the_plan.stages:
            need += gi_gather.batch_bytes(settings.cache_seeds, gi_pipeline.strata(settings.gather_rays))
        largest = max(largest, photon_trace.STORE_GUESS * settings.global_photons * 16, slots * 16)
    return int(need), int(largest)


def _programs(device, settings: RenderSettings, the_plan: Plan) -> list[tuple[str, dict]]:
    """Every program the render builds, in the order the stages need them
    (they are built from the start, in that order)."""
    wanted = primitives_programs()
    if "kdtree" in the_plan.stages or "kdtree_overlay" in the_plan.stages:
        wanted += kdtree_build.programs(device) + (kdtree_blocks.programs() if kdtree_blocks.wanted(device) else [])
    if "kdtree_overlay" in the_plan.stages:
        wanted += kdtree_overlay.programs()
    if settings.mode == "gi":
        if the_plan.traces_photons:
            wanted += photon_trace.programs(the_plan.scene_defines)
        if the_plan.reweights_photons:
            wanted += photon_reweight.programs()
        if not the_plan.cache_reused:
            wanted += gi_pipeline.programs(device, settings, the_plan.stages, the_plan.scene_defines)
    return wanted + image_programs(the_plan.image_defines)
