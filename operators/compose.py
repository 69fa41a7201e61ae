"""Compose: the asset in the photo, set up in SceneFit's own scene ("SceneFit Composite") and rendered there at
the quality preset's samples, denoised, as Run All's compose; F12 in that scene renders with its own settings."""
from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import BoolProperty, IntProperty

from ..blender_io.compose import setup_composite
from ..core.base.errors import SceneFitError
from ..core.base.limits import COMPOSE_MAX_SIDE
from ..core.pipeline.preset_tables import TABLES
from .asset import asset_objects
from .folders import run_folder
from .photo import composite_camera, photo_path, photo_view
from .polls import OnMesh
from .results import apply_composite_image
from ..workers.blender_jobs import written_whole


class SCENEFIT_OT_compose(OnMesh, bpy.types.Operator):
    """Set up the composite in SceneFit's own scene ("SceneFit Composite": a camera matched to the photo,
    the photo behind the render, a shadow-catcher floor, the asset linked, lit by the estimated World when
    there is one) and render it there at the quality preset's samples, denoised; your scene's settings, camera
    and compositor stay as they are"""

    bl_idname = "scenefit.compose"
    bl_label = "Compose"
    bl_options = {"REGISTER", "UNDO"}

    render: BoolProperty(name="Render", default=True,
                         description="Render the composite now and save it in a new run folder")
    samples: IntProperty(name="Samples", default=0, min=0, options={"SKIP_SAVE"},
                         description="Cycles samples for this render (0: the quality preset's, denoised, as Run "
                                     "All's compose)")

    def execute(self, context):
        settings = context.scene.scenefit
        try:
            # the asset as Run All takes it: the selected objects, or the active one
            objects = asset_objects(context)
            photo = photo_path(context)
            view = photo_view(context, photo, objects)
            scene_camera = bpy.data.objects.get(view["scene_camera"]) if view["scene_camera"] else None
            made = setup_composite(context, objects, photo, tuple(settings.placement), settings.size,
                                   composite_camera(context, photo, view), scene_camera=scene_camera,
                                   world=settings.result_world)
            own = made["scene"]
            if not self.render:
                self.report({"INFO"}, f"Composite set up in the scene '{own.name}' with '{made['camera'].name}': "
                                      "F12 there renders it")
                return {"FINISHED"}
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        cost, how = self.render_cost(own, settings.preset)
        if context.window is not None and not bpy.app.background:
            # In the UI Blender's own render job runs it (progress, Esc); the artist saves it from there. The
            # scene's own settings come back when the job ends, so F12 there stays the artist's.
            restore_after_render(own, at_cost(own, cost))
            bpy.ops.render.render("INVOKE_DEFAULT", scene=own.name)
            self.report({"INFO"}, f"Rendering the composite {how}; F12 in '{own.name}' renders with its own "
                                  "settings")
            return {"FINISHED"}
        try:
            active = context.active_object
            folder = run_folder(context, "compose", (active if active in objects else objects[0]).name)
            out = written_whole(str(folder), lambda staging: {"composite": self._render(own, staging, cost)})
        except SceneFitError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        apply_composite_image(context, out["composite"], "compose")
        self.report({"INFO"}, f"Composite rendered {how}: {out['composite']}")
        return {"FINISHED"}

    def render_cost(self, scene, preset: str) -> tuple[dict, str]:
        """(the render settings, the words for them): as Run All's compose renders at `preset`, its sample cap
        (or the samples asked for) with the denoiser, its long side at most the preset's; the composite
        scene's own settings are for the artist's F12."""
        table = TABLES["compose"][preset]
        samples = self.samples or table["max_spp"]
        longest = max(scene.render.resolution_x, scene.render.resolution_y, 1)
        percent = max(1, min(100, 100 * table.get("max_side", COMPOSE_MAX_SIDE) // longest))
        # Cycles' adaptive sampling stops each pixel at the preset's noise target, between the compose stage's
        # sample bounds (its default lower one, 4); the denoiser's guide passes are first-hit and clean, so
        # they are not denoised first (prefilter FAST; ACCURATE tripled the denoiser's time here), and its
        # quality follows the preset (the denoiser was most of a draft Compose's time at HIGH).
        cost = {"samples": samples, "use_adaptive_sampling": not self.samples,
                "adaptive_threshold": table["noise_target"], "adaptive_min_samples": min(samples, 4),
                "use_denoising": True, "denoiser": "OPENIMAGEDENOISE", "denoising_prefilter": "FAST",
                "denoising_quality": DENOISER_QUALITY[preset], "resolution_percentage": percent}
        whose = f"{samples} samples" if self.samples else \
            f"the {preset.capitalize()} preset's noise target, at most {samples} samples"
        size = f", {percent}% of the photo's size" if percent < 100 else ""
        return cost, f"at {whose}, denoised{size}"

    def _render(self, scene, folder: Path, cost: dict) -> str:
        """F12 of the composite scene with write_still into `folder`; its settings put back after."""
        out = folder / "composite.png"
        settings = scene.render.image_settings
        before = at_cost(scene, cost), scene.render.filepath, settings.file_format
        try:
            scene.render.filepath = str(out)
            settings.file_format = "PNG"
            bpy.ops.render.render(write_still=True, scene=scene.name)
        finally:
            put_back(scene, before[0])
            scene.render.filepath, settings.file_format = before[1:]
        return str(out)


# Open Image Denoise's quality per preset in Cycles' words: a draft is a quick look.
DENOISER_QUALITY = {"draft": "FAST", "balanced": "BALANCED", "final": "HIGH"}


def _owner(scene, name: str):
    """The settings block a render setting lives in: the resolution in scene.render, the rest in Cycles'."""
    return scene.render if name == "resolution_percentage" else scene.cycles


def at_cost(scene, cost: dict) -> dict:
    """Set the scene's render settings for one render; what they were."""
    before = {name: getattr(_owner(scene, name), name) for name in cost}
    for name, value in cost.items():
        setattr(_owner(scene, name), name, value)
    return before


def put_back(scene, before: dict) -> None:
    for name, value in before.items():
        setattr(_owner(scene, name), name, value)


def restore_after_render(scene, before: dict) -> None:
    """Put the scene's render settings back once Blender's render job for it completes or is cancelled."""
    name = scene.name

    def done(*_args) -> None:
        for handlers in (bpy.app.handlers.render_complete, bpy.app.handlers.render_cancel):
            if done in handlers:
                handlers.remove(done)
        if name in bpy.data.scenes:
            put_back(bpy.data.scenes[name], before)

    bpy.app.handlers.render_complete.append(done)
    bpy.app.handlers.render_cancel.append(done)


classes = (SCENEFIT_OT_compose,)

register, unregister = bpy.utils.register_classes_factory(classes)
