"""The plain-numpy scene gpu_core renders (validate.py checks it on entry).

Everything is a struct of arrays in world space, in Blender's units:
light power in watts (sun: W/m^2), emission as radiance (colour x strength),
world colour x strength as radiance. Positions are float64 so that a scene far
from the origin keeps its precision until the renderer recentres it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, fields

import numpy as np

from ..device.constants import (AREA_RECTANGLE, CAMERA_PERSP, CAUSTIC_ROUGHNESS, FILTER_BOX, LIGHT_POINT, LIGHT_SUN,
                                MATERIAL_PRINCIPLED, MATERIAL_TRANSPARENT, TEXTURE_LUMINANCE)


_SINGULAR_ROUGHNESS = 2e-10 ** 0.25  # roughness of MICROFACET_SINGULAR_ALPHA2 (alpha = roughness^2)
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)  # shading/texture.h's Texture_value, Blender's linear Rec. 709


@dataclass
class Materials:
    """One row per material; a triangle's ``material_ids`` entry indexes it.

    The columns are the Principled BSDF's inputs (shading/bsdf.h), or a
    Glossy or Glass shader node's (``shader``). Unlike Blender's Principled
    BSDF, a row made here has no specular layer unless it asks for one
    (``specular_ior_level`` 0: a Lambertian base); the add-on passes
    Blender's value (0.5 by default).

    A mix of surfaces (Mix and Add Shader) is a chain of rows from the
    triangle's row along ``mix_next``: each shading event uses one row of
    it, picked with the rows' chances (``mix_stop``), its BSDF scaled by
    ``mix_scale`` so the pick is unbiased. Emission is the first row's.
    """

    base_color: np.ndarray  # (M, 3) float32, linear
    metallic: np.ndarray  # (M,) float32
    roughness: np.ndarray  # (M,) float32
    transmission: np.ndarray  # (M,) float32
    ior: np.ndarray  # (M,) float32
    emission: np.ndarray  # (M, 3) float32, colour x strength (radiance)
    alpha: np.ndarray  # (M,) float32
    texture_id: np.ndarray  # (M,) int32 into Scene.textures, -1 for none: multiplies base_color
    roughness_texture: np.ndarray  # (M,) int32, -1 for none: replaces roughness
    roughness_channel: np.ndarray  # (M,) int32: 0-3 r, g, b, a; TEXTURE_LUMINANCE
    metallic_texture: np.ndarray  # (M,) int32, -1 for none: replaces metallic
    metallic_channel: np.ndarray  # (M,) int32, as roughness_channel
    normal_texture: np.ndarray  # (M,) int32, -1 for none: a tangent-space normal map (Normal Map node)
    normal_strength: np.ndarray  # (M,) float32: the Normal Map node's Strength
    mix_next: np.ndarray  # (M,) int32: a mix of surfaces, the chain's next row (a later one), -1 at its end
    mix_stop: np.ndarray  # (M,) float32: the chance of using this row once the pick reached it
    mix_scale: np.ndarray  # (M,) float32: the row's BSDF (and pass-through) times this: weight / chance
    mix_texture: np.ndarray  # (M,) int32, -1 for none: a Mix Shader's Fac, mix_stop = 1 - its value
    mix_channel: np.ndarray  # (M,) int32, as roughness_channel
    specular_ior_level: np.ndarray  # (M,) float32: 0 no dielectric layer, 0.5 F0 of the IOR, 1 twice that
    specular_tint: np.ndarray  # (M, 3) float32: tints F0 of the dielectric layers, F82 of the metal
    shader: np.ndarray  # (M,) int32: MATERIAL_PRINCIPLED, MATERIAL_GLOSSY, MATERIAL_GLASS or MATERIAL_TRANSPARENT
    # (M,) float32: Principled's Anisotropic (0..1) or the Glossy node's
    # Anisotropy (-1..1), stretching the metal and specular lobes along the
    # corner tangents (Scene.tangents; a triangle's UV direction without)
    anisotropy: np.ndarray
    anisotropic_rotation: np.ndarray  # (M,) float32, in turns about the normal
    diffuse_roughness: np.ndarray  # (M,) float32: Principled's Diffuse Roughness or the Diffuse node's (Oren-Nayar)
    # (M,) int32: 1 where the shader's distribution is GGX, whose lobes lose
    # the energy of multiple scattering (0: Multiscatter GGX, Blender's default)
    single_scatter: np.ndarray
    names: list[str] = field(default_factory=list)

    @staticmethod
    def make(rows: list[dict]) -> "Materials":
        """Materials from dicts with the field names above (missing ones default)."""
        defaults = dict(
            base_color=(0.8, 0.8, 0.8),
            metallic=0.0,
            roughness=0.5,
            transmission=0.0,
            ior=1.5,
            emission=(0.0, 0.0, 0.0),
            alpha=1.0,
            texture_id=-1,
            roughness_texture=-1,
            roughness_channel=TEXTURE_LUMINANCE,
            metallic_texture=-1,
            metallic_channel=TEXTURE_LUMINANCE,
            normal_texture=-1,
            normal_strength=1.0,
            mix_next=-1,
            mix_stop=1.0,
            mix_scale=1.0,
            mix_texture=-1,
            mix_channel=TEXTURE_LUMINANCE,
            specular_ior_level=0.0,
            specular_tint=(1.0, 1.0, 1.0),
            shader=MATERIAL_PRINCIPLED,
            anisotropy=0.0,
            anisotropic_rotation=0.0,
            diffuse_roughness=0.0,
            single_scatter=0,
            name="",
        )
        rows = [{**defaults, **row} for row in rows] or [dict(defaults, name="default")]

        def column(key):
            """int32 where the default is an int, float32 otherwise; (M, 3) for colours."""
            default = defaults[key]
            dtype = np.int32 if isinstance(default, int) else np.float32
            shape = (len(rows), len(default)) if isinstance(default, tuple) else (len(rows),)
            return np.array([row[key] for row in rows], dtype=dtype).reshape(shape)

        return Materials(**{key: column(key) for key in defaults if key != "name"},
                         names=[row["name"] for row in rows])

    def __len__(self) -> int:
        return len(self.base_color)

    def next_rows(self) -> np.ndarray:
        """Each row's next row in its mix's chain: mix_next where it is a
        later row (a chain only runs forward, so it ends), else -1."""
        rows = np.arange(len(self))
        return np.where((self.mix_next > rows) & (self.mix_next < len(self)), self.mix_next, -1)


@dataclass
class Lights:
    """One row per light (emissive meshes are triangles, not rows here)."""

    kind: np.ndarray  # (L,) int32, LIGHT_*
    position: np.ndarray  # (L, 3) float64
    direction: np.ndarray  # (L, 3) float32, unit, where the light points (its -Z)
    axis_u: np.ndarray  # (L, 3) float32, area light: full size along its X
    axis_v: np.ndarray  # (L, 3) float32, area light: full size along its Y
    power: np.ndarray  # (L, 3) float32, colour x watts (sun: colour x W/m^2)
    radius: np.ndarray  # (L,) float32, point/spot soft radius
    spot_angle: np.ndarray  # (L,) float32, full cone angle in radians
    spot_blend: np.ndarray  # (L,) float32, 0..1
    sun_angle: np.ndarray  # (L,) float32, angular diameter in radians
    shape: np.ndarray  # (L,) int32, AREA_RECTANGLE or AREA_ELLIPSE
    names: list[str] = field(default_factory=list)

    @staticmethod
    def make(rows: list[dict]) -> "Lights":
        """Lights from dicts with the field names above (missing ones default)."""
        defaults = dict(
            kind=LIGHT_POINT,
            position=(0.0, 0.0, 0.0),
            direction=(0.0, 0.0, -1.0),
            axis_u=(1.0, 0.0, 0.0),
            axis_v=(0.0, 1.0, 0.0),
            power=(0.0, 0.0, 0.0),
            radius=0.0,
            spot_angle=np.pi / 4,
            spot_blend=0.15,
            sun_angle=0.0,
            shape=AREA_RECTANGLE,
            name="",
        )
        rows = [{**defaults, **row} for row in rows]

        def column(key, dtype, width=None):
            shape = (len(rows), width) if width else (len(rows),)
            return np.array([row[key] for row in rows], dtype=dtype).reshape(shape)

        return Lights(
            kind=column("kind", np.int32),
            position=column("position", np.float64, 3),
            direction=column("direction", np.float32, 3),
            axis_u=column("axis_u", np.float32, 3),
            axis_v=column("axis_v", np.float32, 3),
            power=column("power", np.float32, 3),
            radius=column("radius", np.float32),
            spot_angle=column("spot_angle", np.float32),
            spot_blend=column("spot_blend", np.float32),
            sun_angle=column("sun_angle", np.float32),
            shape=column("shape", np.int32),
            names=[row["name"] for row in rows],
        )

    def __len__(self) -> int:
        return len(self.kind)

    def subset(self, keep: np.ndarray) -> "Lights":
        names = [n for n, k in zip(self.names, keep) if k] if self.names else []
        return Lights(
            **{
                name: getattr(self, name)[keep]
                for name in (
                    "kind position direction axis_u axis_v power radius "
                    "spot_angle spot_blend sun_angle shape"
                ).split()
            },
            names=names,
        )


@dataclass
class Camera:
    """A pinhole or orthographic camera and the pixels to render.

    ``window`` (x0, x1, y0, y1) is the image rectangle in camera space: on the
    plane z = -1 for a perspective camera (sensor fit and lens shift already
    applied), in scene units for an orthographic one. ``border`` (x0, y0, x1,
    y1) is the pixel window to render, x1/y1 exclusive; rows count from the
    bottom, as in Blender's render result. ``filter_kind`` (FILTER_*) and
    ``filter_width`` (pixels) are the pixel filter, as Cycles' film sets them.
    """

    matrix: np.ndarray  # (4, 4) float64, camera to world (camera looks down -Z)
    window: tuple[float, float, float, float]
    width: int
    height: int
    kind: int = CAMERA_PERSP
    clip_start: float = 0.1
    clip_end: float = 1000.0
    border: tuple[int, int, int, int] | None = None
    filter_kind: int = FILTER_BOX
    filter_width: float = 1.0

    @property
    def pixel_window(self) -> tuple[int, int, int, int]:
        if self.border is None:
            return (0, 0, self.width, self.height)
        return self.border


@dataclass
class ValidationReport:
    """What validation dropped or repaired, for stats and warnings."""

    dropped_nonfinite_triangles: int = 0
    dropped_degenerate_triangles: int = 0
    repaired_material_ids: int = 0
    repaired_normals: int = 0
    dropped_lights: int = 0
    repaired_materials: int = 0
    messages: list[str] = field(default_factory=list)

    def as_stats(self) -> dict:
        return {
            "dropped_nonfinite_triangles": self.dropped_nonfinite_triangles,
            "dropped_degenerate_triangles": self.dropped_degenerate_triangles,
            "repaired_material_ids": self.repaired_material_ids,
            "repaired_normals": self.repaired_normals,
            "dropped_lights": self.dropped_lights,
            "repaired_materials": self.repaired_materials,
        }


@dataclass
class Scene:
    """Triangles (a soup), their materials, lights, world and camera."""

    triangles: np.ndarray  # (N, 3, 3) float64 world positions
    normals: np.ndarray  # (N, 3, 3) float32 corner normals (world, unit)
    uvs: np.ndarray  # (N, 3, 2) float32
    material_ids: np.ndarray  # (N,) int32
    materials: Materials
    lights: Lights
    camera: Camera
    world_color: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    textures: list[np.ndarray] = field(default_factory=list)  # (H, W, 4) float32, linear
    texture_closest: list[bool] = field(default_factory=list)  # per texture: the nearest texel, not bilinear
    # (N, 3, 4) float32 per corner: the tangent (world) a normal map or
    # anisotropy reads and in w its bitangent's sign (MikkTSpace's, or radial
    # ones); empty (0, 3, 4): none (tangents then come from each triangle's
    # UVs); a zero tangent, the same
    tangents: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 4), np.float32))
    warnings: list[str] = field(default_factory=list)
    report: ValidationReport = field(default_factory=ValidationReport)

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    def used_materials(self) -> np.ndarray:
        """Indices of the materials some triangle uses, with the rows of
        their mixes (chains along mix_next, forward only as the table's)."""
        following = self.materials.next_rows()
        used = self._materials_of_triangles()
        while True:
            nxt = following[used[(used >= 0) & (used < len(following))]]
            more = np.union1d(used, nxt[nxt >= 0])
            if len(more) == len(used):
                return used
            used = more

    def has_mix(self) -> bool:
        """Whether a triangle's material mixes surfaces (a chain of rows)."""
        following, rows = self.materials.next_rows(), self._materials_of_triangles()
        return bool((following[rows[(rows >= 0) & (rows < len(following))]] >= 0).any())

    def _materials_of_triangles(self) -> np.ndarray:
        """The sorted distinct material ids of the triangles: counted per id
        (much faster than sorting them all) where the ids span a range no
        wider than the table and the triangles. Kept with this scene for its
        material ids array (a plan asks nine times: 7 ms of every render of
        the large scene)."""
        memo = self.__dict__.get("_used_ids")
        if memo is not None and memo[0] is self.material_ids:
            return memo[1]
        ids = np.asarray(self.material_ids).ravel()
        if not len(ids):
            used = np.zeros(0, ids.dtype)
        else:
            low, high = int(ids.min()), int(ids.max())
            if high - low > len(ids) + len(self.materials) + 1024:
                used = np.unique(ids)
            else:
                used = (np.flatnonzero(np.bincount(ids - low)) + low).astype(ids.dtype)
        used.flags.writeable = False  # shared by every caller
        self.__dict__["_used_ids"] = (self.material_ids, used)
        return used

    def has_specular(self) -> bool:
        """Whether a triangle is near-specular metal or glass (roughness
        below CAUSTIC_ROUGHNESS somewhere): specular paths and, where light
        reaches them, caustics."""
        used, m = self.used_materials(), self.materials
        roughness = self._value_range(m.roughness, m.roughness_texture, m.roughness_channel, used, 0.5)
        metallic = self._value_range(m.metallic, m.metallic_texture, m.metallic_channel, used, 0.0)
        smooth = roughness[0] < CAUSTIC_ROUGHNESS
        return bool((smooth & ((metallic[1] > 0) | (m.transmission[used] > 0))).any())

    def has_glossy(self) -> bool:
        """Whether a triangle has a glossy lobe: metal, glass or a
        dielectric specular layer rougher than a mirror (alpha^2 above
        shading/microfacet.h's MICROFACET_SINGULAR_ALPHA2) somewhere."""
        used, m = self.used_materials(), self.materials
        roughness = self._value_range(m.roughness, m.roughness_texture, m.roughness_channel, used, 0.5)
        metallic = self._value_range(m.metallic, m.metallic_texture, m.metallic_channel, used, 0.0)
        rough = roughness[1] > _SINGULAR_ROUGHNESS
        lobes = (metallic[1] > 0) | (m.transmission[used] > 0) | (m.specular_ior_level[used] > 0)
        return bool((rough & lobes).any())

    def _value_range(self, values, texture, channel, used, default) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of a material input over rows ``used``: its value, or
        the range of its texture's channel where one is bound (clipped to
        [0, 1] like the table's)."""
        value = np.nan_to_num(values[used].astype(np.float64), nan=default)
        low, high = value.copy(), value.copy()
        for row, (tex, ch) in enumerate(zip(texture[used], channel[used])):
            if 0 <= tex < len(self.textures):
                texels = texture_channel(self.textures[tex], int(ch))
                low[row], high[row] = np.clip([np.nanmin(texels), np.nanmax(texels)], 0.0, 1.0)
        return low, high

    def has_tangents(self) -> bool:
        """Whether corner tangents are given and a triangle's material reads
        them: a normal map, or anisotropy."""
        if not len(self.tangents):
            return False
        used, m = self.used_materials(), self.materials
        return bool(((m.normal_texture[used] >= 0) | (m.anisotropy[used] != 0)).any())

    def has_textures(self) -> bool:
        """Whether a triangle's material reads a texture."""
        used, m = self.used_materials(), self.materials
        bound = [m.texture_id[used], m.roughness_texture[used], m.metallic_texture[used], m.normal_texture[used],
                 m.mix_texture[used]]
        return bool(self.textures) and any(bool((ids >= 0).any()) for ids in bound)

    def has_alpha(self) -> bool:
        """Whether a triangle's material is see-through (Alpha, or a Transparent shader)."""
        used, m = self.used_materials(), self.materials
        return bool(((m.alpha[used] < 1.0) | (m.shader[used] == MATERIAL_TRANSPARENT)).any())

    def triangle_bounds(self) -> np.ndarray:
        """(2, 3): min and max of the triangles' corners; empty (0, 3) without triangles."""
        if not len(self.triangles):
            return np.zeros((0, 3))
        # axis by axis (numpy reduces short rows slowly)
        axes = [self.triangles[:, :, k] for k in range(3)]
        return np.array([[a.min() for a in axes], [a.max() for a in axes]])

    def bounds(self, triangle_bounds: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) of triangles and positional lights; a unit box if empty.
        ``triangle_bounds``: the triangles' own (triangle_bounds()), when known."""
        triangles = self.triangle_bounds() if triangle_bounds is None else triangle_bounds
        pts = np.concatenate([triangles, self.lights.position[self.lights.kind != LIGHT_SUN].reshape(-1, 3)])
        if len(pts) == 0:
            return np.full(3, -1.0), np.full(3, 1.0)
        return pts.min(axis=0), pts.max(axis=0)


def texture_channel(pixels: np.ndarray, channel: int) -> np.ndarray:
    """The values a value socket reads from (H, W, 4) linear pixels: one
    channel, or the colour's luminance (TEXTURE_LUMINANCE, Rec. 709
    weights as Blender's colour-to-value conversion)."""
    if channel == TEXTURE_LUMINANCE:  # the weighted sum written out: ``@`` on a texture over
        # 3,072 texels wide goes to OpenBLAS's threads, which then spin beside
        # the kernels (README, "numpy's BLAS threads and the first kernels")
        r, g, b = (np.float32(w) for w in LUMINANCE_WEIGHTS)
        return pixels[..., 0] * r + pixels[..., 1] * g + pixels[..., 2] * b
    return pixels[..., min(max(channel, 0), 3)]


# The parts of a scene an edit can change on its own; each is uploaded, and
# invalidates what depends on it, apart from the others (plan.py).
PARTS = ("geometry", "materials", "lights", "world", "camera")


def part_digests(scene: Scene, parts=PARTS) -> dict[str, "PartDigest"]:
    """A digest of each of ``parts``: renders whose parts have the same
    digests can share what was built from those parts (kd-tree, tables,
    photon maps, the GI cache)."""
    m, lights, camera = scene.materials, scene.lights, scene.camera
    arrays = {
        "geometry": lambda: [scene.triangles, scene.normals, scene.uvs, scene.material_ids, scene.tangents],
        "materials": lambda: ([getattr(m, f.name) for f in fields(Materials) if f.name != "names"] + list(scene.textures)
                              + [scene.texture_closest]),
        "lights": lambda: [getattr(lights, f.name) for f in fields(Lights) if f.name != "names"],
        "world": lambda: [scene.world_color],
        "camera": lambda: [np.asarray(camera.matrix), np.asarray(camera.window),
                           np.array([camera.width, camera.height, camera.kind, camera.clip_start, camera.clip_end,
                                     *(camera.border or (-1, -1, -1, -1)), camera.filter_kind, camera.filter_width],
                                    np.float64)],
    }
    return {part: PartDigest(arrays[part]()) for part in parts}


class PartDigest:
    """The digest of a part's arrays, hashed only when a comparison needs
    it: a renderer's first render has nothing to compare with (an F12
    render's fresh renderer never hashes; the large scene's geometry took
    ~40 ms), and a part whose arrays are the very objects of the last
    render's is the same without hashing (callers put new arrays in a scene
    for what changed and never write into one already rendered). It holds
    the part's arrays (a held renderer's digests keep the last scene's)."""

    def __init__(self, arrays: list):
        self._arrays = arrays
        self._value: bytes | None = None

    @property
    def value(self) -> bytes:
        if self._value is None:
            digest = hashlib.blake2b(digest_size=16)
            for array in self._arrays:
                a = np.ascontiguousarray(array)
                digest.update(str((a.dtype, a.shape)).encode())
                digest.update(a.tobytes())
            self._value = digest.digest()
        return self._value

    def __eq__(self, other) -> bool:
        if not isinstance(other, PartDigest):
            return NotImplemented
        if len(self._arrays) == len(other._arrays) and all(a is b for a, b in zip(self._arrays, other._arrays)):
            return True
        return self.value == other.value

    __hash__ = None
