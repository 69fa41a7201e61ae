"""Convert: SceneFit's neural texture from the asset's own maps (the selected objects, or the active object
with all its materials), as a background job."""
from __future__ import annotations

import bpy
from bpy.props import IntProperty

from ..workers import blender_jobs as work
from .asset import asset_layout
from .folders import run_folder
from .polls import OnMesh
from .jobs import JobOperator
from .results import apply_layout_results, materials_words, result_targets


class SCENEFIT_OT_convert(OnMesh, JobOperator):
    """Fit SceneFit's neural texture to the active object's material maps (Esc cancels)"""

    bl_idname = "scenefit.convert"
    bl_label = "Convert"
    job_name = "convert"
    records_runs = True

    iterations: IntProperty(name="Iterations", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                            description="For scripts and quick looks; 0 keeps the preset's")

    def prepare(self, context):
        layout = asset_layout(context)   # the selected objects, or the active one with all its materials
        self._object_name, self._layout = layout.name, result_targets(layout)
        out = run_folder(context, "convert", layout.name)
        # the maps are decoded in the job; procedural chains are baked between redraws before it starts
        # the run's settings as one frozen RunConfig; an iteration count is a quick look's stage override
        config = work.plain_config(preset=context.scene.scenefit.preset, stage_overrides=work.quick_overrides(self))
        data = {"config": config, "out": str(out), "asset": layout.plan(context)}
        if len(layout.materials) == 1:
            return work.convert, data
        # several materials: fitted as their atlas, then each baked in its own UVs for its slots
        return work.convert, dict(data, materials=layout.bake_data())

    def apply(self, context, result) -> str:
        mats = apply_layout_results(context, self._layout, result, "convert")
        return (f"Converted: {materials_words(mats)} "
                f"({result.numbers['psnr_db']:.1f} dB on the covered texels)")


classes = (SCENEFIT_OT_convert,)

register, unregister = bpy.utils.register_classes_factory(classes)
