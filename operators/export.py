"""Export to Mitsuba: the active object, its maps and a camera as a scene `mitsuba` renders alone."""
import bpy

from ..core.errors import SceneFitError
from .common import gather_asset, output_dir, poll_mesh


class SCENEFIT_OT_export_mitsuba(bpy.types.Operator):
    """Write the active object, its material maps and a camera as a Mitsuba 3 scene (XML, PLY, images)"""

    bl_idname = "scenefit.export_mitsuba"
    bl_label = "Export to Mitsuba"
    bl_options = {"REGISTER"}

    directory: bpy.props.StringProperty(name="Folder", subtype="DIR_PATH", default="",
                                        description="Where to write; empty uses the panel's output folder")

    @classmethod
    def poll(cls, context):
        return poll_mesh(context)

    def execute(self, context):
        import math

        from ..core.camera import Camera
        from ..core.export import export_mitsuba_scene  # Mitsuba starts only when asked for

        try:
            _, mesh, maps = gather_asset(context)
            out = bpy.path.abspath(self.directory) if self.directory else output_dir(context, "mitsuba")
            camera = Camera(azimuth_deg=30.0, elevation_deg=math.degrees(context.scene.scenefit.elevation),
                            width=512, height=512)
            xml = export_mitsuba_scene(mesh, maps, out, camera=camera)
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Mitsuba scene written to {xml}")
        return {"FINISHED"}


classes = (SCENEFIT_OT_export_mitsuba,)

register, unregister = bpy.utils.register_classes_factory(classes)
