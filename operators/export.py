"""Export to Mitsuba: the asset (the active object with every material, or the selected objects; several
materials as their atlas), its maps, and the photo's camera and estimated light when
SceneFit made them (else an orbit camera and a white environment), as a scene `mitsuba` renders alone."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import bpy

from ..blender_io.material import object_mesh_and_slots
from ..blender_io.compose import CAMERA_NAME
from ..core.base.errors import SceneFitError
from ..blender_io.tag import TAG
from .asset import asset_layout
from .dependencies import check_dependencies
from .folders import run_folder
from .photo import artist_camera, photo_path
from .polls import OnMesh
from ..workers.blender_jobs import written_whole


def photo_look_at(context):
    """The photo's camera as a LookAt in world space: SceneFit's, else the artist's camera that shows the
    photo; None when neither is set up."""
    from mathutils import Vector

    from ..core.render.export import LookAt

    cam = bpy.data.objects.get(CAMERA_NAME)
    if cam is None or cam.type != "CAMERA" or TAG not in cam:
        cam = None
        if context.scene.scenefit.photo_path:
            try:
                cam = artist_camera(context, photo_path(context))[0]
            except SceneFitError:
                cam = None
    if cam is None:
        return None
    m = cam.matrix_world
    origin = m.translation
    forward = (m.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    up = (m.to_3x3() @ Vector((0.0, 1.0, 0.0))).normalized()
    # The photo's frame: SceneFit's composite scene has the photo's resolution (the artist's scene keeps theirs).
    from ..blender_io.compose import SCENE_NAME

    own = bpy.data.scenes.get(SCENE_NAME)
    render = own.render if own is not None and TAG in own else context.scene.render
    return LookAt(origin=tuple(origin), target=tuple(origin + forward), up=tuple(up),
                  fov_deg=math.degrees(cam.data.angle_x), width=render.resolution_x, height=render.resolution_y)


class SCENEFIT_OT_export_mitsuba(OnMesh, bpy.types.Operator):
    """Write the asset (the active object, or the selected objects), its material maps, the photo's camera and
    the estimated light as a Mitsuba 3 scene (XML, PLY, images)"""

    bl_idname = "scenefit.export_mitsuba"
    bl_label = "Export to Mitsuba"
    bl_options = {"REGISTER"}

    directory: bpy.props.StringProperty(name="Folder", subtype="DIR_PATH", default="",
                                        description="Where to write; empty makes a new run folder")

    def execute(self, context):
        try:
            check_dependencies()
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        from ..core.render.orbit_camera import Camera
        from ..core.render.export import export_mitsuba_scene  # Mitsuba starts only when asked for
        from ..core.render.environment import load_environment

        settings = context.scene.scenefit
        try:
            # the asset as Run All takes it (every material, or the selection), as its slots show it; several
            # materials as their atlas, one shape, as `scenefit export` writes them
            layout = asset_layout(context)
            camera = photo_look_at(context)
            if camera is not None and len(layout.objects) == 1:   # the photo's camera sees the world
                obj = bpy.data.objects[layout.objects[0]]
                layout = replace(layout, mesh=object_mesh_and_slots(obj, context.evaluated_depsgraph_get(),
                                                                    space="world")[0])
            mesh, maps = layout.read(context, shown=True).fitting_view()
            if camera is None:
                camera = Camera(azimuth_deg=30.0, elevation_deg=-math.degrees(settings.pitch), width=512,
                                height=512)
            light = Path(bpy.path.abspath(settings.light_path)) if settings.light_path else None
            envmap = load_environment(light) if light is not None and light.is_file() else None
            if self.directory:
                xml = export_mitsuba_scene(mesh, maps, bpy.path.abspath(self.directory), camera=camera, envmap=envmap)
            else:  # a new run folder, written whole
                xml = written_whole(str(run_folder(context, "mitsuba", layout.name)), lambda folder: {
                    "xml": str(export_mitsuba_scene(mesh, maps, folder, camera=camera, envmap=envmap))})["xml"]
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        used = ", ".join(n for n, on in (("the photo's camera", camera.__class__.__name__ == "LookAt"),
                                          ("the estimated light", envmap is not None)) if on)
        self.report({"INFO"}, f"Mitsuba scene written to {xml}" + (f" (with {used})" if used else ""))
        return {"FINISHED"}


classes = (SCENEFIT_OT_export_mitsuba,)

register, unregister = bpy.utils.register_classes_factory(classes)
