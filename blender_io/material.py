"""Blender material <-> core.maps.PBRMaps."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.imageio import srgb_to_linear
from ..core.maps import PBRMaps

# Size of the base-colour image made when Base Color is a constant but another channel is not.
CONSTANT_SIZE = 256
# Colour spaces whose 8-bit pixels are stored as-is (no transfer function to undo).
_LINEAR_SPACES = {"Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear CIE-XYZ E", "Linear FilmLight E-Gamut",
                  "Linear Rec.2020", "ACEScg", "ACES2065-1"}
_REC709_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def principled_bsdf(material):
    """The Principled BSDF that feeds the material output (or the only one there is)."""
    if material is None:
        raise InputError("The object has no material; give it one with a Principled BSDF.")
    tree = material.node_tree  # Blender 5 materials always have one; 4.x ones may not use nodes
    if tree is None or not getattr(material, "use_nodes", True):
        raise InputError(f"Material '{material.name}' does not use nodes; enable 'Use Nodes' (Principled BSDF).")
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    if output is not None and output.inputs["Surface"].is_linked:
        node = output.inputs["Surface"].links[0].from_node
        if node.type == "BSDF_PRINCIPLED":
            return node
    candidates = [n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"]
    if not candidates:
        raise InputError(f"Material '{material.name}' has no Principled BSDF node; SceneFit reads its "
                         "Base Color, Roughness and Metallic inputs.")
    return candidates[0]


def image_pixels_linear(image) -> np.ndarray:
    """(H, W, 4) float32, rows top to bottom, colour channels decoded to linear.

    Blender keeps float images linear; 8-bit images are exposed as stored, so their transfer
    function is undone here from the image's colour space (sRGB, or none for Non-Color).
    """
    w, h = image.size  # reading the size loads the file
    if w == 0 or h == 0:
        raise InputError(f"Image '{image.name}' cannot be loaded (is '{image.filepath}' missing?).")
    c = image.channels
    pixels = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(h, w, c)[::-1]  # Blender's first row is the bottom one
    if c < 3:
        pixels = np.concatenate([np.repeat(pixels[..., :1], 3, axis=2), pixels[..., 1:2]], axis=2)
    if pixels.shape[2] == 3:
        pixels = np.concatenate([pixels, np.ones((h, w, 1), np.float32)], axis=2)
    pixels = np.ascontiguousarray(pixels)
    space = image.colorspace_settings.name
    if not image.is_float and space not in _LINEAR_SPACES:
        pixels[..., :3] = srgb_to_linear(pixels[..., :3])
    return pixels


def _linked_image(socket, label: str):
    """(image node, output socket name) when `socket` is driven by an Image Texture, else None."""
    if not socket.is_linked:
        return None
    link = socket.links[0]
    node = link.from_node
    while node.type == "REROUTE" and node.inputs[0].is_linked:
        link = node.inputs[0].links[0]
        node = link.from_node
    if node.type != "TEX_IMAGE":
        raise InputError(f"{label} is driven by a '{node.name}' node; SceneFit reads an Image Texture or a "
                         "plain value. Bake the node setup to an image first.")
    if node.image is None:
        raise InputError(f"The Image Texture node '{node.name}' for {label} has no image.")
    return node, link.from_socket.name


def _scalar_map(socket, label: str) -> np.ndarray | float:
    linked = _linked_image(socket, label)
    if linked is None:
        return float(np.clip(socket.default_value, 0.0, 1.0))
    node, output = linked
    pixels = image_pixels_linear(node.image)
    if output == "Alpha":
        return pixels[..., 3].copy()
    rgb = pixels[..., :3]
    if np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2]):
        return rgb[..., 0].copy()
    return (rgb @ _REC709_LUMA).astype(np.float32)  # Blender's colour -> float conversion


def maps_from_material(material) -> PBRMaps:
    """Base colour, roughness and metallic of the material's Principled BSDF.

    An Image Texture linked to an input gives its pixels (linear float, rows top to bottom); an
    unlinked input gives its value. A constant base colour becomes an image the size of the other
    maps (or CONSTANT_SIZE square). The material is only read.
    """
    bsdf = principled_bsdf(material)
    roughness = _scalar_map(bsdf.inputs["Roughness"], f"Roughness of '{material.name}'")
    metallic = _scalar_map(bsdf.inputs["Metallic"], f"Metallic of '{material.name}'")
    linked = _linked_image(bsdf.inputs["Base Color"], f"Base Color of '{material.name}'")
    if linked is not None:
        base_color = image_pixels_linear(linked[0].image)[..., :3].copy()
    else:
        sizes = [m.shape for m in (roughness, metallic) if isinstance(m, np.ndarray)]
        h, w = sizes[0] if sizes else (CONSTANT_SIZE, CONSTANT_SIZE)
        value = np.clip(np.array(bsdf.inputs["Base Color"].default_value[:3], dtype=np.float32), 0.0, 1.0)
        base_color = np.broadcast_to(value, (h, w, 3)).copy()
    return PBRMaps(base_color=base_color.astype(np.float32), roughness=roughness, metallic=metallic)


def _load_image(path: str | os.PathLike, colorspace: str):
    import bpy

    image = bpy.data.images.load(str(Path(path).resolve()), check_existing=False)
    image.colorspace_settings.name = colorspace
    return image


def write_result_material(obj, maps_paths: dict, name: str | None = None, assign: bool = True):
    """A new material with image textures for the result maps; returns it.

    maps_paths: {"base_color": path (sRGB image), "roughness": path or float, "metallic": path or float}.
    Nothing of the user's is modified or deleted: new images are loaded (never reused), and when
    `assign` puts the new material in the object's active slot, the material it replaces gets a
    fake user so it survives saving.
    """
    import bpy

    if "base_color" not in maps_paths:
        raise InputError("No base colour map was produced; nothing to build a material from.")
    mat = bpy.data.materials.new(name or f"{obj.name}_SceneFit")
    if mat.node_tree is None:  # Blender 4.x
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    for row, (key, socket, space) in enumerate((("base_color", "Base Color", "sRGB"),
                                                ("roughness", "Roughness", "Non-Color"),
                                                ("metallic", "Metallic", "Non-Color"))):
        value = maps_paths.get(key)
        if value is None:
            continue
        if isinstance(value, (int, float)):
            bsdf.inputs[socket].default_value = float(value)
            continue
        tex = nodes.new("ShaderNodeTexImage")
        tex.name = tex.label = f"SceneFit {socket}"
        tex.image = _load_image(value, space)
        tex.location = (bsdf.location.x - 400, bsdf.location.y - 300 * row)
        links.new(tex.outputs["Color"], bsdf.inputs[socket])
    if assign:
        if obj.material_slots and obj.active_material is not None:
            obj.active_material.use_fake_user = True
        if obj.material_slots:
            obj.active_material = mat
        else:
            obj.data.materials.append(mat)
    return mat


# Principled BSDF inputs SceneFit reads; every other linked input is left out of its result material.
READ_INPUTS = ("Base Color", "Roughness", "Metallic")


def material_summary(material) -> tuple[list[str], list[str]]:
    """(what SceneFit will read, what it will drop) from the material, without reading any pixels.

    Cheap enough for a panel's draw(): it only looks at the Principled BSDF's links.
    """
    bsdf = principled_bsdf(material)
    found = []
    for name in READ_INPUTS:
        socket = bsdf.inputs[name]
        if socket.is_linked:
            node = socket.links[0].from_node
            image = getattr(node, "image", None)
            found.append(f"{name}: image '{image.name}'" if image is not None else f"{name}: '{node.name}' node")
        else:
            found.append(f"{name}: value")
    dropped = [socket.name for socket in bsdf.inputs if socket.is_linked and socket.name not in READ_INPUTS]
    return found, dropped
