"""Blender materials (Cycles node trees) to gpu_core material rows.

Supported: Principled BSDF (Base Color, Metallic, Roughness, Transmission
Weight, IOR, Specular IOR Level, Specular Tint, Emission Color x Strength,
Alpha), Diffuse, Glossy, Glass, Transparent and Emission shaders, Add and
Mix Shader over them (emission is summed; the surfaces become a chain of
rows, one picked per shading event by its weight; a Mix's Fac may be an
Image Texture where it mixes two surfaces), an Image Texture on Base Color
or Color, on Roughness or Metallic (its Color as luminance, its Alpha, or a
channel through Separate Color), and a tangent-space Normal Map node with
an Image Texture on the shaders' Normal. Anything else falls back to a
default value and is named in the warnings; nothing here raises on an
unexpected node tree.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpu_core.scene import MATERIAL_GLASS, MATERIAL_GLOSSY, MATERIAL_TRANSPARENT, TEXTURE_LUMINANCE

DEFAULT_ROW = {"base_color": (0.8, 0.8, 0.8), "roughness": 0.5}
BLACK = (0.0, 0.0, 0.0)
_GLOSSY = ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic")
_SRGB_SPACES = ("sRGB", "sRGB EOTF")
# Separate Color (and the older Separate RGB) between an Image Texture and a value socket: output -> channel
_SEPARATE_NODES = ("ShaderNodeSeparateColor", "ShaderNodeSeparateRGB")
_SEPARATE_CHANNELS = {"Red": 0, "Green": 1, "Blue": 2, "R": 0, "G": 1, "B": 2}
# Principled layers the renderer has no model for, with the input that switches them on
_PRINCIPLED_UNSUPPORTED = (("Subsurface Weight", "subsurface"), ("Coat Weight", "coat"), ("Sheen Weight", "sheen"),
                           ("Thin Film Thickness", "thin film"))
# the tangent an anisotropic shader reads with its Tangent input unlinked, as Cycles: radial about Z
DEFAULT_TANGENT = ("RADIAL", "Z")


@dataclass
class Surface:
    """What a shader node outputs: its surfaces, each a row with the weight
    it is summed with, and the emission they add."""

    leaves: list = field(default_factory=list)  # (weight, row)
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    fac: dict | None = None  # a Mix's Fac texture over exactly two leaves: mix_texture, mix_channel, mix_stop


class MaterialTable:
    """Material rows and textures, one row per distinct Blender material."""

    def __init__(self, pixels: dict | None = None):
        """``pixels``: image name -> linear pixels read before, kept by the
        caller across tables (an image is read once until it is edited)."""
        self.rows: list[dict] = [{**DEFAULT_ROW, "name": "default"}]
        self.textures: list[np.ndarray] = []
        self.texture_closest: list[bool] = []  # per texture: the node's Closest interpolation
        self.exported = 0  # materials read from Blender so far
        self._index: dict = {None: 0}
        self._chains: dict = {}  # material -> rows after its first that hold the other surfaces of its mix
        self._images: dict = {}
        self._pixels = {} if pixels is None else pixels
        self._stale: set[str] = set()  # materials edited since their row was made
        self._notes: dict = {}  # material -> its warnings
        self._exporting = None

    def index(self, material) -> int:
        """Row of ``material`` (None = the default row), exported on first use.

        The evaluated material is read (animated values at the render's
        frame), keyed by the datablock it was evaluated from.
        """
        key = material.original.name_full if material is not None else None
        if key not in self._index:
            self._index[key] = len(self.rows)
            self.rows.append({})
            self._place(key, self._exported(key, material))
        elif key in self._stale:
            self._place(key, self._exported(key, material))
        self._stale.discard(key)
        return self._index[key]

    def _place(self, key, rows: list[dict]) -> None:
        """Put a material's rows in the table: the first at its index, the
        rest of its mix in rows of its own after it (kept across edits,
        more added at the end when an edit needs them), linked by mix_next."""
        chain = self._chains.setdefault(key, [])
        while len(chain) < len(rows) - 1:
            chain.append(len(self.rows))
            self.rows.append({**DEFAULT_ROW, "name": f"{rows[0]['name']} (unused)"})
        slots = [self._index[key]] + chain[:len(rows) - 1]
        for i, (slot, row) in enumerate(zip(slots, rows)):
            self.rows[slot] = {**row, "mix_next": slots[i + 1] if i + 1 < len(slots) else -1}

    def tangents_of(self, rows) -> dict:
        """The tangents the materials of ``rows`` (table rows, their mixes
        followed) read, by row: "UV" where a normal map bends the normal or
        the anisotropy follows a UV map (MikkTSpace's, the normal map's
        winning where a row has both), ("RADIAL", axis) where it follows an
        axis of the object's texture space; rows reading none are left out."""
        todo, seen, out = [int(r) for r in rows], set(), {}
        while todo:
            row = todo.pop()
            if row in seen or not 0 <= row < len(self.rows):
                continue
            seen.add(row)
            fields = self.rows[row]
            tangent = fields.get("tangent")
            if fields.get("normal_texture", -1) >= 0 or (tangent is not None and tangent[0] == "UV"):
                out[row] = "UV"
            elif tangent is not None:
                out[row] = tangent
            todo.append(fields.get("mix_next", -1))
        return out

    def forget(self, name: str) -> None:
        """Export the material ``name`` again at its next use (it was edited);
        its row keeps its place, so material ids stay."""
        self._stale.add(name)

    @property
    def warnings(self) -> list[str]:
        """What the materials' export left out, each message once."""
        return list(dict.fromkeys(message for notes in self._notes.values() for message in notes))

    def _exported(self, key, material) -> dict:
        """The row of ``material``, its warnings kept under ``key``."""
        self._exporting, self._notes[key] = key, []
        self.exported += 1
        try:
            return self._export(material)
        finally:
            self._exporting = None

    def _warn(self, message: str) -> None:
        notes = self._notes.setdefault(self._exporting, [])
        if message not in notes:
            notes.append(message)

    # -- node tree ------------------------------------------------------------

    def _export(self, mat) -> list[dict]:
        """The rows of one material: its surface shader's (one per surface
        of a mix), or its viewport colours."""
        if mat.node_tree is None:
            return [{
                "name": mat.name,
                "base_color": tuple(mat.diffuse_color[:3]),
                "metallic": float(mat.metallic),
                "roughness": float(mat.roughness),
            }]
        output = _output_node(mat.node_tree)
        source = _linked_node(output.inputs["Surface"]) if output is not None else None
        if source is None:
            self._warn(f"material '{mat.name}': nothing is connected to the Surface output; used the default material")
            return [{**DEFAULT_ROW, "name": mat.name}]
        return _mix_rows(mat.name, self._shader(mat.name, source))

    def _shader(self, name: str, node) -> Surface:
        """What the shader ``node`` outputs."""
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            row = self._principled(name, node)
            return Surface([(1.0, row)], np.array(row.pop("emission")))
        if kind in ("ShaderNodeAddShader", "ShaderNodeMixShader"):
            return self._combine(name, node)
        if kind == "ShaderNodeEmission":
            color = np.array(self._color_value(name, node.inputs["Color"])) * self._value(name, node.inputs["Strength"])
            return Surface([], color)
        return Surface([(1.0, self._bsdf(name, node))])

    def _bsdf(self, name: str, node) -> dict:
        """The row of a one-lobe shader node (Diffuse, Glossy, Glass, Transparent)."""
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfDiffuse":
            return {**self._color(name, node.inputs["Color"]), "roughness": 1.0,
                    "diffuse_roughness": self._value(name, node.inputs["Roughness"]), **self._normal(name, node)}
        if kind in _GLOSSY:
            return {
                **self._distribution(name, node),
                **self._color(name, node.inputs["Color"]),
                "shader": MATERIAL_GLOSSY,
                "metallic": 1.0,
                **self._texture_value(name, node.inputs["Roughness"], "roughness"),
                **self._normal(name, node),
                **self._anisotropy(name, node, "Anisotropy", "Rotation"),
            }
        if kind == "ShaderNodeBsdfGlass":
            return {
                **self._distribution(name, node),
                **self._color(name, node.inputs["Color"]),
                "shader": MATERIAL_GLASS,
                "transmission": 1.0,
                **self._texture_value(name, node.inputs["Roughness"], "roughness"),
                "ior": self._value(name, node.inputs["IOR"]),
                **self._normal(name, node),
            }
        if kind == "ShaderNodeBsdfTransparent":
            # everything passes, tinted by its colour
            return {"shader": MATERIAL_TRANSPARENT, "base_color": tuple(self._color_value(name, node.inputs["Color"])),
                    "alpha": 0.0}
        self._warn(f"material '{name}': shader node '{node.bl_idname}' is not supported; used the default material")
        return dict(DEFAULT_ROW)

    def _principled(self, name: str, node) -> dict:
        inputs = node.inputs
        emission = np.array(self._color_value(name, inputs["Emission Color"])) * self._value(name, inputs["Emission Strength"])
        for socket_name, layer in _PRINCIPLED_UNSUPPORTED:
            socket = inputs.get(socket_name)
            if socket is not None and (socket.is_linked or socket.default_value > 0.0):
                self._warn(f"material '{name}': the Principled BSDF {layer} layer is not supported; left out")
        return {
            **self._distribution(name, node),
            **self._color(name, inputs["Base Color"]),
            **self._texture_value(name, inputs["Metallic"], "metallic"),
            **self._texture_value(name, inputs["Roughness"], "roughness"),
            **self._normal(name, node),
            "transmission": self._value(name, inputs["Transmission Weight"]),
            "ior": self._value(name, inputs["IOR"]),
            "specular_ior_level": self._value(name, inputs["Specular IOR Level"]),
            "specular_tint": tuple(self._color_value(name, inputs["Specular Tint"])),
            "alpha": self._value(name, inputs["Alpha"]),
            "emission": tuple(float(c) for c in emission),
            **({"diffuse_roughness": self._value(name, inputs["Diffuse Roughness"])}
               if "Diffuse Roughness" in inputs else {}),
            **self._anisotropy(name, node, "Anisotropic", "Anisotropic Rotation"),
        }

    def _distribution(self, name: str, node) -> dict:
        """The row field of a shader's microfacet distribution: GGX keeps
        single scattering only; Beckmann and Ashikhmin-Shirley are named in
        the warnings and render as Multiscatter GGX."""
        distribution = getattr(node, "distribution", "MULTI_GGX")
        if distribution == "GGX":
            return {"single_scatter": 1}
        if distribution != "MULTI_GGX":
            label = node.bl_rna.properties["distribution"].enum_items[distribution].name
            self._warn(f"material '{name}': the {label} distribution of {node.name} is not supported; "
                       "rendered as Multiscatter GGX")
        return {}

    def _anisotropy(self, name: str, node, amount: str, rotation: str) -> dict:
        """Row fields of a shader's anisotropy (its ``amount`` and
        ``rotation`` sockets) and the tangent it is read along (the row's
        "tangent": ("RADIAL", axis) about an axis of the object's texture
        space, or ("UV", map): the map's MikkTSpace tangents)."""
        socket = node.inputs.get(amount)
        if socket is None:
            return {}
        value = self._value(name, socket)
        if value == 0.0:
            return {}
        fields = {"anisotropy": value, "anisotropic_rotation": self._value(name, node.inputs[rotation])}
        source = _linked_node(node.inputs["Tangent"]) if "Tangent" in node.inputs else None
        mapped = _linked_node(node.inputs["Normal"]) if "Normal" in node.inputs else None
        if mapped is not None and mapped.bl_idname == "ShaderNodeNormalMap" and not (
                source is not None and source.bl_idname == "ShaderNodeTangent" and source.direction_type == "UV_MAP"):
            self._warn(f"material '{name}': the anisotropy of {node.name} follows its normal map's UV tangents, "
                       "not the radial one")
        if source is None:
            return {**fields, "tangent": DEFAULT_TANGENT}
        if source.bl_idname == "ShaderNodeTangent":
            if source.direction_type == "UV_MAP":
                return {**fields, "tangent": ("UV", source.uv_map)}
            return {**fields, "tangent": ("RADIAL", source.axis)}
        self._warn(f"material '{name}': '{source.bl_idname}' on {node.name} > Tangent is not supported; "
                   "used the radial tangent about Z")
        return {**fields, "tangent": DEFAULT_TANGENT}

    def _combine(self, name: str, node) -> Surface:
        """Add/Mix Shader: the surfaces of both inputs, weighted (1 each, or
        1 - Fac and Fac), and their emission summed the same way. An Image
        Texture on a Mix's Fac stays a texture where the Mix is of one
        surface each side (else its value is used)."""
        sources = [_linked_node(s) for s in node.inputs if s.type == "SHADER"]
        sides = [self._shader(name, source) if source is not None else Surface() for source in sources]
        if any(side.fac for side in sides):
            self._warn(f"material '{name}': a textured Mix Fac inside {node.name} is not supported; used its value")
        if node.bl_idname == "ShaderNodeAddShader":
            return _weighted(sides, [1.0, 1.0])
        value = self._texture_value(name, node.inputs["Fac"], "mix")
        fac = float(np.clip(value["mix"], 0.0, 1.0))
        surface = _weighted(sides, [1.0 - fac, fac])
        if "mix_texture" not in value:
            return surface
        if not all(len(side.leaves) == 1 for side in sides):
            self._warn(f"material '{name}': the texture on {node.name} > Fac mixes more than two surfaces; "
                       "used its value")
            return surface
        if any(side.emission.any() for side in sides):
            self._warn(f"material '{name}': emission under the texture on {node.name} > Fac uses the Fac's value")
        # the texture picks between the two surfaces, each keeping its own weight
        texture = {"mix_texture": value["mix_texture"], "mix_channel": value["mix_channel"], "mix_stop": 1.0 - fac}
        return Surface([side.leaves[0] for side in sides], surface.emission, texture)

    # -- sockets --------------------------------------------------------------

    def _color(self, name: str, socket) -> dict:
        """Row fields of a colour socket: an Image Texture on it becomes the
        row's texture over a white base; any other link its default value."""
        source = _linked_node(socket)
        if source is not None and source.bl_idname == "ShaderNodeTexImage":
            texture = self._texture(name, source)
            if texture >= 0:
                return {"base_color": (1.0, 1.0, 1.0), "texture_id": texture}
            return {"base_color": tuple(float(c) for c in socket.default_value[:3])}
        return {"base_color": tuple(self._color_value(name, socket))}

    def _texture_value(self, name: str, socket, key: str) -> dict:
        """Row fields of a value socket (``key``: roughness or metallic): an
        Image Texture on it, directly (its Color as luminance, or its Alpha)
        or through a Separate Color node (one channel), becomes the row's
        ``key``_texture and ``key``_channel; anything else its value."""
        node, output = _link_source(socket)
        channel = None
        if node is not None and node.bl_idname in _SEPARATE_NODES and output is not None:
            channel = _SEPARATE_CHANNELS.get(output.name)
            if node.bl_idname == "ShaderNodeSeparateColor" and node.mode != "RGB":
                channel = None
            node, output = _link_source(node.inputs[0]) if channel is not None else (None, None)
        if node is not None and node.bl_idname == "ShaderNodeTexImage" and output is not None:
            if output.name == "Alpha":
                channel = 3 if channel is None else None
            elif channel is None:
                channel = TEXTURE_LUMINANCE
            texture = self._texture(name, node) if channel is not None else -1
            if texture >= 0:
                return {key: float(socket.default_value), f"{key}_texture": texture, f"{key}_channel": channel}
        return {key: self._value(name, socket)}

    def _normal(self, name: str, node) -> dict:
        """Row fields of a shader's Normal input: a Normal Map node in
        tangent space with an Image Texture on its Color becomes the row's
        normal map; other links are named in the warnings."""
        socket = node.inputs.get("Normal")
        if socket is None or not socket.is_linked:
            return {}
        source = _linked_node(socket)
        if source is None:
            return {}
        if source.bl_idname != "ShaderNodeNormalMap":
            self._warn(f"material '{name}': '{source.bl_idname}' on {node.name} > Normal is not supported; "
                       "used the smooth normal")
            return {}
        if source.space != "TANGENT":
            self._warn(f"material '{name}': {source.name} in {source.space.lower()} space is not supported; "
                       "used the smooth normal")
            return {}
        if source.uv_map:
            self._warn(f"material '{name}': {source.name} names the UV map '{source.uv_map}'; used the active one")
        image = _linked_node(source.inputs["Color"])
        if image is None or image.bl_idname != "ShaderNodeTexImage":
            if source.inputs["Color"].is_linked:
                self._warn_link(name, source.inputs["Color"])
            return {}
        texture = self._texture(name, image)
        if texture < 0:
            return {}
        return {"normal_texture": texture, "normal_strength": self._value(name, source.inputs["Strength"])}

    def _color_value(self, name: str, socket) -> list[float]:
        if socket.is_linked:
            self._warn_link(name, socket)
        return [float(c) for c in socket.default_value[:3]]

    def _value(self, name: str, socket) -> float:
        if socket.is_linked:
            self._warn_link(name, socket)
        return float(socket.default_value)

    def _warn_link(self, name: str, socket) -> None:
        source = socket.links[0].from_node.bl_idname if socket.links else "a link"
        self._warn(f"material '{name}': '{source}' on {socket.node.name} > {socket.name} is not supported; used its value")

    def _texture(self, name: str, node) -> int:
        """Index of the node's image, filtered as the node says (Closest or
        Linear), in the texture list; -1 if it has no pixels."""
        image = node.image.original if node.image is not None else None  # pixels live on the original
        if image is None:
            self._warn(f"material '{name}': {node.name} has no image; used the socket's colour")
            return -1
        if node.inputs["Vector"].is_linked:
            self._warn(f"material '{name}': texture coordinates on {node.name} are not supported; used the UV map")
        if node.interpolation not in ("Linear", "Closest"):
            self._warn(f"material '{name}': {node.interpolation} interpolation on {node.name} is not supported; "
                       "used Linear")
        if node.extension != "REPEAT":
            self._warn(f"material '{name}': the {node.extension.lower()} extension on {node.name} is not supported; "
                       "used Repeat")
        closest = node.interpolation == "Closest"
        key = (image.name_full, closest)
        if key not in self._images:
            if image.name_full not in self._pixels:
                self._pixels[image.name_full] = image_pixels(image)
            pixels = self._pixels[image.name_full]
            if pixels is None:
                self._warn(f"material '{name}': image '{image.name}' has no pixels (missing file?); used the socket's colour")
                return -1
            self._images[key] = len(self.textures)
            self.textures.append(pixels)
            self.texture_closest.append(closest)
        return self._images[key]


