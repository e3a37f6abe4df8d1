"""Blender materials (Cycles node trees) to gpu_core material rows.

Supported: Principled BSDF, Diffuse, Glossy, Glass and Emission shaders
(also inside an Add/Mix Shader, where the first supported input wins) and
an Image Texture on Base Color / Color. Anything else falls back to a
default and is named in the warnings.
"""

from __future__ import annotations

import numpy as np

DEFAULT_ROW = {"base_color": (0.8, 0.8, 0.8), "roughness": 0.5, "name": "default"}


class MaterialTable:
    """Material rows and textures, one row per distinct Blender material."""

    def __init__(self):
        self.rows: list[dict] = [dict(DEFAULT_ROW)]
        self.textures: list[np.ndarray] = []
        self.warnings: list[str] = []
        self._index: dict = {None: 0}
        self._images: dict = {}

    def index(self, material) -> int:
        """Row of ``material`` (None = the default row), exported on first use."""
        key = material.original.name_full if material is not None else None
        if key not in self._index:
            self._index[key] = len(self.rows)
            self.rows.append(self._export(material))
        return self._index[key]

    def _warn(self, message: str) -> None:
        if message not in self.warnings:
            self.warnings.append(message)

    def _export(self, material) -> dict:
        mat = material.original
        row = {"name": mat.name}
        if not mat.use_nodes or mat.node_tree is None:
            row["base_color"] = tuple(mat.diffuse_color[:3])
            row["metallic"] = float(mat.metallic)
            row["roughness"] = float(mat.roughness)
            return row
        output = _output_node(mat.node_tree)
        if output is None or not output.inputs["Surface"].is_linked:
            self._warn(f"material '{mat.name}': no surface output; used the default material")
            return {**DEFAULT_ROW, "name": mat.name}
        shader = output.inputs["Surface"].links[0].from_node
        return {**row, **self._shader(mat.name, shader)}

    def _shader(self, name: str, node) -> dict:
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfPrincipled":
            row = {
                **self._color(name, node.inputs["Base Color"]),
                "metallic": _value(node.inputs["Metallic"]),
                "roughness": _value(node.inputs["Roughness"]),
                "transmission": _value(node.inputs["Transmission Weight"]),
                "ior": _value(node.inputs["IOR"]),
                "alpha": _value(node.inputs["Alpha"]),
            }
            strength = _value(node.inputs["Emission Strength"])
            emission = np.asarray(_color_value(node.inputs["Emission Color"])) * strength
            row["emission"] = tuple(float(c) for c in emission)
            return row
        if kind == "ShaderNodeBsdfDiffuse":
            return {**self._color(name, node.inputs["Color"]), "roughness": 1.0}
        if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            return {**self._color(name, node.inputs["Color"]), "metallic": 1.0,
                    "roughness": _value(node.inputs["Roughness"])}
        if kind == "ShaderNodeBsdfGlass":
            return {**self._color(name, node.inputs["Color"]), "transmission": 1.0,
                    "roughness": _value(node.inputs["Roughness"]), "ior": _value(node.inputs["IOR"])}
        if kind == "ShaderNodeEmission":
            color = np.asarray(_color_value(node.inputs["Color"])) * _value(node.inputs["Strength"])
            return {"base_color": (0.0, 0.0, 0.0), "emission": tuple(float(c) for c in color)}
        if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
            for socket in node.inputs:
                if socket.type == "SHADER" and socket.is_linked:
                    self._warn(f"material '{name}': {node.name} reduced to its first shader")
                    return self._shader(name, socket.links[0].from_node)
        self._warn(f"material '{name}': shader node '{node.bl_idname}' is not supported; used the default material")
        return {k: v for k, v in DEFAULT_ROW.items() if k != "name"}

    def _color(self, name: str, socket) -> dict:
        """Row fields for a colour socket: an Image Texture link becomes the
        row's texture (white base), anything else linked its default value."""
        if socket.is_linked:
            source = socket.links[0].from_node
            if source.bl_idname == "ShaderNodeTexImage" and source.image is not None:
                texture = self._texture(name, source.image)
                if texture >= 0:
                    return {"base_color": (1.0, 1.0, 1.0), "texture_id": texture}
            else:
                self._warn(f"material '{name}': '{source.bl_idname}' on {socket.name} is not supported; used its default value")
        return {"base_color": tuple(_color_value(socket))}

    def _texture(self, name: str, image) -> int:
        key = image.name_full
        if key not in self._images:
            pixels = image_pixels(image)
            if pixels is None:
                self._warn(f"material '{name}': image '{image.name}' has no pixels; ignored")
                return -1
            self._images[key] = len(self.textures)
            self.textures.append(pixels)
        return self._images[key]


def image_pixels(image) -> np.ndarray | None:
    """(H, W, 4) float32 linear pixels of a Blender image, or None."""
    width, height = image.size
    if width == 0 or height == 0:
        return None
    buf = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(buf)
    pixels = buf.reshape(height, width, 4)
    if not image.is_float and image.colorspace_settings.name in ("sRGB", "sRGB EOTF"):
        rgb = pixels[..., :3]
        pixels[..., :3] = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return pixels


def _output_node(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for node in outputs:
        if node.is_active_output and node.target in ("ALL", "CYCLES"):
            return node
    return outputs[0] if outputs else None


def _value(socket) -> float:
    return float(socket.default_value)


def _color_value(socket) -> list:
    return [float(c) for c in socket.default_value[:3]]
