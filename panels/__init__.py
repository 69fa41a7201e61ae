"""The SceneFit N-panel in the 3D viewport and the add-on preferences."""
import bpy
from bpy.props import BoolProperty, StringProperty

# The add-on's own module name: `bl_ext.<repo>.scenefit` installed, `scenefit` in development.
ADDON_PACKAGE = __package__.rpartition(".")[0]


class SceneFitPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_PACKAGE

    model_cache: StringProperty(name="Model cache", subtype="DIR_PATH", default="",
                                description="Folder for downloaded diffusion models (empty: the Hugging Face default)")
    offline: BoolProperty(name="Offline", default=False,
                          description="Never use the network: models must already be in the cache")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "model_cache")
        layout.prop(self, "offline")


class SCENEFIT_PT_main(bpy.types.Panel):
    bl_idname = "SCENEFIT_PT_main"
    bl_label = "SceneFit"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "SceneFit"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.scenefit
        col = layout.column()
        col.prop(settings, "photo_path")
        col.prop(settings, "placement")
        col.prop(settings, "elevation")
        col.prop(settings, "preset")
        col.prop(settings, "output_dir")
        col.separator()
        col.operator("scenefit.convert", icon="TEXTURE")
        col.operator("scenefit.export_mitsuba", icon="EXPORT")
        if settings.status:
            box = layout.box()
            box.prop(settings, "progress", slider=True)
            box.label(text=settings.status)


classes = (SceneFitPreferences, SCENEFIT_PT_main)

register, unregister = bpy.utils.register_classes_factory(classes)
