"""Blender material <-> core.maps.PBRMaps."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..core.base.errors import InputError
from ..core.data.imageio import check_decodes, srgb_to_linear
from ..core.data.map_plan import FILE_MAGIC, CheckedPixels, PendingAsset, PendingMaterial, TextureFile, later
from ..core.data.maps import PBRMaps
from ..core.data.materials import AssetMaterials, Material
from ..core.data.mesh import Mesh
from ..core.base.quiet import native_output_captured
from .mesh import mesh_from_object
from .node_values import NotAnImageChain, socket_value, source
from .procedural_bake import SocketBake
from .unlit import unlit_surface

# Colour spaces whose 8-bit pixels are stored as-is (no transfer function to undo).
_LINEAR_SPACES = {"Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear CIE-XYZ E", "Linear FilmLight E-Gamut",
                  "Linear Rec.2020", "ACEScg", "ACES2065-1"}


def principled_bsdf(material):
    """The Principled BSDF that feeds the material output (or the only one there is); for an unlit
    material (KHR_materials_unlit, no Principled BSDF) a stand-in with its colour as Base Color."""
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
    if not candidates and (unlit := unlit_surface(tree)) is not None:
        return unlit  # KHR_materials_unlit: Base Color is the emission colour (see blender_io.unlit)
    if not candidates:
        raise InputError(f"Material '{material.name}' has no Principled BSDF node; SceneFit reads its "
                         "Base Color, Roughness and Metallic inputs.")
    return candidates[0]


def image_pixels_linear(image, decode_srgb: bool = True) -> np.ndarray:
    """(H, W, 4) float32, rows top to bottom, colour channels decoded to linear, read through Blender
    here (its stored file checked first).

    Blender keeps float images linear; 8-bit images are exposed as stored, so their transfer
    function is undone here from the image's colour space (sRGB, or none for Non-Color).
    """
    check_stored_image(image)
    return _held_pixels(image, decode_srgb)


# Colour spaces whose 8-bit files Blender keeps as stored bytes (a file the job decodes gives the same pixels).
_JOB_SPACES = {"sRGB", "Non-Color"}


def pixels_source(image, decode_srgb: bool = True):
    """What a job decodes for `image`: its 8-bit PNG or JPEG file (or packed bytes) when Blender's reader
    would give the stored values, else a copy of the pixels Blender holds (edited, generated, float, other
    formats; a copy is fast once loaded), its stored file checked in the job."""
    space = image.colorspace_settings.name
    stored = _stored_bytes(image)
    if stored is not None and space in _JOB_SPACES and _eight_bit(stored[1]) \
            and getattr(image, "alpha_mode", "STRAIGHT") in ("STRAIGHT", "CHANNEL_PACKED"):
        where, _ = stored
        decode = decode_srgb and space not in _LINEAR_SPACES
        if isinstance(where, bytes):
            return TextureFile(image.name, packed=where, decode_srgb=decode)
        return TextureFile(where, path=where, decode_srgb=decode)
    return CheckedPixels(_held_pixels(image, decode_srgb), None if stored is None else stored[0],
                         image.name if stored is None or isinstance(stored[0], bytes) else stored[0])


def _stored_bytes(image) -> tuple[str | bytes, bytes] | None:
    """(the file's path or the packed bytes, their first bytes) of an unedited file image, else None."""
    import bpy

    if image.source != "FILE" or image.is_dirty or len(image.packed_files) > 1:
        return None
    if image.packed_file is not None:
        data = bytes(image.packed_file.data)
        return data, data[:32]
    path = bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""
    if not path or not os.path.isfile(path):
        return None
    with open(path, "rb") as f:
        return path, f.read(32)


def _eight_bit(head: bytes) -> bool:
    """A JPEG, or a PNG of 8 bits per sample (a palette's too): what the job decodes as Blender does."""
    kind = next((s for m, s in FILE_MAGIC.items() if head.startswith(m)), None)
    if kind == ".png":
        return len(head) > 24 and head[12:16] == b"IHDR" and head[24] == 8
    return kind == ".jpg"


def _held_pixels(image, decode_srgb: bool = True) -> np.ndarray:
    """The pixels Blender holds for `image` (loading its file first if it has not yet)."""
    with native_output_captured():   # libjpeg's and libpng's warnings would go straight to the terminal
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
    if decode_srgb and not image.is_float and space not in _LINEAR_SPACES:
        pixels[..., :3] = srgb_to_linear(pixels[..., :3])
    return pixels


def check_stored_image(image) -> None:
    """Refuse a JPEG or PNG texture whose file (or the bytes packed into the .blend/.glb) does not
    decode whole: Blender shows a truncated JPEG with its missing rows grey and says nothing."""
    import bpy

    if image.source != "FILE":
        return
    if image.packed_file is not None:
        check_decodes(bytes(image.packed_file.data), image.name)   # packed: Blender's name for it
    elif image.filepath:
        path = bpy.path.abspath(image.filepath, library=image.library)
        if os.path.isfile(path):   # a file gone since Blender loaded it: its pixels are what Blender holds
            check_decodes(path, path)


# Principled inputs the neural texture does not model: reported when they change the look.
_UNMODELLED = (("Coat Weight", 0.0), ("Sheen Weight", 0.0), ("Transmission Weight", 0.0),
               ("Subsurface Weight", 0.0), ("Anisotropic", 0.0), ("Specular IOR Level", 0.5))
# Where the glTF importer/exporter keep occlusion: a node group of this name with an Occlusion input.
_GLTF_SETTINGS_GROUPS = ("glTF Material Output", "glTF Settings")
# Size of images baked from procedural chains when the material has no image to take the size from.
PROCEDURAL_BAKE_SIZE = 512


class _Reading:
    """How one material's pixels are reached: `pixels_of` (decoded in the job, or read here) and the
    procedural chains' bakes, owed by the main thread (`bakes`), with the material's bake size."""

    def __init__(self, material, obj, slot: int, pixels_of, bakes: list, bake_limit: int | None = None) -> None:
        self.material, self.obj, self.slot, self.pixels_of, self.bakes = material, obj, slot, pixels_of, bakes
        self.bake_limit = bake_limit
        self._size: int | None = None

    @property
    def bake_size(self) -> int:
        if self._size is None:
            self._size = _image_size(self.material)   # (loads the images: only where a chain is baked)
        return self._size if self.bake_limit is None else min(self._size, self.bake_limit)


def _read_input(bsdf, name: str, kind: str, reading: _Reading, read: list[str],
                wrap: tuple[str, str] = ("repeat", "repeat")):
    """The input's value through its node chain; a procedural chain is baked with Cycles (over UVs
    outside [0, 1] too, wrapped as `wrap` says) by the main thread before the job resolves it."""
    trail: list[str] = []
    try:
        value = socket_value(bsdf.inputs[name], kind, trail, reading.pixels_of)
    except NotAnImageChain as why:
        size = reading.bake_size
        bake = SocketBake(reading.obj, reading.slot, bsdf.inputs[name], size, wrap, reading.material, _held_pixels)
        reading.bakes.append(bake)
        read.append(f"{name} <- procedural setup ({why}) baked by Cycles to {size}² "
                    f"(Blender's bake, emission pass)")
        return later("baked", bake, kind)
    if trail:
        read.append(f"{name} <- " + ", ".join(reversed(trail)))
    else:
        shown = ", ".join(f"{x:.4g}" for x in np.ravel(value))
        read.append(f"{name} <- constant {shown}")
    return later("clipped", value)


# Blender's Image Texture extension -> how glTF's exporter writes the sampler (core.data.uv_raster.WRAP_MODES).
_WRAP_OF_EXTENSION = {"REPEAT": "repeat", "MIRROR": "mirror", "EXTEND": "clamp", "CLIP": "clamp"}
EXTENSION_OF_WRAP = {"repeat": "REPEAT", "mirror": "MIRROR", "clamp": "EXTEND"}


def _chain_images(socket) -> list:
    """The Image Texture nodes in the chain behind `socket`, nearest first (their own UV inputs aside)."""
    found, queue, seen = [], [socket], set()
    while queue:
        linked = source(queue.pop(0))
        if linked is None or linked[0].name in seen:
            continue
        node = linked[0]
        seen.add(node.name)
        if node.type == "TEX_IMAGE":
            found.append(node)
        else:
            queue.extend(s for s in node.inputs if s.is_linked)
    return found


def _chain_nodes(socket) -> list:
    """Every node in the chain behind `socket`."""
    found, queue, seen = [], [socket], set()
    while queue:
        linked = source(queue.pop(0))
        if linked is None or linked[0].name in seen:
            continue
        seen.add(linked[0].name)
        found.append(linked[0])
        queue.extend(s for s in linked[0].inputs if s.is_linked)
    return found


def reads_vertex_colours(material) -> bool:
    """Whether the material's Base Color reads the mesh's colour attribute (glTF's COLOR_0, as Blender's
    importer links it through a Color Attribute node)."""
    try:
        bsdf = principled_bsdf(material)
    except InputError:
        return False
    socket = bsdf.inputs.get("Base Color")
    return socket is not None and any(n.type in ("VERTEX_COLOR", "ATTRIBUTE") for n in _chain_nodes(socket))


def unwrap_vertex_coloured(objects: list) -> list[str]:
    """A UV map (Smart UV Project, blender_io.uv_unwrap) for each of `objects` that has none and whose
    materials read its vertex colours: their colours, baked through it (each corner's colour, as the
    triangle interpolates them), become the material's base colour image, which a mesh without UVs could
    not hold. Only for objects loaded into SceneFit's own temporary scene (the command line, batch jobs):
    the artist's meshes are never changed. Returns what was done, for the report."""
    from .uv_unwrap import new_uv_map_active

    needing = [obj for obj in objects if obj.type == "MESH" and obj.data.uv_layers.active is None and
               any(slot.material is not None and reads_vertex_colours(slot.material) for slot in obj.material_slots)]
    if not needing:
        return []
    materials = list({slot.material.name: slot.material for obj in needing for slot in obj.material_slots
                      if slot.material is not None}.values())
    with new_uv_map_active(needing, materials):
        pass   # (a mesh that had no UV map keeps the new one as its only one)
    return [f"'{obj.name}' has no UV map and its material reads its vertex colours: unwrapped (Smart UV Project) "
            "so its colours bake into a base colour image" for obj in needing]


def material_wrap(material, dropped: list[str] | None = None) -> tuple[str, str]:
    """How the material's UVs outside [0, 1] read its maps, (u, v): the extension of the image behind
    Base Color (else Roughness, else Metallic), as Blender's glTF importer sets it from the sampler
    (REPEAT, MIRRORED_REPEAT, CLAMP_TO_EDGE); repeat without an image. Another image of these
    inputs that wraps otherwise is noted in `dropped`."""
    bsdf = principled_bsdf(material)
    images = [n for name in ("Base Color", "Roughness", "Metallic") for n in _chain_images(bsdf.inputs[name])]
    if not images:
        return "repeat", "repeat"
    mode = _WRAP_OF_EXTENSION.get(images[0].extension, "repeat")
    others = sorted({n.image.name for n in images if _WRAP_OF_EXTENSION.get(n.extension, "repeat") != mode
                     and n.image is not None})
    if others and dropped is not None:
        dropped.append(f"images {', '.join(others)} wrap otherwise than '{images[0].name}' ({mode}); SceneFit fits "
                       f"and bakes the material's UVs outside [0, 1] as {mode}")
    return mode, mode


def _image_size(material) -> int:
    with native_output_captured():   # the first .size loads the file (see image_pixels_linear)
        sizes = [max(n.image.size) for n in material.node_tree.nodes
                 if n.type == "TEX_IMAGE" and n.image is not None and max(n.image.size) > 0]
    return max(sizes) if sizes else PROCEDURAL_BAKE_SIZE


def _normal_map(bsdf, material, kept: list[str], dropped: list[str], pixels_of):
    """The tangent-space normal map behind Normal, with the node's strength applied, or None."""
    linked = source(bsdf.inputs["Normal"])
    if linked is None:
        return None
    node = linked[0]
    if node.type != "NORMAL_MAP":
        dropped.append(f"Normal <- '{node.name}' ({node.bl_idname}): only a Normal Map node with an image is "
                       "used in renders; the node stays in the material for export")
        return None
    color = source(node.inputs["Color"])
    if color is None:
        return None  # an unlinked Normal Map node (the FBX importer adds one) leaves the normal as it is
    if node.space != "TANGENT" or color[0].type != "TEX_IMAGE" or color[0].image is None:
        dropped.append(f"Normal Map '{node.name}' ({node.space.lower()} space, not an image in tangent space) is "
                       "not used in renders; it stays in the material for export")
        return None
    image = color[0].image
    stored = pixels_of(image, decode_srgb=False)
    is_float = False if isinstance(stored, TextureFile) else image.is_float   # (an 8-bit file: never float)
    if image.colorspace_settings.name not in _LINEAR_SPACES and not is_float:
        dropped.append(f"normal map image '{image.name}' is tagged {image.colorspace_settings.name}; its bytes are "
                       "read as Non-Color data, as Blender's glTF importer tags normal maps")
    strength = float(node.inputs["Strength"].default_value)
    kept.append(f"normal map <- image '{image.name}' via Normal Map '{node.name}' (tangent space, strength "
                f"{strength:.3g}): used in renders, kept for export")
    return later("normal_at_strength", stored, strength)


def alpha_mode(material, bsdf) -> str:
    """glTF's alpha mode as Blender's glTF exporter would write it for this material."""
    if getattr(material, "surface_render_method", "DITHERED") == "BLENDED":
        return "BLEND"
    alpha = bsdf.inputs["Alpha"]
    linked = source(alpha)
    if linked is None:
        return "OPAQUE" if alpha.default_value >= 1.0 else "BLEND"
    node = linked[0]
    if node.type == "MATH" and node.operation in ("SUBTRACT", "ROUND", "GREATER_THAN", "LESS_THAN"):
        return "MASK"
    return "BLEND"


def _carried(material, bsdf, kept: list[str], dropped: list[str]) -> str:
    """Alpha, emission and occlusion: not fitted, carried unchanged into game export. Returns the alpha mode."""
    name = material.name
    mode = alpha_mode(material, bsdf)
    alpha = source(bsdf.inputs["Alpha"])
    if mode != "OPAQUE":
        where = f"'{alpha[0].name}' {alpha[1].name}" if alpha else f"constant {bsdf.inputs['Alpha'].default_value:.3g}"
        kept.append(f"alpha ({mode}) <- {where}: carried unchanged into export; renders are opaque")
    strength = bsdf.inputs["Emission Strength"]
    color = bsdf.inputs["Emission Color"]
    emits = color.is_linked or strength.is_linked or (
        strength.default_value > 0 and max(color.default_value[:3]) > 0)
    if emits:
        what = f"'{source(color)[0].name}'" if color.is_linked else \
            "colour (" + ", ".join(f"{x:.3g}" for x in color.default_value[:3]) + ")"
        kept.append(f"emission <- {what} x strength {strength.default_value:.3g}: carried unchanged into export; "
                    "not added to renders")
    for node in material.node_tree.nodes:
        if node.type == "GROUP" and node.node_tree is not None and node.node_tree.name in _GLTF_SETTINGS_GROUPS:
            occlusion = node.inputs.get("Occlusion")
            if occlusion is not None and occlusion.is_linked:
                kept.append(f"occlusion <- '{source(occlusion)[0].name}' (glTF settings group): kept for export")
    for socket_name, neutral in _UNMODELLED:
        socket = bsdf.inputs.get(socket_name)
        if socket is not None and (socket.is_linked or abs(float(socket.default_value) - neutral) > 1e-6):
            dropped.append(f"{socket_name} of '{name}' is not modelled by the neural texture (base colour, "
                           "roughness, metallic); it stays in the material for export")
    return mode


def plan_material(material, obj=None, slot: int = 0, bakes: list | None = None,
                  files_in_job: bool = True, bake_limit: int | None = None) -> PendingMaterial:
    """Everything SceneFit reads from one material, with an account of what it read and dropped, its
    maps still to compute (core/data/map_plan.py): its image files decoded wherever `resolved()` runs, its
    procedural chains' Cycles bakes appended to `bakes` for the main thread to run first.

    Base Color, Roughness and Metallic come from images, constants, one channel of an image
    (Separate Color, as glTF's packed metallic-roughness image) or factors; any other node chain is
    baked with Cycles over the faces of `obj`'s slot `slot`. The material is only read.
    files_in_job=False reads every image through Blender here instead. bake_limit: the largest side a
    chain is baked at (else the material's largest image's).
    """
    bsdf = principled_bsdf(material)
    read: list[str] = []
    kept: list[str] = []
    dropped: list[str] = []
    pixels_of = pixels_source if files_in_job else image_pixels_linear
    reading = _Reading(material, obj, slot, pixels_of, bakes if bakes is not None else [], bake_limit)
    wrap = material_wrap(material, dropped)
    roughness = _read_input(bsdf, "Roughness", "float", reading, read, wrap)
    metallic = _read_input(bsdf, "Metallic", "float", reading, read, wrap)
    base_color = _read_input(bsdf, "Base Color", "color", reading, read, wrap)
    normal = _normal_map(bsdf, material, kept, dropped, pixels_of)
    mode = _carried(material, bsdf, kept, dropped)
    if getattr(bsdf, "unlit", False):
        kept.append(f"unlit (KHR_materials_unlit) <- '{bsdf.name}': its colour is read as base colour, renders "
                    "shade it as a rough dielectric (unlit is not modelled); exported unlit again")
    return PendingMaterial(name=material.name, maps=later("pbr_maps", base_color, roughness, metallic, normal),
                           read=tuple(read), kept=tuple(kept), dropped=tuple(dropped), alpha_mode=mode, wrap=wrap)


def read_material(material, obj=None, slot: int = 0) -> Material:
    """The material's maps read now (its bakes run, its files decoded here): see plan_material."""
    bakes: list = []
    plan = plan_material(material, obj, slot, bakes)
    for bake in bakes:
        bake.run()
    return plan.resolved()


def read_material_within(material, obj, slot: int, limit: int) -> tuple[Material, frozenset[str]]:
    """read_material for a bake that writes at most limit² texels: a procedural chain is baked by Cycles at
    no more than that, not at the material's image size to be averaged down after (ToyCar's fabric: 1024²,
    2 s, for a 256² bake). Also returns the channels ("base_color", "roughness", "metallic") so shrunk:
    the material's own nodes give them larger than the bake, so they are never its unchanged maps."""
    bakes: list = []
    plan = plan_material(material, obj, slot, bakes, bake_limit=limit)
    for bake in bakes:
        bake.run()
    full = _image_size(material) if bakes else 0
    shrunk = frozenset(b.socket_name.lower().replace(" ", "_") for b in bakes if b.size < full)
    return plan.resolved(), shrunk


def plan_asset(mesh, materials: list, users: list[tuple], files_in_job: bool = True) -> PendingAsset:
    """An asset's materials planned (plan_material), each read over its (object, slot) in `users`."""
    bakes: list = []
    planned = tuple(plan_material(m, obj, slot, bakes, files_in_job) for m, (obj, slot) in zip(materials, users))
    return PendingAsset(mesh=mesh, materials=planned, bakes=bakes)


def maps_from_material(material, obj=None, slot: int = 0) -> PBRMaps:
    """Base colour, roughness, metallic (and the normal map) of the material's Principled BSDF.

    Linear float pixels, rows top to bottom; an unlinked input gives its value. A constant base
    colour becomes an image the size of the other maps (or core.data.map_steps.CONSTANT_SIZE square). See read_material.
    """
    return read_material(material, obj, slot).maps


def object_mesh_and_slots(obj, depsgraph, space: str = "object") -> tuple[Mesh, list[int]]:
    """The object's mesh with material_index numbering the slots its faces use (None for one),
    and those slot numbers in order. space "world": with the node's transform (rotation, mirroring,
    scale), as an asset file places it; "object": as the artist's object is, wherever it is moved."""
    mesh = mesh_from_object(obj, depsgraph, space)
    if not obj.material_slots:
        raise InputError(f"Object '{obj.name}' has no material; give it a Principled BSDF with image textures.")
    raw = np.zeros(len(mesh.faces), np.int32) if mesh.material_index is None else mesh.material_index
    used = np.unique(raw)
    for slot in used:
        if slot >= len(obj.material_slots) or obj.material_slots[slot].material is None:
            raise InputError(f"Faces of '{obj.name}' use material slot {slot + 1}, which holds no material.")
    index = np.searchsorted(used, raw).astype(np.int32) if len(used) > 1 else None
    mesh = Mesh.from_arrays(mesh.positions, mesh.faces, mesh.uvs, mesh.normals, mesh.name, index)
    return mesh, [int(s) for s in used]


def read_object_materials(obj, depsgraph, space: str = "object") -> AssetMaterials:
    """The object's mesh (see object_mesh_and_slots for `space`) and every material its faces use
    (slots no face uses are skipped)."""
    mesh, slots = object_mesh_and_slots(obj, depsgraph, space)
    materials = [read_material(obj.material_slots[slot].material, obj, slot) for slot in slots]
    unused = [s.material.name for i, s in enumerate(obj.material_slots) if i not in slots and s.material is not None]
    notes = [f"material slots no face uses were skipped: {', '.join(unused)}"] if unused else []
    return AssetMaterials(mesh=mesh, materials=tuple(materials), notes=tuple(notes))


def _load_image(path: str | os.PathLike, colorspace: str):
    import bpy

    image = bpy.data.images.load(str(Path(path).resolve()), check_existing=False)
    image.colorspace_settings.name = colorspace
    return image


def write_result_material(obj, maps_paths: dict, name: str | None = None, assign: bool = True,
                          wrap: tuple[str, str] | None = None):
    """A new material with image textures for the result maps; returns it.

    maps_paths: {"base_color": path (sRGB image), "roughness": path or float, "metallic": path or float}.
    wrap: how UVs outside [0, 1] read the maps, (u, v), as the material they replace (default repeat).
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
        if wrap is not None and wrap[0] == wrap[1]:
            tex.extension = EXTENSION_OF_WRAP[wrap[0]]
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
