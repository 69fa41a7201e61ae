"""Writing the asset with baked maps as glTF 2.0 through Blender's own glTF exporter.

Each material of the object gets the baked maps in the layout Blender's glTF importer builds and
its exporter reads: an sRGB Image Texture into Base Color, a linear packed image through Separate
Color into Roughness (G) and Metallic (B), or plain values where a channel is constant. Everything
else in the material (normal map, occlusion, emission, alpha and its mode) is left as it is, so
the exporter writes it unchanged; the base colour image carries the original alpha channel
(resized) when the material uses alpha.
"""
from __future__ import annotations

import hashlib

import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.base.errors import InputError
from ..core.stages.bake.gltf_ktx2 import basisu_path, ktx2_glb
from ..core.stages.bake.engine_targets import engine_target
from ..core.stages.bake.gltf_tangents import tangents_repaired
from ..core.data.gltf_images import images_reencoded
from ..core.data.gltf_meshopt import encoded_glb
from ..core.stages.bake.gltf_output import (MIME_OF_FORMAT, GltfOutput, check_output_format, extensions_kept,
                                            output_like_input, skinned_meshes_moved_to_root)
from ..core.data.imageio import srgb_to_linear, write_image
from ..core.data.maps import resize_channels
from ..core.base.quiet import native_output_captured
from ..core.data.uv_raster import sample_image
from .material import EXTENSION_OF_WRAP, image_pixels_linear, material_wrap, principled_bsdf
from .node_values import source

if TYPE_CHECKING:   # (game_bake evaluates the network: torch, which Blender need not load to register the add-on)
    from ..core.stages.bake.game_bake import BakedMaterial

FORMATS = {"glb": "GLB", "gltf": "GLTF_SEPARATE"}
# --textures -> the exporter's image format (AUTO keeps the PNGs SceneFit bakes, and each other image's own format).
# ktx2: the exporter writes PNGs, which core.gltf_ktx2 then encodes.
_IMAGE_FORMATS = {"png": "AUTO", "jpeg": "JPEG", "webp": "WEBP", "ktx2": "AUTO"}


def _alpha_source(bsdf):
    """(image node, the input its Alpha output feeds) at the start of the Alpha chain, or None."""
    socket = bsdf.inputs["Alpha"]
    for _ in range(16):  # follow the first linked input up the chain (factor, clip nodes)
        linked = source(socket)
        if linked is None:
            return None
        node, output = linked
        if node.type == "TEX_IMAGE":
            return (node, socket) if output.name == "Alpha" and node.image is not None else None
        socket = next((s for s in node.inputs if s.is_linked), None)
        if socket is None:
            return None
    return None


def normal_mapped(material) -> bool:
    """Whether the material links its normal input (a normal map: the exporter writes it, and it needs TANGENT)."""
    try:
        socket = principled_bsdf(material).inputs.get("Normal")
    except InputError:
        return False
    return socket is not None and socket.is_linked


def _with_tangents(output: GltfOutput, asset_path: str | Path) -> GltfOutput:
    """`output` with tangents where a loaded material links its normal input (a normal map: engines want
    TANGENT with it), for inputs that are not glTF. A glTF input's TANGENT is followed as it is: where it
    has none, glTF's clients generate MikkTSpace tangents (as the spec asks), the validator's warning is
    the input's own, and 16 bytes a vertex (ToyCar: 1.22x the input's size) buy nothing the input had."""
    import bpy

    if Path(asset_path).suffix.lower() in (".glb", ".gltf"):
        return output
    tangents = (output.tangents or any(normal_mapped(m) for m in bpy.data.materials)) and output.compress != "draco"
    return replace(output, tangents=tangents, normals=output.normals or tangents)  # glTF: no TANGENT without NORMAL


def constant_channels(material) -> dict[str, float]:
    """The channels ("roughness", "metallic") the material gives as plain values, with those values."""
    bsdf = principled_bsdf(material)
    return {name.lower(): float(bsdf.inputs[name].default_value) for name in ("Roughness", "Metallic")
            if source(bsdf.inputs[name]) is None}


