"""Match Camera: the photo's camera estimated (its lines, EXIF) and SceneFit's camera made from it, with
what was found drawn over the photo behind the camera; the values go to the panel to correct."""
from __future__ import annotations

import math
from pathlib import Path

import bpy

from ..blender_io.compose import composite_scene, ensure_photo_camera, load_photo_image, object_base, settle
from ..blender_io.tag import TAG
from ..core.base.errors import InputError, SceneFitError
from ..core.scene.asset_pose import camera_for_placement
from .folders import keep_image, relative_if_saved, run_folder
from .photo import artist_camera, photo_path
from ..workers.blender_jobs import written_whole

OVERLAY_NAME = "SceneFit Camera Lines"


class SCENEFIT_OT_match_camera(bpy.types.Operator):
    """Estimate the photo's camera from its lines and EXIF, make SceneFit's camera from it and draw the lines
    and horizon found over the photo; the field of view, pitch and roll go to the panel, to correct"""

    bl_idname = "scenefit.match_camera"
    bl_label = "Match Camera"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from ..core.stages.camera import estimate_photo_camera

        settings = context.scene.scenefit
        try:
            photo = photo_path(context)
            camera, _ = artist_camera(context, photo)
            if camera is not None:
                raise InputError(f"The scene camera '{camera.name}' already shows the photo and SceneFit uses it as "
                                 "it is; make another camera active to match a new one.")
            estimate = estimate_photo_camera(photo)
            folder = run_folder(context, "camera", photo.stem)
            overlay = written_whole(str(folder), lambda out: {"lines": _write_overlay(estimate, out)})["lines"]
            cam = self._make_camera(context, photo, estimate, overlay)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        settings.fov, settings.pitch = math.radians(estimate.fov_deg), math.radians(estimate.pitch_deg)
        settings.roll, settings.camera_from = math.radians(estimate.roll_deg), "panel"
        found = ", ".join(f"{name} {getattr(estimate, f'{key}_deg'):.1f}° ({getattr(estimate, f'{key}_source')})"
                          for name, key in (("field of view", "fov"), ("pitch", "pitch"), ("roll", "roll")))
        fallback = "; the lines are weak, so some values are defaults" if estimate.fallback else ""
        self.report({"INFO"}, f"Camera '{cam.name}' matched: {found}{fallback}")
        return {"FINISHED"}

    def _make_camera(self, context, photo: Path, estimate, overlay: str):
        image = load_photo_image(photo)
        w, h = image.size
        camera = estimate.photo_camera(width=w, height=h)
        cam = ensure_photo_camera(context.scene, image, camera)
        obj = context.active_object
        if obj is not None and obj.type == "MESH":   # placed as Compose will place it, so the view is the same
            base, height = object_base(obj)
            settings = context.scene.scenefit
            cam.location = tuple(float(v) for v in camera_for_placement(
                base, height, tuple(settings.placement), settings.size, camera))
        lines = bpy.data.images.load(overlay, check_existing=False)
        lines.name = OVERLAY_NAME
        lines[TAG] = "camera"
        lines.filepath = relative_if_saved(overlay)
        keep_image(lines)
        data = cam.data
        for background in list(data.background_images):   # one overlay: the latest estimate's
            if background.image is not None and background.image.get(TAG) == "camera":
                data.background_images.remove(background)
        shown = data.background_images.new()
        shown.image, shown.alpha, shown.display_depth, shown.frame_method = lines, 1.0, "FRONT", "FIT"
        settle(composite_scene())
        return cam


def _write_overlay(estimate, folder: Path) -> str:
    from ..core.stages.camera_overlay import camera_overlay
    from ..core.data.imageio import write_image

    (folder / "camera.json").write_text(estimate.to_json(indent=2))
    return str(write_image(folder / "lines.png", camera_overlay(estimate)))


classes = (SCENEFIT_OT_match_camera,)

register, unregister = bpy.utils.register_classes_factory(classes)
