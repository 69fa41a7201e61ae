"""Helpers shared by the operators (main thread only)."""
from __future__ import annotations

from pathlib import Path

import bpy

from ..blender_io import maps_from_material, mesh_from_object


def output_dir(context, sub: str) -> Path:
    """The scene's output folder (Blender-relative '//' resolved) plus `sub`, created."""
    settings = context.scene.scenefit
    base = Path(bpy.path.abspath(settings.output_dir or "//scenefit/"))
    if not base.is_absolute() or str(base).startswith("//"):
        base = Path(bpy.app.tempdir or "/tmp") / "scenefit"
    folder = base / bpy.path.clean_name(context.active_object.name) / sub
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def gather_asset(context):
    """The active object's mesh (object space) and material maps, as core data."""
    obj = context.active_object
    mesh = mesh_from_object(obj, context.evaluated_depsgraph_get())
    maps = maps_from_material(obj.active_material)
    return obj, mesh, maps


def poll_mesh(context) -> bool:
    obj = context.active_object
    return obj is not None and obj.type == "MESH"
