"""Run: the command line's pipeline (core.run.run_pipeline) as one background job, then its results
applied in Blender: the new material, the World, the composite set up for Cycles and its image."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import bpy
from bpy.props import EnumProperty, StringProperty

from ..blender_io.compose import photo_read_whole, setup_composite
from ..core.base.errors import InputError, SceneFitError
from ..workers import blender_jobs as work
from ..workers.job_seam import RunInputs, RunOutcome, RunRequest
from .adapt import adapt_seconds_here
from .folders import last_finished_run
from .identity import object_by_id
from .polls import OnMeshWithPhoto
from .jobs import CHOICES, CostFirst, JobOperator
from .properties import GUIDANCE
from .results import apply_composite_image, apply_layout_results, apply_result_world, materials_words
from .run_request import gather_run, resumed_run

if TYPE_CHECKING:
    from ..workers.time_model import LocalWork



class SCENEFIT_OT_run(OnMeshWithPhoto, CostFirst, JobOperator):
    """Fit the asset into the photo in one go (the selected objects, or the active one with all its
    materials): convert, estimate the photo's light, restyle (when the diffusion models are here and there
    is a prompt), compose; then put the results in every material slot"""

    bl_idname = "scenefit.run"
    bl_label = "Run All"
    job_name = "run"
    runs_remotely = True
    records_runs = True
    skippable = True
    choice: EnumProperty(name="Choice", items=CHOICES, default="ask", options={"SKIP_SAVE", "HIDDEN"},
                         description="What the artist chose when asked about long work")

    # Scripts may set it; else the Run section's Adaptation (properties.SceneFitSettings.guidance).
    guidance: EnumProperty(name="Guidance", items=GUIDANCE, default="auto", options={"SKIP_SAVE", "HIDDEN"},
                           description="Whether the texture is restyled with Stable Diffusion 2")

    def chosen_guidance(self, context) -> str:
        if self.choice == "skip":
            return "none"
        return self.guidance if self.properties.is_property_set("guidance") else context.scene.scenefit.guidance

    resume: StringProperty(name="Resume", default="", options={"SKIP_SAVE", "HIDDEN"}, subtype="DIR_PATH",
                           description="An unfinished Run All's folder to continue (Resume in the run list)")

    def prepare(self, context):
        if getattr(self, "resume", ""):   # (scripts may leave it out) as it was clicked, on its own asset: its finished stages and checkpoint go on
            request, layout = resumed_run(self, context, self.resume)
            earlier = None
        else:
            request, layout = gather_run(self, context, "Run All fits the asset into the photo; use Convert and "
                                                        "Adapt for the other modes", self.chosen_guidance(context))
            earlier = last_finished_run(Path(request.out))   # its stages with this run's settings are reused
        self._request = request
        # the maps are decoded in the job; procedural chains are baked between redraws before it starts
        return work.run, RunInputs(request=request, asset=layout.plan(context),
                                   materials=layout.bake_data() if len(layout.materials) > 1 else None,
                                   reuse_from=str(earlier) if earlier else None)

    def long_local_work(self, context) -> LocalWork | None:
        guidance = self.chosen_guidance(context)
        if guidance == "none" or (guidance == "auto" and not context.scene.scenefit.prompt.strip()):
            return None   # no adaptation: the rest takes seconds
        # "auto" adapts only when the job finds the weights on disk (jobs never download): the
        # question is asked without looking (a look imports torch and may touch the network).
        return adapt_seconds_here(context)

    def long_work_warning(self, context) -> str | None:
        from .jobs import long_work_warning

        return long_work_warning(context, "Run All's adaptation (when Stable Diffusion 2's weights are found)",
                                 self.long_local_work(context), self.runs_remotely)

    def apply(self, context, result: RunOutcome) -> str:
        """The run's results on its own asset (found by its identity, whatever its name or the selection
        is now), the World in the scene it was clicked in, the composite through its placement and size."""
        request: RunRequest = self._request
        mats = apply_layout_results(context, self._layout, result, result.stage)
        scene = bpy.data.scenes.get(request.scene) or context.scene
        world = apply_result_world(context, result.hdr, "run", scene=scene)
        image = apply_composite_image(context, result.composite, "run")
        self._made = {"world": world, "composite": image}   # the run history's (operators/history.py)
        lines = [materials_words(mats), f"World '{world.name}'", f"composite image '{image.name}'"]
        try:
            if result.camera is None:
                raise InputError("the run has no camera stage")
            scene_camera = bpy.data.objects.get(request.scene_camera) if request.scene_camera else None
            objects = [o for o in (object_by_id(i) for i in request.object_ids) if o is not None]
            photo_read_whole(request.photo)   # (the run's camera and light stages decoded it whole)
            made = setup_composite(context, objects, request.photo, request.placement, request.config.size,
                                   result.camera, scene_camera=scene_camera, world=world)
            lines.append(f"Cycles composite set up in the scene '{made['scene'].name}' through "
                         f"'{made['camera'].name}' (F12 there renders it)")
        except SceneFitError as error:
            lines.append(f"no Cycles composite: {error}")
        reused = [name for name, status in result.stages.items() if status == "reused"]
        if reused:
            lines.append(f"{', '.join(reused)} reused from the last run (same settings and inputs)")
        if result.stages.get("adapt") == "skipped":
            lines.append(f"adapt skipped: {result.adapt_skipped}")
        return "Done: " + "; ".join(lines)


classes = (SCENEFIT_OT_run,)

register, unregister = bpy.utils.register_classes_factory(classes)
