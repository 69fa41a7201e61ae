"""Pick Sun: three clicks in the photo — the foot of something upright on the floor, its top, the tip of
its shadow — give the sun's direction through the photo's camera (core/lighting/shadow_hint.py). The
Scene section's Sun becomes "As set here" with that azimuth and elevation, which the light stage then
centres its unseen light on (as `scenefit light --sun`). With EXEC_DEFAULT the three points are the
operator's properties (fractions of the photo, y from the top).
"""
from __future__ import annotations

import math
from dataclasses import replace

import bpy
from bpy.props import FloatVectorProperty

from ..blender_io.placement import CANCEL, CLICK, classify_event, placement_from_click
from ..core.errors import InputError, SceneFitError
from .common import artist_camera, composite_camera, photo_path, photo_view
from .placement import camera_frame_in_region, window_region

STEPS = ("foot", "top", "tip")
ASK = {"foot": "Click the foot of something upright on the floor (a post, a person, a table leg)",
       "top": "Click its top, straight above the foot",
       "tip": "Click the tip of its shadow on the floor"}


def sun_from_points(context, points: dict) -> tuple[float, float]:
    """(azimuth, elevation) in degrees from the three points (fractions of the photo), through the camera
    SceneFit composes with (the artist's when it shows the photo, else the panel's or the estimate)."""
    from ..core.imageio import upright_size
    from ..core.lighting.shadow_hint import sun_from_shadow

    photo = photo_path(context)
    view = photo_view(context, photo)
    size = upright_size(photo)
    if size is None:
        raise InputError(f"The photo '{photo}' cannot be read; choose another in the Scene section.")
    camera = replace(composite_camera(context, photo, view), width=size[0], height=size[1])
    foot, top, tip = ((points[k][0] * size[0], points[k][1] * size[1]) for k in STEPS)
    return sun_from_shadow(camera, foot, top, tip)


class SCENEFIT_OT_pick_sun(bpy.types.Operator):
    """Click the foot of something upright, its top and the tip of its shadow in the photo: the sun's direction
    for the light stage (Esc or right click cancels)"""

    bl_idname = "scenefit.pick_sun"
    bl_label = "Pick Sun"
    bl_options = {"REGISTER", "UNDO"}

    foot: FloatVectorProperty(name="Foot", size=2, min=0.0, max=1.0, default=(0.5, 0.8))
    top: FloatVectorProperty(name="Top", size=2, min=0.0, max=1.0, default=(0.5, 0.6))
    tip: FloatVectorProperty(name="Tip", size=2, min=0.0, max=1.0, default=(0.6, 0.85))

    def execute(self, context):
        try:
            azimuth, elevation = sun_from_points(context, {k: tuple(getattr(self, k)) for k in STEPS})
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        settings = context.scene.scenefit
        settings.sun_azimuth, settings.sun_elevation = math.radians(azimuth), math.radians(elevation)
        settings.sun_from = "set"
        self.report({"INFO"}, f"Sun from the shadow: azimuth {azimuth:.0f}°, elevation {elevation:.0f}°")
        return {"FINISHED"}

    def invoke(self, context, event):
        if context.area is None or context.area.type != "VIEW_3D":
            self.report({"ERROR"}, "Pick Sun works in a 3D Viewport; run it from the SceneFit panel there.")
            return {"CANCELLED"}
        try:
            photo = photo_path(context)
            if context.scene.camera is None or (artist_camera(context, photo)[0] is None
                                                and "scenefit" not in context.scene.camera):
                raise InputError("Pick Sun clicks in the photo seen through the camera: set it up first (Match "
                                 "Camera or Pick Placement), or make the camera that shows the photo active.")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        _, rv3d = window_region(context.area)
        if rv3d is None:
            self.report({"ERROR"}, "This 3D Viewport has no view to click in.")
            return {"CANCELLED"}
        self._view_before, self._points = rv3d.view_perspective, {}
        rv3d.view_perspective = "CAMERA"
        context.area.header_text_set(f"{ASK['foot']}; Esc or right click cancels")
        context.window.cursor_modal_set("CROSSHAIR")
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        action = classify_event(event.type, event.value)
        region, rv3d = window_region(context.area)
        if action == CANCEL:
            rv3d.view_perspective = self._view_before
            self._end(context)
            return {"CANCELLED"}
        if action != CLICK:
            return {"RUNNING_MODAL"} if event.type in ("LEFTMOUSE", "RIGHTMOUSE") else {"PASS_THROUGH"}
        rect = camera_frame_in_region(context.scene, region, rv3d)
        point = placement_from_click((event.mouse_x - region.x, event.mouse_y - region.y), rect) if rect else None
        if point is None:
            self.report({"WARNING"}, "Click inside the photo's frame.")
            return {"RUNNING_MODAL"}
        step = STEPS[len(self._points)]
        self._points[step] = point
        setattr(self, step, point)
        if len(self._points) < len(STEPS):
            context.area.header_text_set(f"{ASK[STEPS[len(self._points)]]}; Esc or right click cancels")
            return {"RUNNING_MODAL"}
        self._end(context)
        return self.execute(context)

    def cancel(self, context):
        self._end(context)

    def _end(self, context):
        if context.area is not None:
            context.area.header_text_set(None)
            context.area.tag_redraw()
        if context.window is not None:
            context.window.cursor_modal_restore()


classes = (SCENEFIT_OT_pick_sun,)

register, unregister = bpy.utils.register_classes_factory(classes)
