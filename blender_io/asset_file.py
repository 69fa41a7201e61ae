"""Loading an asset from any file Blender reads (.blend, glTF, OBJ, FBX, PLY, USD) for the command line.

The file is opened or imported into a fresh, empty Blender session; the user's file is only read.
"""
from __future__ import annotations

from pathlib import Path

from ..core.errors import InputError
from ..core.maps import PBRMaps
from ..core.materials import AssetMaterials
from ..core.mesh import Mesh
from .material import read_object_materials

IMPORTERS = {
    ".glb": ("import_scene", "gltf"), ".gltf": ("import_scene", "gltf"),
    ".obj": ("wm", "obj_import"), ".fbx": ("import_scene", "fbx"), ".ply": ("wm", "ply_import"),
    ".usd": ("wm", "usd_import"), ".usda": ("wm", "usd_import"), ".usdc": ("wm", "usd_import"),
    ".usdz": ("wm", "usd_import"),
}


def load_asset_file(path: str | Path, object_name: str | None = None) -> tuple[Mesh, PBRMaps]:
    """The named mesh object (or the one with most faces) and its maps; several materials come as
    one atlas (see AssetMaterials.fitting_view)."""
    return load_asset_materials(path, object_name).fitting_view()


def load_asset_materials(path: str | Path, object_name: str | None = None) -> AssetMaterials:
    """The named mesh object (or the one with most faces) with every material its faces use."""
    return read_object_materials(*import_asset_file(path, object_name))


def import_asset_file(path: str | Path, object_name: str | None = None):
    """(object, depsgraph): the file opened or imported into a fresh, empty Blender session."""
    import bpy

    path = Path(path)
    if not path.is_file():
        raise InputError(f"Asset file '{path}' does not exist.")
    suffix = path.suffix.lower()
    if suffix == ".blend":
        bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    elif suffix in IMPORTERS:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        module, op = IMPORTERS[suffix]
        if suffix in (".fbx",) or module == "import_scene":
            import addon_utils

            addon_utils.enable("io_scene_gltf2" if "gltf" in suffix else "io_scene_fbx", default_set=False)
        getattr(getattr(bpy.ops, module), op)(filepath=str(path))
    else:
        known = ", ".join(sorted({".blend", *IMPORTERS}))
        raise InputError(f"SceneFit cannot read '{suffix}' files; use one of {known}, or an asset folder.")

    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    if object_name is not None:
        obj = bpy.data.objects.get(object_name)
        if obj is None or obj.type != "MESH":
            names = ", ".join(o.name for o in meshes) or "none"
            raise InputError(f"No mesh object '{object_name}' in '{path.name}'; mesh objects: {names}.")
    elif meshes:
        obj = max(meshes, key=lambda o: len(o.data.polygons))
    else:
        raise InputError(f"'{path.name}' holds no mesh object.")
    return obj, bpy.context.evaluated_depsgraph_get()
