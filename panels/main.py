"""The SceneFit N-panel in the 3D viewport: Asset, Scene, Style, Quality, Run, Results.

Drawing only reads: the material summary looks at node links (no pixels), the dependency check
asks importlib where modules are (once), the photo's thumbnail and size were read when it was chosen,
and runtime state comes from the WindowManager. Labels built in code go through Blender's translation
(iface_ with str.format, never an f-string); long sentences are short labels whose tooltip says it all.
"""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.app.translations import pgettext_iface as iface_

from ..core.base.errors import SceneFitError
from ..operators.asset import asset_objects, flat_parts
from ..operators.dependencies import dependency_sentence, missing_modules
from ..operators.photo import artist_camera
from .quality import BENCH_MACHINE, EXPECTED_SECONDS, adapt_projection, duration_text, expected_line
from .thumbnail import thumbnail


def warning(layout, short: str, details: str, icon: str = "ERROR") -> None:
    """A short label whose tooltip (and click) gives the whole sentence, which a sidebar would cut off."""
    op = layout.operator("scenefit.show_details", text=short, icon=icon, emboss=False, translate=False)
    op.details = details


class _Section:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "SceneFit"


class _Subsection(_Section):
    bl_parent_id = "SCENEFIT_PT_main"


def settings_column(panel, context):
    """The scene's SceneFit settings and a column to draw them in, labels on the left as Blender's own
    property panels have them."""
    panel.layout.use_property_split = True
    panel.layout.use_property_decorate = False
    return context.scene.scenefit, panel.layout.column()


class SCENEFIT_PT_main(_Section, bpy.types.Panel):
    bl_idname = "SCENEFIT_PT_main"
    bl_label = "SceneFit"

    def draw(self, context):
        layout = self.layout
        sentence = dependency_sentence()
        if sentence:
            warning(layout, iface_("Modules missing"), sentence)
        rt = context.window_manager.scenefit_runtime
        if rt.running or rt.status:
            box = layout.box()
            if rt.running:
                row = box.row(align=True)
                row.progress(factor=rt.progress, type="BAR", text=rt.status)
                row.operator("scenefit.cancel_job", text="", icon="X")
            else:
                row = box.row(align=True)
                row.label(text=rt.status, translate=False)
                if rt.details:
                    row.operator("scenefit.copy_details", text="", icon="COPYDOWN")
            if rt.has_preview:
                from ..operators.jobs import PREVIEW_IMAGE, preview_icon_id

                box.template_icon(icon_value=preview_icon_id(), scale=8.0)
                warning(box, PREVIEW_IMAGE, iface_("The latest preview is the image '{}': open it in an Image Editor "
                                                   "to see it larger").format(PREVIEW_IMAGE), icon="IMAGE_DATA")
        if not bpy.data.is_saved:
            warning(layout, iface_("Unsaved file"), iface_("Results are packed into the unsaved file; save it first "
                                                           "to keep them as files beside it."), icon="INFO")


class SCENEFIT_PT_asset(_Subsection, bpy.types.Panel):
    bl_label = "Asset"

    def draw(self, context):
        from ..blender_io.material import material_summary

        layout = self.layout
        obj = context.active_object
        if obj is None or obj.type != "MESH":
            row = layout.row()
            row.label(text="Select a mesh object.", icon="INFO")
            row.operator("scenefit.import_asset", text="", icon="IMPORT")
            return
        row = layout.row()
        row.label(text=obj.name, icon="OBJECT_DATA", translate=False)
        row.operator("scenefit.import_asset", text="", icon="IMPORT")
        objects = asset_objects(context)
        if len(objects) > 1:   # what Run All, Convert, Adapt, Compose and Bake Asset will take
            layout.label(text=iface_("{} objects, one asset").format(len(objects)), icon="GROUP")
            for name, ratio in flat_parts(objects):   # said before Run All refuses the whole selection
                shape = iface_("flat") if ratio > 1000 else iface_("{:.0f} times as wide as tall").format(ratio)
                warning(layout, iface_("'{}' is flat").format(name),
                        iface_("'{}' is {} (a ground plane?): deselect it to fit the rest").format(name, shape))
        try:
            found, dropped = material_summary(obj.active_material)
        except SceneFitError as error:
            warning(layout, iface_("Material not readable"), str(error))
            return
        col = layout.column(align=True)
        for line in found:
            col.label(text=line, icon="CHECKMARK")
        if dropped:
            warning(col, iface_("{} inputs dropped").format(len(dropped)),
                    iface_("Not read: {}").format(", ".join(dropped)), icon="TRASH")
        if not obj.data.uv_layers:
            warning(layout, iface_("No UV map"), iface_("The mesh has no UV map: unwrap it first "
                                                        "(UV > Smart UV Project)."))
            layout.operator("scenefit.add_uv_map", icon="UV")