@dataclass
class BakeImages:
    """Where one export's baked images are written, and those written so far: materials that bake to the
    same pixels (a palette texture many materials sample) share one image, as the input did, instead of
    each writing a copy. `ships_png`: the exporter passes these PNGs' bytes into the file (png textures),
    so they are worth zlib's highest level; for jpeg, webp and ktx2 it re-encodes them, and level 9 on a
    2048² map cost seconds for nothing."""

    folder: Path
    ships_png: bool = True
    written: dict = field(default_factory=dict)

    def load(self, name: str, pixels: np.ndarray, colorspace: str):
        """An 8-bit image holding exactly `pixels` (uint8, rows top to bottom), saved as PNG (straight
        alpha, as glTF wants) and packed, so the exporter reads these bytes."""
        import bpy

        key = (colorspace, pixels.shape, hashlib.sha256(np.ascontiguousarray(pixels).tobytes()).hexdigest())
        if key in self.written:
            return self.written[key]
        # Packed as written: the exporter passes a packed PNG's bytes through unchanged (Blender's own PNG
        # writer makes files about 1.8x larger).
        path = write_image(self.folder / f"{bpy.path.clean_name(name)}.png", pixels.astype(np.float32) / 255.0,
                           "uint8", smallest=self.ships_png)
        image = bpy.data.images.load(str(path))
        image.name = name
        image.colorspace_settings.name = colorspace
        image.alpha_mode = "STRAIGHT"
        image.pack()  # the temporary folder can go
        self.written[key] = image
        return image


def apply_baked_material(material, baked: BakedMaterial, images: BakeImages) -> list[str]:
    """Rewire `material` (a fresh import, or a copy) to the baked maps, its images written by `images`;
    returns what was done."""
    bsdf = principled_bsdf(material)
    notes = []
    if baked.uv_map:
        notes.append(f"baked into a new UV map '{baked.uv_map}' (Smart UV Project): the asset's own UVs share texels "
                     "between surfaces, and the adapted result differs per surface; its own UVs stay for its "
                     "other images")
    if "base_color" in baked.unchanged:
        # What the material already gives (the exact start, nothing adapted): its own nodes and images are
        # written as they came, shared images, texture transforms, alpha and all.
        notes.append("base colour: unchanged, the material's own nodes and images kept")
    else:
        notes += _write_base_color(material, bsdf, baked, images)
    if getattr(bsdf, "unlit", False):
        notes.append("unlit: only the base colour is written (an unlit material has no roughness or metallic)")
        return notes
    if {"roughness", "metallic"} <= baked.unchanged:
        notes.append("roughness and metallic: unchanged, the material's own nodes and images kept")
        return notes
    return notes + _write_roughness_metallic(material, bsdf, baked, images)


def _extension(baked: BakedMaterial) -> str:
    """The maps were baked wrapped as the material's sampler says, so the exporter must write that sampler."""
    return EXTENSION_OF_WRAP[baked.wrap[0]] if baked.wrap[0] == baked.wrap[1] else "REPEAT"


def _read_through(material, image_node, baked: BakedMaterial) -> None:
    """An image baked in a new UV map reads that map (a UV Map node; the exporter writes its TEXCOORD)."""
    if baked.uv_map is None:
        return
    uv = material.node_tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = baked.uv_map
    uv.location = (image_node.location.x - 250, image_node.location.y)
    material.node_tree.links.new(uv.outputs["UV"], image_node.inputs["Vector"])


