"""Baking a procedural node chain (noise, ramps, vertex colours, ...) into an image with Cycles.

The bake runs on temporary copies only: a copy of the object's evaluated mesh holding just the
faces of one material slot, and a copy of the material whose output shows the chain through an
Emission shader. The user's object, mesh, material, selection and render settings are restored or
never touched; the temporaries are removed afterwards.
"""
from __future__ import annotations

import numpy as np

from ..core.errors import InputError

# Samples per texel: the emission of a procedural chain needs no light paths, only anti-aliasing.
BAKE_SAMPLES = 4


def bake_socket(obj, slot: int, socket, size: int, pixels_of) -> np.ndarray:
    """(size, size, 3) linear values of what drives `socket` (an input of a node in the material of
    `obj`'s slot `slot`), over that slot's faces in the mesh's active UV layout."""
    import bmesh
    import bpy

    if obj is None:
        raise InputError(f"'{socket.node.name}' drives {socket.name} through a procedural node setup, and "
                         "without its object it cannot be baked; bake it to an image first.")
    material = obj.material_slots[slot].material
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
        bpy.ops.object.bake(type="EMIT", margin=max(2, size // 64), use_clear=True)
        return pixels_of(image)[..., :3].copy()
    finally:
        _restore_state(bpy, scene, saved)
        bpy.data.objects.remove(tmp)
        bpy.data.meshes.remove(mesh)
        bpy.data.materials.remove(mat)
        bpy.data.images.remove(image)


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
