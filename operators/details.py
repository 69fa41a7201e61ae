"""Long text the panel shows short: a warning's label whose tooltip (and click) gives the whole sentence,
and Copy Details for the last job's error (its full text on the clipboard, to paste into a bug report)."""
import textwrap

import bpy
from bpy.props import StringProperty


class SCENEFIT_OT_show_details(bpy.types.Operator):
    """Show the whole message"""

    bl_idname = "scenefit.show_details"
    bl_label = "Details"
    bl_options = {"INTERNAL"}

    details: StringProperty(name="Details", options={"SKIP_SAVE"}, description="The whole message")

    @classmethod
    def description(cls, _context, properties) -> str:
        return properties.details or cls.__doc__

    def execute(self, context):
        lines = textwrap.wrap(self.details, 60) or [""]

        def draw(menu, _context):
            for line in lines:
                menu.layout.label(text=line, translate=False)

        context.window_manager.popup_menu(draw, title=bpy.app.translations.pgettext_iface("Details"), icon="INFO")
        return {"FINISHED"}


class SCENEFIT_OT_copy_details(bpy.types.Operator):
    """Copy what went wrong in the last job, in full, to the clipboard (to paste into a bug report)"""

    bl_idname = "scenefit.copy_details"
    bl_label = "Copy Details"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        if context.window_manager.scenefit_runtime.details:
            return True
        cls.poll_message_set("The last job ended without an error")
        return False

    def execute(self, context):
        context.window_manager.clipboard = context.window_manager.scenefit_runtime.details
        self.report({"INFO"}, "The error's details are on the clipboard")
        return {"FINISHED"}


classes = (SCENEFIT_OT_show_details, SCENEFIT_OT_copy_details)

register, unregister = bpy.utils.register_classes_factory(classes)
