"""A new UV map for the materials an adapted texture is baked per surface (core.surface_layout).

The game bake writes such a material's maps into a new UV map made by Blender's Smart UV Project:
each of those materials' faces (over every object of the asset) packed into their own [0, 1]
square, the other faces keeping their UVs. The asset's own UV maps stay as they were (its normal
map, occlusion and emission still read them); the new map is written as one more TEXCOORD.
"""
from __future__ import annotations

from contextlib import contextmanager

NEW_UV_MAP = "SceneFit UV"
# Smart UV Project's defaults for an angle that splits charts; margin in UV units (2 texels at 1024²).
ANGLE_LIMIT_DEG = 66.0
ISLAND_MARGIN = 0.002


@contextmanager
def new_uv_map_active(objects: list, materials: list):
    """While the block runs, every object's mesh has NEW_UV_MAP active (as mesh_from_object reads it):
    `materials`' faces unwrapped anew, one material at a time, other faces as in the active map. After
    it, the original map is active again and the new one stays for the exporter."""
    import math

    import bmesh
    import bpy

    meshes = list({obj.data.name: obj.data for obj in objects}.values())
    before = {me.name: me.uv_layers.active.name if me.uv_layers.active else None for me in meshes}
    for me in meshes:
        layer = me.uv_layers.new(name=NEW_UV_MAP, do_init=True)   # a copy of the active map
        me.uv_layers.active = layer
    view_layer = bpy.context.view_layer
    active, selected = view_layer.objects.active, [o for o in view_layer.objects if o.select_get()]
    for obj in selected:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    view_layer.objects.active = objects[0]
    try:
        bpy.ops.object.mode_set(mode="EDIT")
        for material in materials:
            for obj in objects:
                edit = bmesh.from_edit_mesh(obj.data)
                slots = {i for i, slot in enumerate(obj.material_slots) if slot.material == material}
                for face in edit.faces:
                    face.select_set(face.material_index in slots)
                bmesh.update_edit_mesh(obj.data)
            bpy.ops.uv.smart_project(angle_limit=math.radians(ANGLE_LIMIT_DEG), island_margin=ISLAND_MARGIN,
                                     scale_to_bounds=False)
        bpy.ops.object.mode_set(mode="OBJECT")
        yield
    finally:
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        for obj in objects:
            obj.select_set(False)
        for obj in selected:
            obj.select_set(True)
        view_layer.objects.active = active
        for me in meshes:   # (a mesh that had no UV map keeps the new one as its only one)
            if before[me.name] is not None:
                me.uv_layers.active = me.uv_layers[before[me.name]]


def unwrapped_copies(objects: list, materials: list, read) -> tuple[object, dict]:
    """Smart UV Project on copies of `objects` (the artist's objects and meshes are not touched): the asset
    read through the new map by `read(copies)` (in `objects`' order, as the asset was read), and each
    object's new UVs per loop, by the original's name, for the exported copies to carry (add_uv_map)."""
    import bpy
    import numpy as np

    scene = bpy.context.scene
    copies = []
    try:
        for index, obj in enumerate(sorted(objects, key=lambda o: o.name)):
            copy = obj.copy()
            copy.data = obj.data.copy()
            copy.name = f"~scenefit uv {index:04d}"   # sorts as the originals do (scene_mesh reads in name order)
            scene.collection.objects.link(copy)
            copies.append(copy)
        with new_uv_map_active(copies, materials):
            remapped = read(copies)
            loops = {}
            for obj, copy in zip(sorted(objects, key=lambda o: o.name), copies):
                uv = np.empty(2 * len(copy.data.loops), np.float32)
                copy.data.uv_layers[NEW_UV_MAP].uv.foreach_get("vector", uv)
                loops[obj.name] = uv.reshape(-1, 2)
    finally:
        for copy in copies:
            mesh = copy.data
            bpy.data.objects.remove(copy)
            if mesh.users == 0:
                bpy.data.meshes.remove(mesh)
    return remapped, loops


def add_uv_map(obj, loop_uvs) -> None:
    """NEW_UV_MAP on `obj`'s mesh (a copy being exported) with these per-loop UVs; the active map stays."""
    layer = obj.data.uv_layers.new(name=NEW_UV_MAP, do_init=False)
    layer.uv.foreach_set("vector", loop_uvs.astype("float32").ravel())