def _write_base_color(material, bsdf, baked: BakedMaterial, images: BakeImages) -> list[str]:
    """The baked base colour into the material: a factor when it is one colour, else a new image (with
    the alpha the material had, resized into it)."""
    nodes, links = material.node_tree.nodes, material.node_tree.links
    notes = []
    height, width = baked.base_color.shape[:2]
    rgba = baked.base_color
    alpha = _alpha_source(bsdf)
    if alpha is not None:
        original = image_pixels_linear(alpha[0].image)[..., 3]
        if baked.own_uv is not None:   # baked in a new UV map: the alpha read through each texel's own UV
            read = sample_image(original[..., None], baked.own_uv.reshape(-1, 2), material_wrap(material))
            original = read.reshape(height, width)
        else:
            original = resize_channels(original, height, width)
        a = np.round(np.clip(original, 0.0, 1.0) * 255.0).astype(np.uint8)
        rgba = np.concatenate([rgba, a[..., None]], axis=2)
        notes.append(f"alpha of '{alpha[0].image.name}' carried into the base colour image at {width}x{height}")
    if alpha is None and bool((rgba == rgba[0, 0]).all()):
        # One colour everywhere (a material that gave a plain colour, not adapted): a factor, as it came,
        # not an image of that colour.
        for link in list(bsdf.inputs["Base Color"].links):
            links.remove(link)
        linear = srgb_to_linear(rgba[0, 0, :3].astype(np.float32) / 255.0)
        bsdf.inputs["Base Color"].default_value = (*(float(v) for v in linear), 1.0)
        notes.append("base colour: one colour, written as a factor")
    else:
        base = nodes.new("ShaderNodeTexImage")
        base.name = base.label = "SceneFit Base Color"
        base.extension = _extension(baked)
        base.image = images.load(f"{material.name}_base_color", rgba, "sRGB")
        base.location = (bsdf.location.x - 700, bsdf.location.y)
        _read_through(material, base, baked)
        links.new(base.outputs["Color"], bsdf.inputs["Base Color"])
        if alpha is not None:
            links.new(base.outputs["Alpha"], alpha[1])
    return notes


def _write_roughness_metallic(material, bsdf, baked: BakedMaterial, images: BakeImages) -> list[str]:
    """The baked roughness and metallic into the material: factors where constant, else one packed image
    (G roughness, B metallic, as glTF packs them) through Separate Color."""
    nodes, links = material.node_tree.nodes, material.node_tree.links
    notes = []
    height, width = baked.base_color.shape[:2]
    textured = {k: v for k, v in (("Roughness", baked.roughness), ("Metallic", baked.metallic))
                if isinstance(v, np.ndarray)}
    for socket_name, value in (("Roughness", baked.roughness), ("Metallic", baked.metallic)):
        if socket_name not in textured:
            for link in list(bsdf.inputs[socket_name].links):
                links.remove(link)
            bsdf.inputs[socket_name].default_value = float(value)
            notes.append(f"{socket_name}: constant {float(value):.4g} written as a factor")
    if textured:
        zeros = np.zeros((height, width), np.uint8)
        packed = np.stack([zeros, textured.get("Roughness", zeros), textured.get("Metallic", zeros)], axis=2)
        mr = nodes.new("ShaderNodeTexImage")
        mr.name = mr.label = "SceneFit Metallic Roughness"
        mr.extension = _extension(baked)
        mr.image = images.load(f"{material.name}_metallic_roughness", packed, "Non-Color")
        mr.location = (bsdf.location.x - 700, bsdf.location.y - 300)
        _read_through(material, mr, baked)
        separate = nodes.new("ShaderNodeSeparateColor")
        separate.location = (bsdf.location.x - 300, bsdf.location.y - 300)
        links.new(mr.outputs["Color"], separate.inputs["Color"])
        for socket_name, channel in (("Roughness", "Green"), ("Metallic", "Blue")):
            if socket_name in textured:
                links.new(separate.outputs[channel], bsdf.inputs[socket_name])
        notes.append(f"{' and '.join(textured)}: packed image at {width}x{height} (G roughness, B metallic)")
    return notes


