"""Results written back into Blender as NEW datablocks, and switching between them and the originals.

Every material, World and image SceneFit makes is tagged `["scenefit"] = <stage>`; the artist's own
are never modified (they get a fake user while replaced, so saving keeps them). Images refer to
files in the run folder next to the .blend ('//' paths), or are packed when the file is unsaved.
"""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import EnumProperty

from ..blender_io import write_result_material
from ..blender_io.world import assign_world, world_from_hdr
from ..core.errors import InputError
from .common import keep_image, needs_setting, relative_if_saved

TAG = "scenefit"


def _settle_image(image, stage: str) -> None:
    image[TAG] = stage
    image.filepath = relative_if_saved(bpy.path.abspath(image.filepath))
    keep_image(image)


def material_images(material) -> list:
    tree = material.node_tree
    return [n.image for n in tree.nodes if n.type in ("TEX_IMAGE", "TEX_ENVIRONMENT") and n.image] if tree else []


def apply_result_material(context, object_name: str, result: dict, stage: str):
    """A new material from result['maps'] on the object; the artist's material is kept as the original."""
    settings = context.scene.scenefit
    obj = bpy.data.objects.get(object_name)
    if obj is None:
        raise InputError(f"The object '{object_name}' was deleted while SceneFit ran; the maps are in "
                         f"'{Path(result['report']).parent}'.")
    current = obj.active_material
    if current is not None and TAG not in current:
        settings.original_material = current  # the artist's own, never one SceneFit made
    mat = write_result_material(obj, result["maps"], name=f"{obj.name} SceneFit {stage}")
    mat[TAG] = stage
    for image in material_images(mat):
        _settle_image(image, stage)
    settings.result_material, settings.result_object = mat, obj
    if result.get("texture"):
        settings.texture_path = relative_if_saved(result["texture"])
    return mat


def apply_result_world(context, hdr_path: str, stage: str = "light"):
    """A new World lit by the HDR map (rotation and strength editable); the artist's World is kept."""
    scene = context.scene
    settings = scene.scenefit
    world = world_from_hdr(hdr_path, name="SceneFit Light")
    world[TAG] = stage
    for node in world.node_tree.nodes:
        if node.type == "TEX_ENVIRONMENT" and node.image is not None:
            _settle_image(node.image, stage)
    if scene.world is not None and TAG not in scene.world:
        settings.original_world = scene.world
    assign_world(scene, world)
    settings.result_world = world
    settings.light_path = relative_if_saved(hdr_path)
    return world


def apply_composite_image(context, path: str, stage: str):
    """The composite render as an image (tagged, kept like every result image) and the panel's path to it."""
    image = bpy.data.images.load(str(Path(path).resolve()), check_existing=False)
    image.name = "SceneFit Composite"
    image.use_fake_user = True  # no material uses it: without a user, saving would drop it
    _settle_image(image, stage)
    context.scene.scenefit.composite_path = relative_if_saved(path)
    return image


class SCENEFIT_OT_use_result(bpy.types.Operator):
    """Switch the asset's material or the scene's World between SceneFit's result and the original"""

    bl_idname = "scenefit.use_result"
    bl_label = "Use Result"
    bl_options = {"REGISTER", "UNDO"}

    target: EnumProperty(items=(("MATERIAL", "Material", ""), ("WORLD", "World", "")), default="MATERIAL")
    which: EnumProperty(items=(("RESULT", "SceneFit", "SceneFit's result"), ("ORIGINAL", "Original", "The artist's")),
                        default="RESULT")

    def execute(self, context):
        settings = context.scene.scenefit
        if self.target == "WORLD":
            world = settings.result_world if self.which == "RESULT" else settings.original_world
            if world is None:
                self.report({"ERROR"}, "There is no such World; estimate the light first.")
                return {"CANCELLED"}
            assign_world(context.scene, world)
            return {"FINISHED"}
        obj = settings.result_object
        mat = settings.result_material if self.which == "RESULT" else settings.original_material
        if obj is None or mat is None:
            self.report({"ERROR"}, "There is no such material; convert or adapt the asset first.")
            return {"CANCELLED"}
        if obj.active_material is not None:
            obj.active_material.use_fake_user = True  # whichever is swapped out survives saving
        obj.active_material = mat
        return {"FINISHED"}


class SCENEFIT_OT_open_composite(bpy.types.Operator):
    """Open the last composite in an Image Editor (or load it as an image)"""

    poll = needs_setting("composite_path")  # there is a composite to open
    bl_idname = "scenefit.open_composite"
    bl_label = "Open Composite"
    bl_options = {"REGISTER"}

    def execute(self, context):
        path = Path(bpy.path.abspath(context.scene.scenefit.composite_path))
        if not path.is_file():
            self.report({"ERROR"}, f"The composite '{path}' is gone; compose again.")
            return {"CANCELLED"}
        image = bpy.data.images.load(str(path), check_existing=True)
        image.reload()
        for area in context.screen.areas if context.screen else ():
            if area.type == "IMAGE_EDITOR":
                area.spaces.active.image = image
                break
        else:
            if context.window is not None and not bpy.app.background:
                bpy.ops.render.view_show("INVOKE_DEFAULT")
                for area in context.window_manager.windows[-1].screen.areas:
                    if area.type == "IMAGE_EDITOR":
                        area.spaces.active.image = image
        return {"FINISHED"}


classes = (SCENEFIT_OT_use_result, SCENEFIT_OT_open_composite)

register, unregister = bpy.utils.register_classes_factory(classes)