class SCENEFIT_PT_scene(_Subsection, bpy.types.Panel):
    bl_label = "Scene"

    def draw(self, context):
        settings, col = settings_column(self, context)
        col.prop(settings, "photo_path")
        preview = thumbnail(settings.photo_path)   # read when the photo was chosen
        if preview is not None:
            col.template_icon(icon_value=preview.icon_id, scale=6.0)
        row = col.row(align=True)
        row.prop(settings, "placement")
        row.operator("scenefit.pick_placement", text="", icon="EYEDROPPER")
        col.prop(settings, "size")
        col.prop(settings, "turn")
        col.prop(settings, "scene_type")
        draw_camera(settings, context, self.layout.column(align=True))
        draw_choice(self.layout.column(align=True), settings, "sun_from", "Sun", "scenefit.pick_sun", "EYEDROPPER",
                    ("sun_azimuth", "sun_elevation", "sun_uncertainty") if settings.sun_from == "set" else (),
                    more=(("scenefit.sun_from_lamp", "OUTLINER_OB_LIGHT"),))


def draw_camera(settings, context, col) -> None:
    """The photo's camera: the artist's when the scene camera shows the photo, else estimated or set here."""
    camera = None
    if settings.photo_path:
        try:
            camera = artist_camera(context, Path(bpy.path.abspath(settings.photo_path)), read=False)[0]
        except SceneFitError:
            camera = None
    if camera is not None:
        warning(col, iface_("Camera: {}").format(camera.name),
                iface_("The scene camera '{}' shows the photo: the asset is composed where it stands in its "
                       "view").format(camera.name), icon="CAMERA_DATA")
        return
    draw_choice(col, settings, "camera_from", "Camera", "scenefit.match_camera", "VIEW_CAMERA",
                ("fov", "pitch", "roll") if settings.camera_from == "panel" else ())


def draw_choice(col, settings, choice: str, label: str, operator: str, icon: str, values: tuple[str, ...],
                more: tuple[tuple[str, str], ...] = ()) -> None:
    """A source choice with the buttons that find it, then the values it leaves to set by hand."""
    row = col.row(align=True)
    row.prop(settings, choice, text=label)
    for name, symbol in ((operator, icon), *more):
        row.operator(name, text="", icon=symbol)
    for name in values:
        col.prop(settings, name)


class SCENEFIT_PT_style(_Subsection, bpy.types.Panel):
    bl_label = "Style"

    def draw(self, context):
        settings, col = settings_column(self, context)
        col.prop(settings, "mode", expand=True)
        col.prop(settings, "object_prompt")
        col.prop(settings, "scene_prompt")
        col.operator("scenefit.generate_prompt", icon="FILE_TEXT")
        col.prop(settings, "instruction" if settings.mode == "edit" else "prompt")
        col.prop(settings, "negative_prompt")
        col.prop(settings, "seed")
        if settings.prompt_source:
            col.label(text=settings.prompt_source, icon="INFO")


class SCENEFIT_PT_quality(_Subsection, bpy.types.Panel):
    bl_label = "Quality"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        settings, col = settings_column(self, context)
        col.prop(settings, "preset", expand=True)
        col.prop(settings, "output_dir")
        sub = col.column(align=True)
        measured = iface_("(the example asset on a {})").format(BENCH_MACHINE)
        for stage in EXPECTED_SECONDS:
            sub.label(text=expected_line(stage, settings.preset))
        # adapt's line names two machines: short here, the whole of it and where it was measured in the tooltip
        cpu = adapt_projection(settings.preset)
        short = (iface_("adapt: about {} on a CPU").format(duration_text(cpu)) if cpu is not None
                 else expected_line("adapt", settings.preset))
        warning(sub, short, "{} {}".format(expected_line("adapt", settings.preset), measured), icon="TIME")


class SCENEFIT_PT_run(_Subsection, bpy.types.Panel):
    bl_label = "Run"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split, layout.use_property_decorate = True, False
        layout.prop(context.scene.scenefit, "guidance")
        layout.operator("scenefit.run", icon="PLAY")
        col = layout.column(align=True)
        col.operator("scenefit.convert", icon="TEXTURE")
        col.operator("scenefit.estimate_light", icon="WORLD")
        col.operator("scenefit.adapt", icon="BRUSH_DATA")
        col.operator("scenefit.compose", icon="RENDER_STILL")
        layout.operator("scenefit.export_mitsuba", icon="EXPORT")


