"""Pick Placement: the photo behind SceneFit's camera, a click says where the asset stands.

Modal in the 3D viewport: the view goes into the camera, the click inside the photo's frame sets
the placement (a marker stays drawn there), Esc or a right click cancels and restores the view.
With EXEC_DEFAULT (scripts) the x, y properties set the placement directly.
"""
from __future__ import annotations

import bpy
from bpy.props import FloatProperty

from ..blender_io.compose import CAMERA_NAME, ensure_photo_camera, load_photo_image
from ..blender_io.placement import CANCEL, CLICK, classify_event, frame_rect, placement_from_click, \
    region_from_placement
from ..core.base.errors import InputError, SceneFitError
from .photo import artist_camera, composite_camera, photo_path, photo_view

_draw_handle = None


def window_region(area):
    """The viewport's drawing region and its view (the panel's own region has no view)."""
    region = next((r for r in area.regions if r.type == "WINDOW"), None)
    return region, (region.data if region is not None else None)


def viewed_camera(context):
    """The camera a 3D Viewport looks through: its own (local) camera when set, else the scene's."""
    space = context.space_data
    if space is not None and getattr(space, "type", "") == "VIEW_3D" and space.use_local_camera and space.camera:
        return space.camera
    return context.scene.camera


def camera_frame_in_region(scene, region, rv3d, cam=None):
    """(x_min, y_min, x_max, y_max) of the camera's (else the scene camera's) frame in the region, or None."""
    from bpy_extras.view3d_utils import location_3d_to_region_2d

    cam = cam if cam is not None else scene.camera
    if cam is None or region is None or rv3d is None:
        return None
    corners = [cam.matrix_world @ c for c in cam.data.view_frame(scene=scene)]
    points = [location_3d_to_region_2d(region, rv3d, c) for c in corners]
    if any(p is None for p in points):
        return None
    return frame_rect([(p.x, p.y) for p in points])


def draw_marker() -> None:
    """A cross where the asset stands, while looking through SceneFit's camera (not saved anywhere)."""
    context = bpy.context
    rv3d = context.region_data
    scene = context.scene
    cam = viewed_camera(context)
    if rv3d is None or rv3d.view_perspective != "CAMERA" or cam is None or \
            cam.name != CAMERA_NAME or not scene.scenefit.photo_path:
        return
    rect = camera_frame_in_region(scene, context.region, rv3d, cam)
    if rect is None:
        return
    import gpu
    from gpu_extras.batch import batch_for_shader

    x, y = region_from_placement(tuple(scene.scenefit.placement), rect)
    r = 12.0
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    batch = batch_for_shader(shader, "LINES", {"pos": [(x - r, y), (x + r, y), (x, y - r), (x, y + r)]})
    gpu.state.line_width_set(2.0)
    shader.uniform_float("color", (1.0, 0.35, 0.1, 1.0))
    batch.draw(shader)
    gpu.state.line_width_set(1.0)


