"""The world's Background colour x strength as a uniform radiance."""

from __future__ import annotations

import numpy as np


def world_radiance(world, warnings: list[str]) -> np.ndarray:
    """RGB radiance of the world; unsupported links fall back to their default value."""
    if world is None:
        return np.zeros(3, np.float32)
    if not world.use_nodes or world.node_tree is None:
        return np.asarray(world.color[:3], np.float32)
    tree = world.node_tree
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    if output is None or not output.inputs["Surface"].is_linked:
        return np.zeros(3, np.float32)
    node = output.inputs["Surface"].links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        warnings.append(f"world: '{node.bl_idname}' is not supported; the world is black")
        return np.zeros(3, np.float32)
    color_socket = node.inputs["Color"]
    if color_socket.is_linked:
        warnings.append(f"world: '{color_socket.links[0].from_node.bl_idname}' on Color is not supported; used its default colour")
    color = np.asarray(color_socket.default_value[:3], np.float32)
    return color * np.float32(node.inputs["Strength"].default_value)
