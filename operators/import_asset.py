"""Import Asset: an asset file into the open scene, as File > Import does, including the files Blender's
own importers refuse and the command line reads (a meshopt-compressed glTF, an ASCII FBX): an artist
can bring into Blender every asset SceneFit reads. In File > Import and in the Asset section."""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy_extras.io_utils import ImportHelper

from ..core.base.errors import SceneFitError


class SCENEFIT_OT_import_asset(bpy.types.Operator, ImportHelper):
    """Import a glTF, FBX, OBJ, PLY or USD file into this scene, including meshopt-compressed glTF and
    ASCII FBX, which Blender's own importers refuse"""

    bl_idname = "scenefit.import_asset"
    bl_label = "Import Asset"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: bpy.props.StringProperty(default="*.glb;*.gltf;*.fbx;*.obj;*.ply;*.usd;*.usda;*.usdc;*.usdz",
                                          options={"HIDDEN"}, description="The kinds of file the browser lists")

    def execute(self, context):
        from ..blender_io.asset_file import import_into_open_scene

        path = Path(bpy.path.abspath(self.filepath))
        try:
            objects = import_into_open_scene(path)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        # Importers leave a rig (glTF) or the artist's object (FBX) active: the Asset section shows the new
        # asset, a mesh in view (not the glTF importer's hidden bone shapes) and selected where one is.
        shown = [o for o in objects if o.type == "MESH" and o.visible_get()]
        meshes = [o for o in shown if o.select_get()] or shown
        if meshes and context.view_layer.objects.active not in meshes:
            context.view_layer.objects.active = meshes[0]
        self.report({"INFO"}, f"Imported '{path.name}': {len(objects)} object(s), {len(meshes)} with a mesh")
        return {"FINISHED"}


def menu_entry(self, context) -> None:
    self.layout.operator(SCENEFIT_OT_import_asset.bl_idname, text="Asset for SceneFit (glTF, FBX, OBJ, ...)")


classes = (SCENEFIT_OT_import_asset,)
_register, _unregister = bpy.utils.register_classes_factory(classes)


def register() -> None:
    _register()
    bpy.types.TOPBAR_MT_file_import.append(menu_entry)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_import.remove(menu_entry)
    _unregister()
