"""Run: the command line's pipeline (core.run.run_pipeline) as one background job, then its results
applied in Blender: the new material, the World, the composite set up for Cycles and its image."""
from __future__ import annotations

from typing import TYPE_CHECKING

import bpy
from bpy.props import EnumProperty

from ..blender_io.compose import setup_composite
from ..core.base.errors import SceneFitError
from ..core.scene.camera import PhotoCamera
from ..workers import blender_jobs as work
from .adapt import adapt_seconds_here
from .asset import scene_layout
from .folders import last_finished_run, run_folder
from .photo import photo_path, photo_view
from .polls import OnMesh
from .prefs import depth_model_preference, model_settings
from .jobs import CHOICES, CostFirst, JobOperator
from .properties import GUIDANCE
from .results import (apply_composite_image, apply_layout_results, apply_result_world, materials_words,
                      result_targets)

if TYPE_CHECKING:
    from ..panels.quality import LocalWork



class SCENEFIT_OT_run(OnMesh, CostFirst, JobOperator):
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

    def prepare(self, context):
        settings = context.scene.scenefit
        photo, layout = scene_layout(self, context, "Run All fits the asset into the photo; use Convert and "
                                                    "Adapt for the other modes")
        guidance, why_no_adapt = self.chosen_guidance(context), ""
        if not settings.prompt.strip() and guidance == "auto":
            guidance, why_no_adapt = "none", "the Style section has no prompt"
        if self.choice == "skip":
            why_no_adapt = "skipped at the question before the run (Skip adaptation)"
        # The artist's camera when it shows the photo, else the panel's or the estimate; the Cycles set-up
        # takes the camera the run used, so both composites agree.
        view = photo_view(context, photo, [bpy.data.objects[name] for name in layout.objects])
        self._scene_camera = view["scene_camera"]
        self._layout = result_targets(layout)
        out = run_folder(context, "run", layout.name)
        earlier = last_finished_run(out)   # its stages with this run's settings and inputs are reused
        # The run's settings as one frozen RunConfig, built here on the main thread, as `scenefit run` builds it.
        config = work.view_config(view, preset=self.run_preset(context), prompt=settings.prompt, guidance_type=guidance,
                                  models=model_settings(context)[0], scene_type=settings.scene_type,
                                  depth_model=depth_model_preference(context))
        # the maps are decoded in the job; procedural chains are baked between redraws before it starts
        return work.run, {"asset": layout.plan(context), "photo": str(photo), "placement": tuple(view["placement"]),
                          "config": config, "why_no_adapt": why_no_adapt,
                          "materials": layout.bake_data() if len(layout.materials) > 1 else None,
                          "out": str(out), "reuse_from": str(earlier) if earlier else None}

    def long_local_work(self, context) -> LocalWork | None:
        guidance = self.chosen_guidance(context)
        if guidance == "none" or (guidance == "auto" and not context.scene.scenefit.prompt.strip()):
            return None   # no adaptation: the rest takes seconds
        # "auto" adapts only when the job finds the weights on disk (only Download fetches them): the
        # question is asked without looking (a look imports torch and may touch the network).
        return adapt_seconds_here(context)

    def long_work_warning(self, context) -> str | None:
        from .jobs import long_work_warning

        return long_work_warning(context, "Run All's adaptation (when Stable Diffusion 2's weights are found)",
                                 self.long_local_work(context), self.runs_remotely)

    def apply(self, context, result) -> str:
        mats = apply_layout_results(context, self._layout, result, result["stage"])
        world = apply_result_world(context, result["hdr"], "run")
        image = apply_composite_image(context, result["composite"], "run")
        self._made = {"world": world, "composite": image}   # the run history's (operators/history.py)
        lines = [materials_words(mats),
                 f"World '{world.name}'", f"composite image '{image.name}'"]
        settings = context.scene.scenefit
        try:
            name = getattr(self, "_scene_camera", "")   # (not set when the run went to a worker)
            scene_camera = bpy.data.objects.get(name) if name else None
            objects = [bpy.data.objects[name] for name in self._layout["objects"] if name in bpy.data.objects]
            made = setup_composite(context, objects, photo_path(context),
                                   tuple(settings.placement), settings.size, PhotoCamera(**result["camera"]),
                                   scene_camera=scene_camera, world=world)
            lines.append(f"Cycles composite set up in the scene '{made['scene'].name}' through "
                         f"'{made['camera'].name}' (F12 there renders it)")
        except SceneFitError as error:
            lines.append(f"no Cycles composite: {error}")
        reused = [name for name, status in result["stages"].items() if status == "reused"]
        if reused:
            lines.append(f"{', '.join(reused)} reused from the last run (same settings and inputs)")
        if result["stages"]["adapt"] == "skipped":
            lines.append(f"adapt skipped: {result['adapt_skipped']}")
        return "Done: " + "; ".join(lines)


classes = (SCENEFIT_OT_run,)

register, unregister = bpy.utils.register_classes_factory(classes)