def export_gltf(out_file: str | Path, file_format: str, selection_only: list | None = None,
                protect: tuple = (), output: GltfOutput = GltfOutput(), replace: bool = False,
                notes: list[str] | None = None) -> list[Path]:
    """Write the current scene (or only `selection_only` objects) with Blender's glTF exporter, with
    `output`'s compression (Draco by the exporter, meshopt by meshoptimizer's encoder after it),
    texture format and tangents.

    The files are written into a temporary folder beside `out_file` and moved into place once the
    exporter has finished, so a failed export leaves nothing half-written; none is moved over a file
    in `protect` (the asset's own files: a .gltf's buffers and images), nor over any existing file
    unless `replace` (Blender's file browser has asked; the command line has --replace). Returns the
    written paths.
    """
    from ..core.data.asset_files import refuse_overwriting, refuse_replacing

    import addon_utils
    import bpy

    if file_format not in FORMATS:
        raise InputError(f"--format must be one of {', '.join(FORMATS)}, got '{file_format}'.")
    out_file = Path(out_file)
    if out_file.suffix.lower() != f".{file_format}":
        raise InputError(f"The output '{out_file.name}' should end in .{file_format} for --format {file_format}.")
    check_output_format(output, file_format)
    if output.textures == "ktx2":
        basisu_path()
    out_file.parent.mkdir(parents=True, exist_ok=True)
    addon_utils.enable("io_scene_gltf2", default_set=False)
    layer = bpy.context.view_layer
    selected = [o for o in layer.objects if o.select_get()]
    staging = Path(tempfile.mkdtemp(prefix=".scenefit-gltf-", dir=out_file.parent))
    try:
        if selection_only is not None:
            for obj in layer.objects:
                obj.select_set(obj in selection_only)
        with native_output_captured():   # the exporter's log lines (INFO, sampler notes) stay off the terminal
            bpy.ops.export_scene.gltf(filepath=str(staging / out_file.name), export_format=FORMATS[file_format],
                                      use_selection=selection_only is not None, use_active_scene=True,
                                      export_apply=True, export_cameras=True, export_lights=True,
                                      export_image_format=_IMAGE_FORMATS[output.textures], export_materials="EXPORT",
                                      export_tangents=output.tangents and output.compress != "draco",
                                      export_normals=output.normals, export_optimize_animation_keep_anim_armature=False,
                                      # glTF multiplies COLOR_0 into the base colour, and the baked base colour
                                      # already holds the vertex colours it read: no COLOR_n no material uses
                                      export_all_vertex_colors=False,
                                      export_draco_mesh_compression_enable=output.compress == "draco")
        staged = staging / out_file.name
        if output.skins_at_root:
            skinned_meshes_moved_to_root(staged)
        said = [] if notes is None else notes   # (what the caller's report says of the file)
        if output.extensions is not None:   # an engine's bake: only what its importer reads
            # (the exporter keeps a WebP input's images WebP: re-encoded where the engine reads none)
            reencoded = images_reencoded(staged, {MIME_OF_FORMAT[f] for f in engine_target(output.target).textures})
            if reencoded:
                said.append(f"re-encoded as PNG for {engine_target(output.target).label}, whose importer does not "
                            f"read their format: {', '.join(reencoded)}")
            removed = extensions_kept(staged, output.extensions)
            if removed:
                said.append(f"left out for {engine_target(output.target).label}, whose importer does not read "
                            f"them: {', '.join(removed)}")
        if output.tangents and output.compress != "draco":   # the input's where it can, none of zero length
            counts = tangents_repaired(staged, Path(output.tangent_source) if output.tangent_source else None)
            if counts["input_tangents_kept"] or counts["tangents_made_usable"]:
                said.append(f"tangents: {counts['input_tangents_kept']} of {counts['tangents']} the input's own, "
                            f"{counts['tangents_made_usable']} made unit and orthogonal to their normal")
        if output.textures == "ktx2":
            ktx2_glb(staged)
        if output.compress == "meshopt":
            encoded_glb(staged, staged)
        targets = [out_file.parent / p.name for p in sorted(staging.iterdir())]
        refuse_overwriting(targets, list(protect), "the glTF")
        if not replace:
            refuse_replacing(targets)
        written = []
        for path in sorted(staging.iterdir()):
            target = out_file.parent / path.name
            path.replace(target)
            written.append(target)
        return written
    finally:
        for obj in layer.objects:
            obj.select_set(obj in selected)
        shutil.rmtree(staging, ignore_errors=True)


