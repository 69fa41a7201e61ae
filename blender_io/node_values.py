"""Evaluating the node chain behind one Principled BSDF input as pixels, the way Blender would.

Handles what real assets carry, in particular what Blender's glTF importer builds:
Image Texture (Color or Alpha, default UVs or the mesh's UV map), Separate Color / Separate RGB
(one channel, e.g. glTF's packed G = roughness, B = metallic), factors as Math Multiply or Mix
Multiply nodes, and Reroutes. Anything else raises `NotAnImageChain`, and the caller bakes the
chain with Cycles instead. Every step is written down in `trail` for the report. Steps on pixels are `later` steps
(core/data/map_plan.py): where `pixels_of` gives a file still to decode, they run in the job.
"""
from __future__ import annotations

import numpy as np

from ..core.base.errors import InputError
from ..core.data.map_plan import is_pending, later
from ..core.data.map_steps import Value

_CHANNELS = {"Red": 0, "Green": 1, "Blue": 2, "R": 0, "G": 1, "B": 2}


class NotAnImageChain(Exception):
    """The chain holds a node that is not a plain image lookup (procedural, vertex colour, ...)."""

    def __init__(self, node) -> None:
        super().__init__(f"node '{node.name}' ({node.bl_idname})")
        self.node = node


def source(socket):
    """(node, output socket) linked into `socket`, past Reroutes; None when unlinked."""
    if not socket.is_linked:
        return None
    link = socket.links[0]
    while link.from_node.type == "REROUTE":
        if not link.from_node.inputs[0].is_linked:
            return None
        link = link.from_node.inputs[0].links[0]
    return link.from_node, link.from_socket


def socket_value(socket, kind: str, trail: list[str], pixels_of) -> Value:
    """The value of an input socket as `kind` ("float" or "color"), evaluated through its chain.

    pixels_of(image) -> (H, W, 4) linear float pixels, rows top to bottom, or a Source giving them later.
    """
    linked = source(socket)
    if linked is None:
        value = socket.default_value
        if kind == "color":
            if isinstance(value, float):
                return np.full(3, value, np.float32)
            return np.array(value[:3], dtype=np.float32)
        return float(value)
    node, output = linked
    return later("convert", _node_value(node, output, trail, pixels_of), kind)


def _uses_default_uvs(node) -> bool:
    vector = source(node.inputs["Vector"])
    if vector is None:
        return True
    from_node, output = vector
    if from_node.type == "UVMAP":
        return True  # SceneFit reads the mesh's active UV map; the report names the node
    if _moves_nothing(from_node):
        return _uses_default_uvs(from_node)
    return from_node.type == "TEX_COORD" and output.name == "UV"


def _moves_nothing(node) -> bool:
    """A Mapping node that leaves UVs as they are: Blender's glTF importer adds one for a
    KHR_texture_transform that only names the UV set (UnityGLTF writes it on every texture)."""
    if node.type != "MAPPING" or node.vector_type not in ("POINT", "TEXTURE", "VECTOR"):
        return False
    neutral = {"Location": 0.0, "Rotation": 0.0, "Scale": 1.0}
    return all(not node.inputs[name].is_linked and np.allclose(node.inputs[name].default_value, value)
               for name, value in neutral.items() if name in node.inputs)


def _node_value(node, output, trail: list[str], pixels_of) -> Value:
    kind = node.type
    if kind == "TEX_IMAGE":
        if node.image is None:
            raise InputError(f"The Image Texture node '{node.name}' has no image.")
        if not _uses_default_uvs(node):
            raise NotAnImageChain(source(node.inputs["Vector"])[0])
        pixels = pixels_of(node.image)
        trail.append(f"image '{node.image.name}' {output.name} (node '{node.name}', "
                     f"{node.image.colorspace_settings.name})")
        return later("alpha" if output.name == "Alpha" else "colour", pixels)
    if kind in ("SEPARATE_COLOR", "SEPRGB"):
        if kind == "SEPARATE_COLOR" and node.mode != "RGB":
            raise NotAnImageChain(node)
        color = socket_value(node.inputs[0], "color", trail, pixels_of)
        channel = _CHANNELS[output.name]
        trail.append(f"channel {'RGB'[channel]} via {node.bl_label} '{node.name}'")
        return later("channel", color, channel)
    if kind == "MATH" and node.operation == "MULTIPLY":
        a = socket_value(node.inputs[0], "float", trail, pixels_of)
        b = socket_value(node.inputs[1], "float", trail, pixels_of)
        _note_factor(trail, node, a, b)
        return later("clamp", node.use_clamp, later("product", a, b))
    if kind == "MIX" and node.blend_type == "MULTIPLY" and node.data_type in ("RGBA", "FLOAT"):
        return _mix_multiply(node, node.data_type, trail, pixels_of)
    if kind == "MIX_RGB" and node.blend_type == "MULTIPLY":
        return _mix_multiply(node, "LEGACY", trail, pixels_of)
    raise NotAnImageChain(node)


def _mix_multiply(node, data_type: str, trail: list[str], pixels_of) -> Value:
    factor_socket = node.inputs[0]
    if factor_socket.is_linked:
        raise NotAnImageChain(node)
    factor = float(factor_socket.default_value)
    if data_type == "RGBA":
        a_socket, b_socket, kind = node.inputs[6], node.inputs[7], "color"
    elif data_type == "FLOAT":
        a_socket, b_socket, kind = node.inputs[2], node.inputs[3], "float"
    else:
        a_socket, b_socket, kind = node.inputs[1], node.inputs[2], "color"
    a = socket_value(a_socket, kind, trail, pixels_of)
    b = socket_value(b_socket, kind, trail, pixels_of)
    _note_factor(trail, node, a, b)
    clamp = getattr(node, "clamp_result", False) or getattr(node, "use_clamp", False)
    return later("clamp", clamp, later("mixed", a, b, factor))


def _note_factor(trail: list[str], node, a: Value, b: Value) -> None:
    constants = [v for v in (a, b) if not is_pending(v) and not (isinstance(v, np.ndarray) and v.ndim >= 2)]
    if constants:
        shown = ", ".join(f"{x:.4g}" for x in np.ravel(constants[0])[:3])
        trail.append(f"times factor ({shown}) from '{node.label or node.name}'")
