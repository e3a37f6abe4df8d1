"""The world's Background colour x strength as a uniform radiance."""

from __future__ import annotations

import numpy as np

BLACK = np.zeros(3, np.float32)


def world_radiance(world, warnings: list[str]) -> np.ndarray:
    """RGB radiance of the world seen by escaped rays.

    A Background shader's Color x Strength; a world without a node tree uses
    its colour, as Cycles does. Anything linked into the Background falls
    back to the socket's own value and is named in ``warnings``.
    """
    if world is None:
        return BLACK.copy()
    tree = world.node_tree
    if tree is None:
        return np.array(world.color[:3], np.float32)
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld" and n.target in ("ALL", "CYCLES")]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    surface = output.inputs["Surface"] if output is not None else None
    if surface is None or not surface.is_linked:
        return BLACK.copy()
    node = surface.links[0].from_node
    if node.bl_idname not in ("ShaderNodeBackground", "ShaderNodeEmission"):
        warnings.append(f"world: shader '{node.bl_idname}' is not supported; the world is black")
        return BLACK.copy()
    color, strength = node.inputs["Color"], node.inputs["Strength"]
    for socket in (color, strength):
        if socket.is_linked:
            source = socket.links[0].from_node.bl_idname
            warnings.append(f"world: '{source}' on Background > {socket.name} is not supported; used its value")
    return np.array(color.default_value[:3], np.float32) * np.float32(strength.default_value)