def bake_object_to_gltf(obj, baked: list[BakedMaterial], slots: list[int], out_file: str | Path,
                        file_format: str = "glb", whole_scene: bool = True, protect: tuple = (),
                        output: GltfOutput = GltfOutput()) -> dict:
    """Put the baked maps into `obj`'s materials (slot `slots[i]` gets `baked[i]`) and export glTF.

    For an asset loaded into a temporary scene (blender_io.asset_file.loaded_asset): the materials
    are changed in place and `whole_scene` exports every object of that scene, so the asset keeps
    its structure. For the user's own objects use bake_copies_to_gltf (Bake Asset).
    """
    if len(baked) != len(slots):
        raise InputError(f"{len(baked)} baked materials for {len(slots)} material slots.")
    materials = [obj.material_slots[slot].material for slot in slots]
    return bake_materials_to_gltf(materials, baked, out_file, file_format, None if whole_scene else [obj], protect,
                                  output)


def bake_materials_to_gltf(materials: list, baked: list[BakedMaterial], out_file: str | Path, file_format: str = "glb",
                           selection_only: list | None = None, protect: tuple = (),
                           output: GltfOutput = GltfOutput(), replace: bool = False) -> dict:
    """Put `baked[i]` into `materials[i]` (each material once) and export the scene (or `selection_only`)."""
    report = {"materials": []}
    done = set()
    with tempfile.TemporaryDirectory(prefix="scenefit-bake-") as folder:
        images = BakeImages(Path(folder), ships_png=output.textures == "png")
        for maps, material in zip(baked, materials):
            if material.name in done:
                continue
            done.add(material.name)
            notes = apply_baked_material(material, maps, images)
            report["materials"].append(dict(maps.report(), done=notes))
        notes: list[str] = []
        written = export_gltf(out_file, file_format, selection_only, protect, output, replace, notes)
    report["files"] = [str(p) for p in written]
    report["output"] = output.report() | ({"notes": notes} if notes else {})
    return report


def _never_unchanged(baked: BakedMaterial, channels: frozenset[str]) -> BakedMaterial:
    """`baked` with `channels` written as new images even where their bytes are the material's own."""
    return replace(baked, unchanged=baked.unchanged - channels)