def _weighted(sides: list[Surface], weights: list[float]) -> Surface:
    """The sum of ``sides`` times ``weights``: their surfaces of weight
    above 0, and their emission."""
    leaves = [(w * weight, row) for side, weight in zip(sides, weights) for w, row in side.leaves if w * weight > 0.0]
    return Surface(leaves, sum((side.emission * weight for side, weight in zip(sides, weights)), np.zeros(3)))


def _mix_rows(name: str, surface: Surface) -> list[dict]:
    """The rows of a material's surface: one per surface of a mix, each
    with the chance of picking it once the rows before it were passed
    (mix_stop) and its weight over its chance (mix_scale), all with the
    mix's emission; none but emission gives a black surface."""
    emission = tuple(float(c) for c in surface.emission)
    leaves = surface.leaves or [(1.0, {"base_color": BLACK})]
    if surface.fac is not None:
        # the Fac texture gives the chances; each surface keeps its own weight
        (w0, first), (w1, second) = leaves
        return [{**first, **surface.fac, "mix_scale": w0, "emission": emission, "name": name},
                {**second, "mix_scale": w1, "emission": emission, "name": f"{name} (2)"}]
    total = sum(weight for weight, _ in leaves)
    rows, left = [], 1.0
    for i, (weight, row) in enumerate(leaves):
        chance = weight / total
        stop = 1.0 if i == len(leaves) - 1 else min(chance / max(left, 1e-12), 1.0)
        left -= chance
        rows.append({**row, "mix_stop": stop, "mix_scale": total, "emission": emission,
                     "name": name if i == 0 else f"{name} ({i + 1})"})
    return rows


