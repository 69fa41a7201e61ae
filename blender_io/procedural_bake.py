"""Baking a procedural node chain (noise, ramps, vertex colours, ...) into an image with Cycles.

The bake runs on temporary copies only: a copy of the object's evaluated mesh holding just the
faces of one material slot, and a copy of the material whose output shows the chain through an
Emission shader. The user's object, mesh, material, selection and render settings are restored or
never touched; the temporaries are removed afterwards.
"""
from __future__ import annotations

import numpy as np

from ..core.base.errors import InputError
from ..core.data.map_plan import Source
from ..core.base.quiet import native_output_captured
from .interrupts import interrupt_held

# Samples per texel: the emission of a procedural chain needs no light paths, only anti-aliasing.
BAKE_SAMPLES = 4
# Copies of the image (UV tiles) a chain is baked over at most: each is a bake of its own.
MAX_COPIES = 64


class SocketBake(Source):
    """One procedural input's bake, owed by the main thread (one per timer tick of a job's gathering):
    its object, material and socket are found again by name when it runs, as the artist may have
    changed the file between ticks; `pixels()` then gives what bake_socket baked."""

    def __init__(self, obj, slot: int, socket, size: int, wrap: tuple[str, str], material, pixels_of) -> None:
        if obj is None:   # the sentence bake_socket says, at once
            bake_socket(None, slot, socket, size, pixels_of, wrap, material)
        self.object_name, self.slot, self.size, self.wrap = obj.name, slot, size, wrap
        self.material_name, self.node_name = material.name, socket.node.name
        self.socket_name, self.socket_id = socket.name, socket.identifier
        self.pixels_of = pixels_of
        self.words = f"'{material.name}' {socket.name}"
        self.baked: np.ndarray | None = None

    @property
    def done(self) -> bool:
        return self.baked is not None

    def run(self) -> None:
        import bpy

        obj, material = bpy.data.objects.get(self.object_name), bpy.data.materials.get(self.material_name)
        node = material.node_tree.nodes.get(self.node_name) if material is not None else None
        if obj is None or node is None:
            raise InputError(f"{self.words} changed while SceneFit read it (its object, material or node is gone); "
                             "run it again.")
        socket = next((s for s in node.inputs if s.identifier == self.socket_id), None) or node.inputs[self.socket_name]
        self.baked = bake_socket(obj, self.slot, socket, self.size, self.pixels_of, self.wrap, material)

    def pixels(self) -> np.ndarray:
        if self.baked is None:
            raise RuntimeError(f"the bake of {self.words} was not run")
        return self.baked