def bake_asset_file(asset_path: str | Path, texture, out_file: str | Path, file_format: str = "glb",
                    texture_size: int | None = None, object_name: str | None = None, protect: tuple = (),
                    output: GltfOutput | None = None, replace: bool = False) -> dict:
    """`scenefit bake`: the asset file loaded into a temporary scene, the neural texture baked per
    material at `texture_size`² (default: each material's own image size, rounded up to a power of
    two), its base the material's own maps, written
    as glTF 2.0. `texture` is a NeuralTexture or the path of a texture.pt. Returns the report.
    `output`: compression, texture format and size cap (default: as the input, see
    core.gltf_output.output_like_input); tangents as a glTF input has them, and where a material of
    another kind of file has a normal map.

    Known bpy 5.0.1 crash: once the exporter has run on the temporary scene and the scene is
    removed, the next glTF import in the same process segfaults. `scenefit bake` is a process of
    its own; long-lived callers should run it as a subprocess (or use bake_copies_to_gltf)."""
    from ..core.stages.bake.game_bake import bake_game_maps, bake_shapes, materials_to_remap
    from ..core.texture.bake import load_neural_texture
    import bpy

    from .asset_file import loaded_asset
    from .material import object_mesh_and_slots, read_material_within, unwrap_vertex_coloured
    from .scene_asset import scene_mesh
    from .uv_unwrap import NEW_UV_MAP, new_uv_map_active

    if not hasattr(texture, "texture"):
        texture = load_neural_texture(texture)
    with loaded_asset(asset_path, object_name) as (meshes, scene):
        unwrap_vertex_coloured(meshes)   # as convert read it: vertex colours without UVs get a UV map
        def read() -> tuple:
            depsgraph = bpy.context.evaluated_depsgraph_get()
            if len(meshes) > 1:   # several objects are the asset, joined as convert read them
                whole = scene_mesh(meshes, depsgraph, object_name or Path(asset_path).stem)
                return whole.mesh, whole.materials, whole.objects, list(whole.users)
            obj = meshes[0]
            mesh, slots = object_mesh_and_slots(obj, depsgraph, space="world")  # as convert
            return mesh, [obj.material_slots[s].material for s in slots], [obj.name], [(obj, s) for s in slots]

        mesh, materials, taken, users = read()
        output = _with_tangents(output or output_like_input(asset_path), asset_path)
        # No bake is larger than this (bake_shapes): procedural chains are baked by Cycles at no more.
        limit = min(texture_size or output.max_texture, output.max_texture)
        read_own = [read_material_within(m, o, slot, limit) for m, (o, slot) in zip(materials, users)]
        own, shrunk = [r[0].maps for r in read_own], [r[1] for r in read_own]
        wraps = [material_wrap(m) for m in materials]
        # Adapted per surface on UVs that share texels: those materials' maps go into a new UV map.
        remap, remapped, unmapped = materials_to_remap(texture, mesh, wraps), None, None
        if remap:
            try:
                with new_uv_map_active(meshes, [materials[i] for i in sorted(remap)]):
                    remapped = read()[0]
            except (RuntimeError, InputError) as error:   # Smart UV Project failed: the asset's own UVs, said so
                remap, unmapped = frozenset(), f"no new UV map could be made ({str(error)[:160]}); baked in the " \
                                               "asset's own UVs, where surfaces that share texels show one result"
                for me in {o.data for o in meshes}:
                    if NEW_UV_MAP in me.uv_layers:
                        me.uv_layers.remove(me.uv_layers[NEW_UV_MAP])
        # Each material at its own images' shape (--texture-size: all square at that size), within
        # --max-texture; the base is the material's own maps at that shape, so the preset's working size
        # costs no detail.
        baked = bake_game_maps(texture, mesh, [m.name for m in materials], bake_shapes(own, texture_size,
                                                                                       output.max_texture),
                               [constant_channels(m) for m in materials], wraps, own, remapped, remap, NEW_UV_MAP)
        baked = [_never_unchanged(b, s) for b, s in zip(baked, shrunk)]
        report = bake_materials_to_gltf(materials, baked, out_file, file_format, protect=protect, output=output,
                                        replace=replace)
        report.update({"asset": str(asset_path), "object": taken[0] if len(taken) == 1 else None, "objects": taken,
                       "format": file_format, "texture_size": max(max(m.base_color.shape[:2]) for m in baked)})
        if unmapped:
            report["uv_map"] = unmapped
    return report


def bake_copy_to_gltf(obj, baked: list[BakedMaterial], slots: list[int], out_file: str | Path,
                      file_format: str = "glb", output: GltfOutput = GltfOutput()) -> dict:
    """bake_object_to_gltf for an object in the user's session (see bake_copies_to_gltf): slot
    `slots[i]` of `obj` gets `baked[i]`. Nothing of the user's is changed."""
    return bake_copies_to_gltf([obj], baked, [[(obj, slot)] for slot in slots], out_file, file_format, output)


# What may carry an asset without being geometry of its own: the file's group nodes and armatures.
CARRIER_TYPES = ("EMPTY", "ARMATURE")


def _depth(obj) -> int:
    """How many parents stand above `obj`."""
    return 0 if obj.parent is None else 1 + _depth(obj.parent)


def carriers_of(objects: list) -> list:
    """What carries `objects` and is not one of them: every empty and armature above them (the file's root
    and group nodes, a rig) and the armatures that deform them. Exported beside the copies, an asset keeps
    its node tree, its transforms and the animations on those nodes, and a character its skeleton and skin
    (without the armature the exporter applies the pose and writes a still mesh). They are exported as
    they are, never changed; geometry above the asset that is not part of it (a mesh, a curve, text)
    stays out (its baked maps would be missing)."""
    carriers: list = []
    for obj in objects:
        found = [m.object for m in obj.modifiers if m.type == "ARMATURE" and m.object is not None]
        parent = obj.parent
        while parent is not None:
            if parent.type in CARRIER_TYPES:
                found.append(parent)
            parent = parent.parent
        carriers += [o for o in found if o not in carriers and o not in objects]
    return carriers