def draw_switch(layout, label: str, target: str) -> None:
    """Buttons that switch `target` (MATERIAL or WORLD) between SceneFit's result and the artist's original."""
    row = layout.row(align=True)
    row.label(text=label)
    for text, which in (("SceneFit", "RESULT"), ("Original", "ORIGINAL")):
        op = row.operator("scenefit.use_result", text=text)
        op.target, op.which = target, which


class SCENEFIT_PT_results(_Subsection, bpy.types.Panel):
    bl_label = "Results"

    def draw(self, context):
        from ..blender_io.world import world_controls

        settings = context.scene.scenefit
        layout = self.layout
        layout.operator("scenefit.open_composite", icon="IMAGE")
        row = layout.row(align=True)
        row.operator("scenefit.bake_asset", text=iface_("Bake Asset…"), icon="EXPORT")   # a file browser
        row.operator("scenefit.open_bake_folder", text="", icon="FILE_FOLDER")
        for label, target, result in (("Material", "MATERIAL", settings.result_material),
                                      ("World", "WORLD", settings.result_world)):
            if result is not None:
                draw_switch(layout, label, target)
        if settings.result_world is not None:
            mapping, background = world_controls(settings.result_world)
            if mapping is not None:
                layout.prop(mapping.inputs["Rotation"], "default_value", index=2, text="Light rotation")
            if background is not None:
                layout.prop(background.inputs["Strength"], "default_value", text="Light strength")
        draw_runs(layout, context)


RUN_STATE_ICONS = {"finished": "CHECKMARK", "cancelled": "PAUSE", "failed": "ERROR"}


class SCENEFIT_UL_runs(bpy.types.UIList):
    """The active asset's runs: the composite's thumbnail, what made it, when, and how it ended."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_property, index=0, flt_flag=0):
        preview = item.composite.preview if item.composite is not None else None   # made when the run ended
        row = layout.row(align=True)
        if preview is not None:
            row.label(text="", icon_value=preview.icon_id)
        else:
            row.label(text="", icon="RENDER_RESULT")
        state = "cancelled, resumable" if item.state == "cancelled" and item.stage == "adapt" else item.state
        row.label(text="{} · {} · {}".format(iface_(item.stage), iface_(item.preset), item.when), translate=False)
        row.label(text=iface_(state), icon=RUN_STATE_ICONS.get(item.state, "NONE"), translate=False)


def draw_runs(layout, context) -> None:
    """The active asset's run history and what can be done with the chosen run."""
    from ..operators.asset import asset_owner

    owner = asset_owner(context.scene)
    if owner is None or not owner.scenefit_asset.runs:
        return
    state = owner.scenefit_asset
    layout.label(text=iface_("Runs of '{}'").format(owner.name), translate=False)
    layout.template_list("SCENEFIT_UL_runs", "", state, "runs", state, "run_index", rows=3)
    if not 0 <= state.run_index < len(state.runs):
        return
    run = state.runs[state.run_index]
    if run.prompt:
        warning(layout, run.prompt, run.prompt, icon="TEXT")
    row = layout.row(align=True)
    row.operator("scenefit.apply_run", text="Apply", icon="CHECKMARK").index = state.run_index
    row.operator("scenefit.compare_run", text="Compare", icon="SPLIT_HORIZONTAL").index = state.run_index
    row.operator("scenefit.open_run_folder", text="", icon="FILE_FOLDER").index = state.run_index
    if run.stage in ("run", "adapt") and run.state != "finished":   # (operators/history.RESUMABLE)
        row.operator("scenefit.resume_run", text="Resume", icon="PLAY").index = state.run_index
    row.operator("scenefit.delete_run", text="", icon="X").index = state.run_index
    op = row.operator("scenefit.delete_run", text="", icon="TRASH")
    op.index, op.folder = state.run_index, True


classes = (SCENEFIT_UL_runs, SCENEFIT_PT_main, SCENEFIT_PT_asset, SCENEFIT_PT_scene, SCENEFIT_PT_style, SCENEFIT_PT_quality,
           SCENEFIT_PT_run, SCENEFIT_PT_results)

__all__ = ["classes", "dependency_sentence", "missing_modules"]