def image_pixels(image) -> np.ndarray | None:
    """(H, W, 4) float32 linear pixels of a Blender image, or None without pixels.

    Byte images in an sRGB colour space are converted to linear; float images
    are already linear in Blender.
    """
    width, height = image.size
    channels = image.channels
    if width == 0 or height == 0 or channels == 0:
        return None
    buf = np.empty(width * height * channels, np.float32)
    try:
        image.pixels.foreach_get(buf)
    except (RuntimeError, ValueError):
        return None
    pixels = buf.reshape(height, width, channels)
    if channels != 4:
        rgba = np.ones((height, width, 4), np.float32)
        rgba[..., :3] = pixels[..., :1] if channels < 3 else pixels[..., :3]
        if channels == 2:
            rgba[..., 3] = pixels[..., 1]
        pixels = rgba
    if not image.is_float and image.colorspace_settings.name in _SRGB_SPACES:
        rgb = pixels[..., :3]
        pixels[..., :3] = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return pixels


def _output_node(tree):
    """The active Material Output node used by Cycles, if any."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target in ("ALL", "CYCLES")]
    for node in outputs:
        if node.is_active_output:
            return node
    return outputs[0] if outputs else None


def _linked_node(socket):
    """The node feeding ``socket``, through reroutes and muted links; None if unlinked."""
    return _link_source(socket)[0]


def _link_source(socket):
    """(node, output socket) feeding ``socket``, through reroutes; (None,
    None) if unlinked, muted or invalid."""
    seen = 0
    while socket.is_linked and seen < 64:
        link = socket.links[0]
        if link.is_muted or not link.is_valid:
            return None, None
        node = link.from_node
        if node.bl_idname != "NodeReroute":
            return (None, None) if node.mute else (node, link.from_socket)
        socket = node.inputs[0]
        seen += 1
    return None, None