def bake_copies_to_gltf(objects: list, baked: list[BakedMaterial], slots: list[list[tuple]], out_file: str | Path,
                        file_format: str = "glb", output: GltfOutput = GltfOutput(), replace: bool = False,
                        new_uvs: dict | None = None, sources: list | None = None, beside: list = ()) -> dict:
    """Objects of the user's session written as one asset: a copy of each object, its mesh and its materials
    gets the maps (`baked[i]` into the material in each (object, slot number) pair of `slots[i]`) and the
    copies alone are exported, then removed. The copies carry the originals' names while the exporter runs
    (the originals are renamed meanwhile and renamed back after), so the file names its objects and
    materials as the user does. Nothing of the user's is changed. `new_uvs`: per object name, the UVs per loop
    of the new UV map that materials baked per surface read (blender_io.uv_unwrap.unwrapped_copies).
    `sources[i]`: the material the slots of `slots[i]` are exported from (default: the one they hold;
    Bake Asset: the artist's material a SceneFit result replaced). `beside`: objects written as they are
    with the asset and what carries them (the file's cameras and lights, asset_file.imported_beside)."""
    import bpy

    from .uv_unwrap import add_uv_map

    if len(baked) != len(slots):
        raise InputError(f"{len(baked)} baked materials for {len(slots)} materials of the asset.")
    scene = bpy.context.scene
    images_before = set(bpy.data.images)  # the maps made below are removed after; nothing else is
    copies, material_copies, renamed, beside_copies = {}, {}, [], {}
    try:
        for obj in objects:
            copy = obj.copy()
            copy.data = obj.data.copy()
            copies[obj.name] = copy
            scene.collection.objects.link(copy)
            if new_uvs and obj.name in new_uvs:
                add_uv_map(copy, new_uvs[obj.name])
        for other in sorted(beside, key=_depth):   # a camera on the truck's body rides on the body's copy (a copy
            parent = other.parent                 # of it, sharing its data), and a light on that camera on it
            if parent is not None and (parent.name in copies or parent.name in beside_copies):
                beside_copies[other.name] = other.copy()
                scene.collection.objects.link(beside_copies[other.name])
        riders = {**copies, **beside_copies}
        for copy in riders.values():   # a wheel under the truck's body hangs under the body's copy
            if copy.parent is not None and copy.parent.name in riders:
                copy.parent = riders[copy.parent.name]   # (the parent inverse, copied, stays as it was)
        materials = []
        for index, pairs in enumerate(slots):
            for obj, slot in pairs:
                material = sources[index] if sources else obj.material_slots[slot].material
                if material.name not in material_copies:
                    material_copies[material.name] = material.copy()
                copy = copies[obj.name]
                copy.material_slots[slot].link = obj.material_slots[slot].link
                copy.material_slots[slot].material = material_copies[material.name]
            materials.append(copy.material_slots[slot].material)
        written_beside = [beside_copies.get(o.name, o) for o in beside]   # (before the originals are renamed)
        for original, duplicate in [*[(bpy.data.objects[n], c) for n, c in [*copies.items(), *beside_copies.items()]],
                                    *[(bpy.data.materials[n], c) for n, c in material_copies.items()]]:
            name = original.name
            original.name = f"{name}~scenefit"
            renamed.append((original, name))
            duplicate.name = name
        report = bake_materials_to_gltf(materials, baked, out_file, file_format,
                                        [*copies.values(), *written_beside, *carriers_of([*objects, *beside])],
                                        output=output,
                                        replace=replace)
    finally:
        # (a SceneFit result material's own image nodes are also named "SceneFit …": keep those)
        images = set(bpy.data.images) - images_before
        for copy in copies.values():
            mesh = copy.data
            bpy.data.objects.remove(copy)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
        for duplicate in beside_copies.values():
            bpy.data.objects.remove(duplicate)
        for duplicate in material_copies.values():
            bpy.data.materials.remove(duplicate)
        for image in images:
            bpy.data.images.remove(image)
        for original, name in renamed:
            original.name = name
    return report
