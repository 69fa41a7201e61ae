"""Loading an asset from any file Blender reads (.blend, glTF, OBJ, FBX, PLY, USD) for the command line.

The file is opened or imported into a fresh, empty Blender session; the user's file is only read.
"""
from __future__ import annotations

import re
from pathlib import Path

from ..core.errors import InputError
from ..core.maps import PBRMaps
from ..core.mesh import Mesh
from ..core.quiet import native_output_captured
from .material import maps_from_material
from .mesh import mesh_from_object

IMPORTERS = {
    ".glb": ("import_scene", "gltf"), ".gltf": ("import_scene", "gltf"),
    ".obj": ("wm", "obj_import"), ".fbx": ("import_scene", "fbx"), ".ply": ("wm", "ply_import"),
    ".usd": ("wm", "usd_import"), ".usda": ("wm", "usd_import"), ".usdc": ("wm", "usd_import"),
    ".usdz": ("wm", "usd_import"),
}


def _open_or_import(bpy, path: Path, suffix: str) -> None:
    if suffix == ".blend":
        bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
        return
    bpy.ops.wm.read_factory_settings(use_empty=True)
    module, op = IMPORTERS[suffix]
    if suffix in (".fbx",) or module == "import_scene":
        import addon_utils

        addon_utils.enable("io_scene_gltf2" if "gltf" in suffix else "io_scene_fbx", default_set=False)
    getattr(getattr(bpy.ops, module), op)(filepath=str(path))


def _blender_reason(error: Exception) -> str:
    """The last meaningful line of a Blender operator error (they carry the importer's traceback)."""
    lines = [line for line in str(error).splitlines() if line.strip()]
    lines = [line.strip() for line in lines if not line.startswith((" ", "\t"))
             and not line.startswith(("Traceback", "Location:", "Error: Python: Traceback"))]
    reason = lines[-1].removeprefix("Error:").strip() if lines else ""
    reason = re.sub(r"^[A-Za-z_][\w.]*(Error|error|Exception): ", "", reason)
    return reason[:200]


def load_asset_file(path: str | Path, object_name: str | None = None) -> tuple[Mesh, PBRMaps]:
    """The named mesh object (or the one with most faces) and its material's maps."""
    import bpy

    path = Path(path)
    if path.is_dir():
        raise InputError(f"'{path}' is a folder but not a SceneFit asset folder (it has no mesh.npz); give an "
                         "asset folder or a .blend/.glb/.gltf/.obj/.fbx file.")
    if not path.is_file():
        raise InputError(f"Asset file '{path}' does not exist.")
    suffix = path.suffix.lower()
    if suffix != ".blend" and suffix not in IMPORTERS:
        known = ", ".join(sorted({".blend", *IMPORTERS}))
        raise InputError(f"SceneFit cannot read '{suffix}' files; use one of {known}, or an asset folder.")
    if path.stat().st_size == 0:
        raise InputError(f"Asset file '{path}' is empty; export it again.")
    # Blender's importers print to the terminal and raise RuntimeError on a broken file: keep their
    # chatter for the error's reason, off the user's terminal.
    with native_output_captured() as chatter:
        try:
            _open_or_import(bpy, path, suffix)
            failure = None
        except (RuntimeError, ValueError, OSError, UnicodeDecodeError) as error:
            failure = error
    if failure is not None:
        reason = _blender_reason(failure) or chatter.last_line() or "Blender could not read it"
        raise InputError(f"Asset file '{path}' cannot be read ({reason}); check that it is a valid "
                         f"'{suffix}' file, or export it again.") from None

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
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = mesh_from_object(obj, depsgraph)
    if not obj.material_slots or obj.material_slots[0].material is None:
        raise InputError(f"Object '{obj.name}' has no material; give it a Principled BSDF with image textures.")
    return mesh, maps_from_material(obj.material_slots[0].material)
