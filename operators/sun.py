"""Pick Sun: three clicks in the photo — the foot of something upright on the floor, its top, the tip of
its shadow — give the sun's direction through the photo's camera (core/stages/light/shadow_hint.py). The
Scene section's Sun becomes "As set here" with that azimuth and elevation, which the light stage then
centres its unseen light on (as `scenefit light --sun`). With EXEC_DEFAULT the three points are the
operator's properties (fractions of the photo, y from the top). Sun from Light does the same from a Sun
light the artist turned until its shadows on the asset match the photo's.
"""
from __future__ import annotations

import math
from dataclasses import replace

import bpy
from bpy.props import FloatVectorProperty

from ..core.base.errors import InputError, SceneFitError
from ..blender_io.tag import TAG
from .photo import artist_camera, composite_camera, photo_path, photo_view
from .placement import PhotoClicks

STEPS = ("foot", "top", "tip")
ASK = {"foot": "Click the foot of something upright on the floor (a post, a person, a table leg)",
       "top": "Click its top, straight above the foot",
       "tip": "Click the tip of its shadow on the floor"}


def sun_from_points(context, points: dict) -> tuple[float, float, float]:
    """(azimuth, elevation, uncertainty) in degrees from the three points (fractions of the photo), through
    the camera SceneFit composes with (the artist's when it shows the photo, else the panel's or the estimate)."""
    from ..core.data.imageio import upright_size
    from ..core.stages.light.shadow_hint import sun_from_shadow, sun_uncertainty_deg

    photo = photo_path(context)
    view = photo_view(context, photo)
    size = upright_size(photo)
    if size is None:
        raise InputError(f"The photo '{photo}' cannot be read; choose another in the Scene section.")
    camera = replace(composite_camera(context, photo, view), width=size[0], height=size[1])
    foot, top, tip = ((points[k][0] * size[0], points[k][1] * size[1]) for k in STEPS)
    return (*sun_from_shadow(camera, foot, top, tip), sun_uncertainty_deg(camera, foot, top, tip))


class SCENEFIT_OT_pick_sun(PhotoClicks, bpy.types.Operator):
    """Click the foot of something upright, its top and the tip of its shadow in the photo: the sun's direction
    for the light stage (Esc or right click cancels)"""

    bl_idname = "scenefit.pick_sun"
    bl_label = "Pick Sun"
    bl_options = {"REGISTER", "UNDO"}

    foot: FloatVectorProperty(name="Foot", size=2, min=0.0, max=1.0, default=(0.5, 0.8),
                              description="Where the thing casting the shadow meets the ground (fractions of the "
                                          "photo, y from the top)")
    top: FloatVectorProperty(name="Top", size=2, min=0.0, max=1.0, default=(0.5, 0.6),
                             description="The top of the thing casting the shadow (fractions of the photo)")
    tip: FloatVectorProperty(name="Tip", size=2, min=0.0, max=1.0, default=(0.6, 0.85),
                             description="The tip of its shadow on the ground (fractions of the photo)")

    def execute(self, context):
        try:
            azimuth, elevation, spread = sun_from_points(context, {k: tuple(getattr(self, k)) for k in STEPS})
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return set_sun(self, context, azimuth, elevation, "the shadow", spread)

    def invoke(self, context, event):
        self._points = {}
        return self.start_clicks(context, _check_camera, ASK["foot"])

    def clicked(self, context, point):
        step = STEPS[len(self._points)]
        self._points[step] = point
        setattr(self, step, point)
        if len(self._points) < len(STEPS):
            self.ask(context, ASK[STEPS[len(self._points)]])
            return None
        return self.execute(context)


def set_sun(op, context, azimuth: float, elevation: float, source: str, uncertainty: float = 0.0) -> set[str]:
    """The Scene section's Sun "As set here" at (azimuth, elevation) degrees, give or take `uncertainty`,
    said in the status bar."""
    from ..core.stages.light.cues import SUN_UNSURE_ADVICE, sun_is_unsure

    settings = context.scene.scenefit
    settings.sun_azimuth, settings.sun_elevation = math.radians(azimuth), math.radians(elevation)
    settings.sun_uncertainty = math.radians(min(uncertainty, 90.0))
    settings.sun_uncertainty_picked = uncertainty > 0.0   # (after: typing the angles resets only a pick's)
    settings.sun_from = "set"
    said = f"Sun from {source}: azimuth {azimuth:.0f}°, elevation {elevation:.0f}°"
    unsure = sun_is_unsure(uncertainty)
    if uncertainty > 0.0:
        said += f", ±{uncertainty:.0f}° for a slip of a click"
        if unsure:
            said += f" ({SUN_UNSURE_ADVICE}; the light hedges meanwhile)"
    op.report({"WARNING"} if unsure else {"INFO"}, said)   # (a warning shows in the status bar)
    return {"FINISHED"}


def _check_camera(context, why: str = "Pick Sun clicks in the photo seen through the camera"):
    """The camera that shows the photo: the artist's scene camera when it does, else SceneFit's (made by
    Match Camera or Pick Placement, in SceneFit's composite scene)."""
    from ..blender_io.compose import CAMERA_NAME

    photo = photo_path(context)
    camera = artist_camera(context, photo)[0]
    if camera is None:
        ours = bpy.data.objects.get(CAMERA_NAME)
        camera = ours if ours is not None and TAG in ours else None
    if camera is None:
        raise InputError(f"{why}: set it up first (Match Camera or Pick Placement), or make the camera that shows "
                         "the photo active.")
    return camera


def sun_lamp(context):
    """The Sun light the artist aimed: the active object when it is one, else the scene's only Sun light."""
    obj = context.active_object
    if obj is not None and obj.type == "LIGHT" and obj.data.type == "SUN":
        return obj
    suns = [o for o in context.scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    if len(suns) != 1:
        raise InputError("Select the Sun light whose shadows match the photo's" + (
            f" (the scene has {len(suns)})." if suns else "; add one (Add > Light > Sun) and turn it until they do."))
    return suns[0]


class SCENEFIT_OT_sun_from_lamp(bpy.types.Operator):
    """Take the sun's direction from a Sun light turned until its shadows match the photo's (the selected Sun
    light, or the scene's only one), seen from the camera that shows the photo"""

    bl_idname = "scenefit.sun_from_lamp"
    bl_label = "Sun from Light"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from mathutils import Vector

        from ..core.stages.light.shadow_hint import sun_deg_from_direction

        try:
            camera = _check_camera(context, "The sun's azimuth is measured from the camera that shows the photo")
            lamp = sun_lamp(context)
            towards = lamp.matrix_world.to_3x3() @ Vector((0.0, 0.0, 1.0))   # a Sun light shines along its -Z
            forward = camera.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
            azimuth, elevation = sun_deg_from_direction(tuple(towards), tuple(forward))
            if elevation <= 0.0:
                raise InputError(f"The Sun light '{lamp.name}' shines from {elevation:.0f}° below the horizon; turn "
                                 "it to shine down onto the scene.")
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return set_sun(self, context, azimuth, elevation, f"'{lamp.name}'")


classes = (SCENEFIT_OT_pick_sun, SCENEFIT_OT_sun_from_lamp)

register, unregister = bpy.utils.register_classes_factory(classes)