def bake_socket(obj, slot: int, socket, size: int, pixels_of,
                wrap: tuple[str, str] = ("repeat", "repeat"), material=None) -> np.ndarray:
    """(size, size, 3) linear values of what drives `socket` (an input of a node in `material`, by
    default the material of `obj`'s slot `slot`), over that slot's faces in the mesh's active UV layout.
    `material` differs from the slot's where the slot holds a SceneFit result and the artist's material
    it replaced is read (Bake Asset after Run All).

    Blender bakes only UVs inside [0, 1]; faces whose UVs tile past it (wrap "repeat" or "mirror",
    see core.data.uv_raster) are baked once per copy of the image they reach, through a second
    UV map that moves that copy onto [0, 1] while the chain still reads the mesh's own UVs."""
    import bmesh
    import bpy

    if obj is None:
        raise InputError(f"'{socket.node.name}' drives {socket.name} through a procedural node setup, and "
                         "without its object it cannot be baked; bake it to an image first.")
    material = material or obj.material_slots[slot].material
    scene = bpy.context.scene
    if not hasattr(scene, "cycles"):
        import addon_utils

        addon_utils.enable("cycles", default_set=False)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
    mat = material.copy()
    image = bpy.data.images.new("SceneFit bake", size, size, alpha=False, float_buffer=True)
    tmp = bpy.data.objects.new("SceneFit bake", mesh)
    saved = _save_state(bpy, scene)
    try:
        bm = bmesh.new()
        bm.from_mesh(mesh)
        bmesh.ops.delete(bm, geom=[f for f in bm.faces if f.material_index != slot], context="FACES")
        for face in bm.faces:
            face.material_index = 0
        bm.to_mesh(mesh)
        bm.free()
        if len(mesh.polygons) == 0:
            raise InputError(f"No face of '{obj.name}' uses material '{material.name}'; nothing to bake.")
        if mesh.uv_layers.active is None:   # the bake writes through UVs
            raise InputError(f"Object '{obj.name}' has no UV map, which reading the procedural inputs of its material "
                             f"'{material.name}' needs; unwrap it first (Add UV Map in SceneFit's panel, or UV > Smart UV Project).")
        mesh.materials.clear()
        mesh.materials.append(mat)
        tmp.matrix_world = obj.matrix_world
        scene.collection.objects.link(tmp)
        _show_chain_as_emission(mat, socket)
        target = mat.node_tree.nodes.new("ShaderNodeTexImage")
        target.image = image
        mat.node_tree.nodes.active = target  # Cycles bakes into the active Image Texture node

        for other in bpy.context.view_layer.objects:
            other.select_set(False)
        tmp.select_set(True)
        bpy.context.view_layer.objects.active = tmp
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = BAKE_SAMPLES
        scene.render.bake.margin_type = "EXTEND"
        copies = _image_copies(mesh, wrap)
        if len(copies) > MAX_COPIES:
            raise InputError(f"'{socket.node.name}' drives {socket.name} of '{material.name}' through a procedural "
                             f"node setup, over UVs that reach {len(copies)} copies of the texture (SceneFit bakes "
                             f"at most {MAX_COPIES}); bake it to an image in Blender first.")
        # Blender says "Info: Baking map saved ..." for every bake; a Ctrl-C inside Cycles' Python would be lost
        with native_output_captured(), interrupt_held():
            if copies == [(0, 0)]:
                bpy.ops.object.bake(type="EMIT", margin=max(2, size // 64), use_clear=True)
                return pixels_of(image)[..., :3].copy()
            return _bake_copies(bpy, mesh, image, copies, wrap, pixels_of)
    finally:
        _restore_state(bpy, scene, saved)
        bpy.data.objects.remove(tmp)
        bpy.data.meshes.remove(mesh)
        bpy.data.materials.remove(mat)
        bpy.data.images.remove(image)
        # The view layer still lists the removed object until it is updated: a later walk of its
        # objects (the glTF export's selection) would touch freed memory and crash Blender.
        bpy.context.view_layer.update()


def _image_copies(mesh, wrap: tuple[str, str]) -> list[tuple[int, int]]:
    """The copies (u, v) of the image (tiles of the UV plane) that the mesh's faces reach; along an
    axis that clamps only the image itself."""
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers.active.uv.foreach_get("vector", uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    starts = np.empty(len(mesh.polygons), np.int64)
    mesh.polygons.foreach_get("loop_start", starts)
    lo, hi = np.minimum.reduceat(uv, starts), np.maximum.reduceat(uv, starts)
    spans = []
    for axis, mode in enumerate(wrap):
        first = np.floor(lo[:, axis]).astype(np.int64)
        last = np.maximum(np.ceil(hi[:, axis]).astype(np.int64) - 1, first)  # a face ending at 1 stays in copy 0
        spans.append(np.zeros((len(first), 2), np.int64) if mode == "clamp" else np.stack((first, last), 1))
    copies = {(int(u), int(v)) for (u0, u1), (v0, v1) in zip(*spans)
              for u in range(u0, u1 + 1) for v in range(v0, v1 + 1)}
    return sorted(copies)


def _bake_copies(bpy, mesh, image, copies: list[tuple[int, int]], wrap: tuple[str, str], pixels_of) -> np.ndarray:
    """Bake each copy of the image in turn into `image` (margin 0, so no copy paints over another's
    texels), then extend the baked texels into the rest as Blender's EXTEND margin would."""
    from ..core.data.uv_raster import seam_fill_index

    own = mesh.uv_layers.active.name
    mesh.uv_layers.new(name="SceneFit bake copy")
    layers = mesh.uv_layers  # (references to UV maps go stale when one is added)
    layers[own].active_render = True  # the chain reads the mesh's own UVs ...
    layers.active = layers["SceneFit bake copy"]  # ... and the bake writes through this one
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    layers[own].uv.foreach_get("vector", uv)
    uv = uv.reshape(-1, 2)
    image.pixels.foreach_set(np.zeros(len(image.pixels), np.float32))  # alpha 0: not baked yet
    for copy in copies:
        moved = uv.copy()
        for axis, (mode, tile) in enumerate(zip(wrap, copy)):
            if mode == "mirror" and tile % 2:
                moved[:, axis] = tile + 1 - uv[:, axis]  # an odd copy reads the image backwards
            elif mode != "clamp":
                moved[:, axis] = uv[:, axis] - tile
        layers["SceneFit bake copy"].uv.foreach_set("vector", moved.ravel())
        bpy.ops.object.bake(type="EMIT", margin=0, use_clear=False)
    pixels = pixels_of(image)
    baked = pixels[..., 3] > 0.5  # the emission bake writes alpha 1 where it wrote
    if not baked.any():
        return pixels[..., :3].copy()
    return pixels[..., :3].reshape(-1, 3)[seam_fill_index(baked)].reshape(pixels.shape[0], pixels.shape[1], 3)


def _show_chain_as_emission(mat, socket) -> None:
    """Route what drives the copied material's `socket` into an Emission shader at the output."""
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    copied = nodes[socket.node.name].inputs[socket.identifier] if socket.identifier in nodes[socket.node.name].inputs \
        else nodes[socket.node.name].inputs[socket.name]
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    links.new(copied.links[0].from_socket, emission.inputs["Color"])
    output = next((n for n in nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None) \
        or nodes.new("ShaderNodeOutputMaterial")
    links.new(emission.outputs["Emission"], output.inputs["Surface"])


def _save_state(bpy, scene) -> dict:
    layer = bpy.context.view_layer
    return {"selected": [o for o in layer.objects if o.select_get()], "active": layer.objects.active,
            "engine": scene.render.engine, "samples": scene.cycles.samples, "device": scene.cycles.device,
            "margin_type": scene.render.bake.margin_type}


def _restore_state(bpy, scene, saved: dict) -> None:
    layer = bpy.context.view_layer
    for obj in layer.objects:
        obj.select_set(obj in saved["selected"])
    layer.objects.active = saved["active"]
    scene.render.engine = saved["engine"]
    scene.cycles.samples = saved["samples"]
    scene.cycles.device = saved["device"]
    scene.render.bake.margin_type = saved["margin_type"]
