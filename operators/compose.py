"""Compose: the asset in the photo, set up in Blender so that F12 in Cycles renders the composite."""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import BoolProperty, IntProperty

from ..blender_io.compose import setup_composite
from ..core.base.errors import SceneFitError
from .asset import asset_objects
from .folders import run_folder
from .photo import composite_camera, photo_path, photo_view
from .polls import OnMesh
from .results import apply_composite_image
from ..workers.blender_jobs import written_whole


class SCENEFIT_OT_compose(OnMesh, bpy.types.Operator):
    """Set up the composite in SceneFit's own scene ("SceneFit Composite": a camera matched to the photo,
    the photo behind the render, a shadow-catcher floor, the asset linked, lit by the estimated World when
    there is one) and render it there; your scene's settings, camera and compositor stay as they are"""

    bl_idname = "scenefit.compose"
    bl_label = "Compose"
    bl_options = {"REGISTER", "UNDO"}

    render: BoolProperty(name="Render", default=True,
                         description="Render the composite now and save it in a new run folder")
    samples: IntProperty(name="Samples", default=0, min=0, options={"SKIP_SAVE"},
                         description="Cycles samples for this render (0: the scene's own setting)")

    def execute(self, context):
        settings = context.scene.scenefit
        try:
            # the asset as Run All takes it: the selected objects, or the active one
            objects = asset_objects(context)
            photo = photo_path(context)
            view = photo_view(context, photo, objects)
            scene_camera = bpy.data.objects.get(view["scene_camera"]) if view["scene_camera"] else None
            made = setup_composite(context, objects, photo, tuple(settings.placement), settings.size,
                                   composite_camera(context, photo, view), scene_camera=scene_camera,
                                   world=settings.result_world)
            own = made["scene"]
            if not self.render:
                self.report({"INFO"}, f"Composite set up in the scene '{own.name}' with '{made['camera'].name}': "
                                      "F12 there renders it")
                return {"FINISHED"}
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if context.window is not None and not bpy.app.background:
            # In the UI Blender's own render job runs it (progress, Esc); the artist saves it from there.
            bpy.ops.render.render("INVOKE_DEFAULT", scene=own.name)
            return {"FINISHED"}
        try:
            active = context.active_object
            folder = run_folder(context, "compose", (active if active in objects else objects[0]).name)
            out = written_whole(str(folder), lambda staging: {"composite": self._render(own, staging)})["composite"]
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        apply_composite_image(context, out, "compose")
        self.report({"INFO"}, f"Composite rendered: {out}")
        return {"FINISHED"}

    def _render(self, scene, folder: Path) -> str:
        """F12 of the composite scene with write_still into `folder`, its samples and output put back after."""
        out = folder / "composite.png"
        settings = scene.render.image_settings
        before = scene.cycles.samples, scene.render.filepath, settings.file_format
        try:
            if self.samples:
                scene.cycles.samples = self.samples
            scene.render.filepath = str(out)
            settings.file_format = "PNG"
            bpy.ops.render.render(write_still=True, scene=scene.name)
        finally:
            scene.cycles.samples, scene.render.filepath, settings.file_format = before
        return str(out)


classes = (SCENEFIT_OT_compose,)

register, unregister = bpy.utils.register_classes_factory(classes)
