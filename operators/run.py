"""Run: every stage in one background job (convert -> light -> adapt), then the composite set up."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty, IntProperty

from ..blender_io.compose import setup_composite
from ..core.errors import SceneFitError
from . import work
from .adapt import gather_adapt
from .common import photo_path, poll_mesh
from .convert import SCENEFIT_OT_convert
from .jobs import JobOperator
from .light import SCENEFIT_OT_estimate_light
from .results import apply_result_material, apply_result_world


class SCENEFIT_OT_run(JobOperator):
    """Run the whole pipeline on the active object: convert, estimate the light (with a photo), adapt (with a
    prompt and the diffusion models), then set up the composite"""

    bl_idname = "scenefit.run"
    bl_label = "Run All"
    job_name = "run"
    runs_remotely = True

    # Passed to every stage (quick looks and scripts); 0 / auto keep the presets' values.
    iterations: IntProperty(name="Iterations", default=0, min=0, options={"SKIP_SAVE"})
    model_resolution: IntProperty(name="Model resolution", default=0, min=0, options={"SKIP_SAVE"})
    render_size: IntProperty(name="Render size", default=0, min=0, options={"SKIP_SAVE"})
    critic: SCENEFIT_OT_estimate_light.__annotations__["critic"]
    outpaint: SCENEFIT_OT_estimate_light.__annotations__["outpaint"]

    @classmethod
    def poll(cls, context):
        return poll_mesh(context)

    def prepare(self, context):
        settings = context.scene.scenefit
        # The stages' own prepare() gather their inputs and make their run folders (defaults only).
        _, convert_data = SCENEFIT_OT_convert.prepare(self, context)
        data = {"convert": convert_data}
        if settings.photo_path:
            _, data["light"] = SCENEFIT_OT_estimate_light.prepare(self, context)
        if settings.prompt or settings.mode == "edit":
            data["adapt"] = gather_adapt(self, context, texture="")  # the worker passes convert's texture
        return work.run_all, data

    def apply(self, context, result) -> str:
        lines = []
        mat = apply_result_material(context, self._object_name, result["convert"], "convert")
        if "adapt" in result:
            mat = apply_result_material(context, self._object_name, result["adapt"], "adapt")
        lines.append(f"material '{mat.name}'")
        if "light" in result:
            world = apply_result_world(context, result["light"]["hdr"])
            lines.append(f"World '{world.name}'")
            obj = bpy.data.objects.get(self._object_name)
            settings = context.scene.scenefit
            if obj is not None:
                try:
                    setup_composite(context, obj, photo_path(context), tuple(settings.placement), settings.size,
                                    settings.fov, settings.elevation)
                    lines.append("composite set up (F12 renders it)")
                except SceneFitError as error:
                    lines.append(f"no composite: {error}")
        if "adapt_skipped" in result:
            lines.append(result["adapt_skipped"])
        return "Done: " + "; ".join(lines)


classes = (SCENEFIT_OT_run,)

register, unregister = bpy.utils.register_classes_factory(classes)
