"""Estimate Light: an HDR World from the photo and the placement, as a background job."""
from __future__ import annotations


import bpy
from bpy.props import EnumProperty, IntProperty

from ..workers import blender_jobs as work
from .folders import last_finished_run, run_folder
from .photo import photo_path, photo_view
from .prefs import depth_model_preference, model_config
from .polls import needs_setting
from .jobs import JobOperator
from .results import apply_result_world


class SCENEFIT_OT_estimate_light(JobOperator):
    """Estimate an HDR environment map from the photo and make it a new World (the current World is kept)"""

    bl_idname = "scenefit.estimate_light"
    bl_label = "Estimate Light"
    job_name = "light"
    asks_options = True   # Critic and Outpaint in a dialog before it starts
    poll = needs_setting("photo_path", "Pick a photo in the Scene section first")

    critic: EnumProperty(name="Critic", default="auto", description="What sets how bright the light is", items=(
        ("auto", "Auto", "The diffusion critic when Stable Diffusion 2 is on this machine, else the prior alone"),
        ("diffusion", "Diffusion", "Refine the light scales with Stable Diffusion 2 (VSD)"),
        ("none", "Prior only", "The inverse-tone-mapping prior sets the scales (fast)")))
    outpaint: EnumProperty(name="Outpaint", default="auto", description="How the light map is completed where "
                                                                       "the photo does not show it", items=(
        ("auto", "Auto", "Outdoor: SD2 inpainting when it is on this machine, else the sky/ground prior"),
        ("sd2", "SD2", "Complete the unseen map with Stable Diffusion 2 inpainting"),
        ("prior", "Prior", "Complete the unseen map with the sky/ground prior (fast)")))
    # For scripts and quick looks; 0 keeps the preset's value.
    iterations: IntProperty(name="Iterations", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                            description="Refinement steps of the light (0: the quality preset's)")
    model_resolution: IntProperty(name="Model resolution", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                                  description="Image size the diffusion model works at (0: the quality preset's)")

    def prepare(self, context):
        settings = context.scene.scenefit
        photo = photo_path(context)
        out = run_folder(context, "light", photo.stem)
        # The light's settings as one frozen RunConfig, as Run All builds it (the Critic and Outpaint asked in
        # the dialog, and a script's quick look, are the light stage's overrides).
        light = dict(work.quick_overrides(self).get("light", {}), critic_type=self.critic)
        light["outpaint"] = dict(light.get("outpaint", {}), completion_type=self.outpaint)
        config = work.view_config(photo_view(context, photo), preset=settings.preset, scene_type=settings.scene_type,
                                  models=model_config(context), depth_model=depth_model_preference(context),
                                  stage_overrides={"light": light})
        earlier = last_finished_run(out)   # the last estimate of this photo: its stages with these keys are reused
        return work.estimate_light, {"photo": str(photo), "placement": tuple(settings.placement), "config": config,
                                     "out": str(out), "reuse_from": str(earlier) if earlier else None}

    def apply(self, context, result) -> str:
        world = apply_result_world(context, result["hdr"])
        said = result["scene_type"] if result.get("scene_type_blended") else f"{result['scene_type']} scene"
        how = "Light as estimated before (same photo and settings)" if result.get("reused") else "Light estimated"
        return f"{how}, {said}, {result['sun']}: World '{world.name}'"


classes = (SCENEFIT_OT_estimate_light,)

register, unregister = bpy.utils.register_classes_factory(classes)