class PhotoClicks:
    """Operator mixin: clicks in the photo seen through its camera, modal in a 3D Viewport. The view
    goes into the camera (SceneFit's as this viewport's own camera, so the scene camera stays the
    artist's); each left click inside the photo's frame is handed to `clicked(context, point)` (point:
    fractions of the photo, y from the top), which returns the operator's result when done or None for
    another click; Esc or a right click cancels and restores the view."""

    def start_clicks(self, context, prepare, first_prompt: str) -> set:
        """invoke's body: prepare(context) returns the camera showing the photo (or raises SceneFitError),
        then clicking begins."""
        if context.area is None or context.area.type != "VIEW_3D":
            self.report({"ERROR"}, f"{self.bl_label} works in a 3D Viewport; run it from the SceneFit panel there.")
            return {"CANCELLED"}
        try:
            camera = prepare(context)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        _, rv3d = window_region(context.area)
        if rv3d is None:
            self.report({"ERROR"}, "This 3D Viewport has no view to click in.")
            return {"CANCELLED"}
        space = context.space_data
        self._view_before = rv3d.view_perspective
        self._local_before = (space.use_local_camera, space.camera)
        if camera is not None and camera != context.scene.camera:
            space.use_local_camera, space.camera = True, camera
        rv3d.view_perspective = "CAMERA"
        self.ask(context, first_prompt)
        context.window.cursor_modal_set("CROSSHAIR")
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def ask(self, context, prompt: str) -> None:
        context.area.header_text_set(f"{prompt}; Esc or right click cancels")

    def modal(self, context, event):
        action = classify_event(event.type, event.value)
        region, rv3d = window_region(context.area)
        if action == CANCEL:
            rv3d.view_perspective = self._view_before
            self._end(context)
            return {"CANCELLED"}
        if action != CLICK:
            return {"RUNNING_MODAL"} if event.type in ("LEFTMOUSE", "RIGHTMOUSE") else {"PASS_THROUGH"}
        # The click is in window coordinates; the frame is in the viewport region's.
        mouse = (event.mouse_x - region.x, event.mouse_y - region.y)
        rect = camera_frame_in_region(context.scene, region, rv3d, viewed_camera(context))
        point = placement_from_click(mouse, rect) if rect is not None else None
        if point is None:
            self.report({"WARNING"}, "Click inside the photo's frame.")
            return {"RUNNING_MODAL"}
        result = self.clicked(context, point)
        if result is None:
            return {"RUNNING_MODAL"}
        self._end(context)
        return result

    def cancel(self, context):
        self._end(context)

    def _end(self, context):
        before = getattr(self, "_local_before", None)
        space = context.space_data
        if before is not None and space is not None and getattr(space, "type", "") == "VIEW_3D":
            space.use_local_camera, space.camera = before
            self._local_before = None
        if context.area is not None:
            context.area.header_text_set(None)
            context.area.tag_redraw()
        if context.window is not None:
            context.window.cursor_modal_restore()


class SCENEFIT_OT_pick_placement(PhotoClicks, bpy.types.Operator):
    """Show the photo through SceneFit's camera and click where the asset stands (Esc or right click cancels)"""

    bl_idname = "scenefit.pick_placement"
    bl_label = "Pick Placement"
    bl_options = {"REGISTER", "UNDO"}

    x: FloatProperty(name="X", min=0.0, max=1.0, default=0.5, description="From the left, fraction of the width")
    y: FloatProperty(name="Y", min=0.0, max=1.0, default=0.75, description="From the top, fraction of the height")

    def _camera(self, context):
        photo = photo_path(context)
        artist, _ = artist_camera(context, photo)
        if artist is not None:
            raise InputError(f"The scene camera '{artist.name}' shows the photo, so SceneFit composes the asset where "
                             "it stands in that camera's view; move the asset instead of picking a point.")
        camera = composite_camera(context, photo, photo_view(context, photo))
        return ensure_photo_camera(context.scene, load_photo_image(photo), camera)

    def execute(self, context):
        try:
            self._camera(context)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        context.scene.scenefit.placement = (self.x, self.y)
        return {"FINISHED"}

    def invoke(self, context, event):
        return self.start_clicks(context, self._camera, "Click where the asset stands in the photo")

    def clicked(self, context, point):
        self.x, self.y = point
        context.scene.scenefit.placement = point
        self.report({"INFO"}, f"Placement {point[0]:.3f}, {point[1]:.3f}")
        return {"FINISHED"}


classes = (SCENEFIT_OT_pick_placement,)


def register() -> None:
    global _draw_handle
    for cls in classes:
        bpy.utils.register_class(cls)
    _draw_handle = bpy.types.SpaceView3D.draw_handler_add(draw_marker, (), "WINDOW", "POST_PIXEL")


def unregister() -> None:
    global _draw_handle
    if _draw_handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_draw_handle, "WINDOW")
        _draw_handle = None
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
