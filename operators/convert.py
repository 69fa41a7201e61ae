"""Convert: fit SceneFit's neural texture to the active object's own maps, as a background job."""
from __future__ import annotations

import bpy
from bpy.props import IntProperty

from . import work
from .common import OnMesh, gather_asset, run_folder
from .jobs import JobOperator
from .results import apply_result_material


class SCENEFIT_OT_convert(OnMesh, JobOperator):
    """Fit SceneFit's neural texture to the active object's material maps (Esc cancels)"""

    bl_idname = "scenefit.convert"
    bl_label = "Convert"
    job_name = "convert"

    iterations: IntProperty(name="Iterations", default=0, min=0, options={"SKIP_SAVE"},
                            description="For scripts and quick looks; 0 keeps the preset's")

    def prepare(self, context):
        obj, mesh, maps = gather_asset(context)
        self._object_name = obj.name
        out = run_folder(context, "convert", obj.name)
        return work.convert, {"mesh": mesh, "maps": maps, "preset": context.scene.scenefit.preset,
                              "iterations": self.iterations, "out": str(out)}

    def apply(self, context, result) -> str:
        mat = apply_result_material(context, self._object_name, result, "convert")
        return f"Converted: material '{mat.name}' ({result['psnr_db']:.1f} dB on the covered texels)"


classes = (SCENEFIT_OT_convert,)

register, unregister = bpy.utils.register_classes_factory(classes)
