"""Add UV Map: the artist's word to give the asset's meshes without a UV map one (Smart UV Project), so
SceneFit can hold their material (vertex colours, procedural inputs) in a texture. Undo takes it out."""
from __future__ import annotations

import bpy

from ..core.base.errors import SceneFitError
from .asset import asset_objects
from .polls import OnMesh


def objects_without_uvs(context) -> list:
    """The asset's mesh objects (the selection, else the active object) that have no UV map."""
    return [obj for obj in asset_objects(context) if obj.type == "MESH" and not obj.data.uv_layers]


class SCENEFIT_OT_add_uv_map(OnMesh, bpy.types.Operator):
    """Unwrap the asset's meshes that have no UV map (Smart UV Project into a new map 'SceneFit UV'), so
    their colours can become a texture; the shape is not changed, and Undo takes the map out again"""

    bl_idname = "scenefit.add_uv_map"
    bl_label = "Add UV Map"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not super().poll(context):
            return False
        obj = context.active_object
        if obj.data.uv_layers:
            cls.poll_message_set("The mesh already has a UV map")
            return False
        return True

    def execute(self, context):
        from ..blender_io.uv_unwrap import NEW_UV_MAP, new_uv_map_active

        try:
            objects = objects_without_uvs(context)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if not objects:
            self.report({"INFO"}, "Every mesh of the asset already has a UV map")
            return {"CANCELLED"}
        materials = list({slot.material.name: slot.material for obj in objects for slot in obj.material_slots
                          if slot.material is not None}.values())
        if not materials:
            self.report({"ERROR"}, f"'{objects[0].name}' has no material for SceneFit to read; give it one first.")
            return {"CANCELLED"}
        with new_uv_map_active(objects, materials):
            pass   # (a mesh without a UV map keeps the new one as its only, active map)
        names = ", ".join(f"'{obj.name}'" for obj in objects)
        self.report({"INFO"}, f"UV map '{NEW_UV_MAP}' added to {names} (Smart UV Project)")
        return {"FINISHED"}


classes = (SCENEFIT_OT_add_uv_map,)

register, unregister = bpy.utils.register_classes_factory(classes)
