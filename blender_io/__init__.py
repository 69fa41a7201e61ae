"""Blender <-> core: turn Blender data into core's arrays and write results back as new data.

Everything here runs on Blender's main thread and may import bpy; core/ never does.
"""
from .mesh import mesh_from_object, world_matrix
from .material import maps_from_material, read_material, read_object_materials, write_result_material

__all__ = ["mesh_from_object", "world_matrix", "maps_from_material", "read_material", "read_object_materials",
           "write_result_material"]
