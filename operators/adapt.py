"""Adapt: restyle the converted texture to fit the photo (or from a prompt), as a background job."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

from ..blender_io import mesh_from_object
from ..core.base.errors import InputError
from ..workers import blender_jobs as work
from .asset import asset_layout, asset_texture
from .folders import run_folder
from .photo import photo_path, photo_view
from .polls import OnMesh
from .prefs import model_config
from .jobs import CHOICES, CostFirst, JobOperator
from .results import apply_layout_results, apply_result_material, materials_words, result_targets

if TYPE_CHECKING:
    from ..workers.time_model import LocalWork


def gather_adapt(op, context, texture: str) -> dict:
    """Adapt's plain inputs from the scene settings; `op` gives iterations / model_resolution / render_size."""
    settings = context.scene.scenefit
    obj = context.active_object
    # An asset of several materials or objects was converted as their atlas (Convert, Run All): adapt that
    # same mesh, and bake each material's maps for its slots after; one material (or a texture generated
    # from a prompt, perhaps on an object without any) as ever, on the active object.
    layout = asset_layout(context) if settings.mode != "generate" else None
    several = layout is not None and (len(layout.materials) > 1 or len(layout.objects) > 1)
    if several:
        mesh = layout.fitting_mesh()
        objects = [bpy.data.objects[n] for n in layout.objects]
    else:
        mesh = mesh_from_object(obj, context.evaluated_depsgraph_get())
        objects = obj
    # The result goes where the faces' materials are (as Convert's and Run All's do), not the active slot;
    # a texture generated from a prompt goes into the active slot (the object may have no material)
    op._layout = result_targets(layout) if layout is not None else None
    photo = str(photo_path(context)) if settings.mode == "scene" and settings.photo_path else ""
    light = bpy.path.abspath(settings.light_path) if settings.light_path else ""
    view = photo_view(context, Path(photo), objects) if photo else None
    op._object_name = layout.name if layout is not None else obj.name
    # The run's settings as one frozen RunConfig, as Run All builds it: how the photo is seen (the artist's
    # camera, the panel's values or the estimate; where the asset stands and its height), the prompts, and
    # the operator's quick-look properties as stage overrides.
    settings_of_run = {"preset": op.run_preset(context), "mode": settings.mode, "prompt": settings.prompt,
                       "object_prompt": settings.object_prompt, "instruction": settings.instruction,
                       "models": model_config(context), "stage_overrides": work.quick_overrides(op)}
    config = work.view_config(view, **settings_of_run) if view else work.plain_config(
        size=settings.size, **settings_of_run)
    return {
        "materials": layout.bake_data() if layout is not None and len(layout.materials) > 1 else None,
        "mesh": mesh, "texture": texture, "photo": photo, "config": config,
        "placement": view["placement"] if view else tuple(settings.placement),
        # the light stage's map: its camera is the one the local views' light was estimated with
        "envmap": light if light and Path(light).is_file() else "",
        # Resume: the cancelled run's folder, whose hidden sibling holds its checkpoint (else a new folder)
        "out": op.resume or str(run_folder(context, "adapt", op._object_name))}


def adapt_seconds_here(context, iterations: int | None = None) -> LocalWork | None:
    """The projected work of an adaptation at the panel's preset when it would run in this Blender
    (workers/time_model.py's measurements: the bench CPU, or an H200 on CUDA); None when not measured.

    Main thread, at a click: no model lookup (the job looks the models up; it never downloads them),
    no network, and torch is not imported for it (`device_here`)."""
    from ..workers.time_model import LocalWork, adapt_projection
    from .prefs import preferences

    prefs = preferences(context)   # (not model_settings: its ModelConfig imports torch)
    device = device_here(prefs.device if prefs is not None else "auto")
    if device is None:
        return None   # measured on neither
    seconds = adapt_projection(context.scene.scenefit.preset, iterations, gpu=device == "cuda")
    return None if seconds is None else LocalWork(seconds, device == "cuda")


def device_here(preference: str) -> str | None:
    """"cpu" or "cuda" as an adaptation here would run, without importing torch: the preference when it
    names one; for "auto", torch's answer once a job has imported it, else CUDA when the machine shows an
    NVIDIA driver, else the CPU. None for a device the bench has not measured."""
    import os
    import sys

    if preference in ("cpu", "cuda"):
        return preference
    if preference != "auto":
        return None
    torch = sys.modules.get("torch")
    if torch is not None:
        return "cuda" if torch.cuda.is_available() else "cpu"
    return "cuda" if os.path.exists("/proc/driver/nvidia/version") else "cpu"


class SCENEFIT_OT_adapt(OnMesh, CostFirst, JobOperator):
    """Restyle the asset's converted texture with diffusion guidance so it fits the photo (Esc cancels)"""

    bl_idname = "scenefit.adapt"
    bl_label = "Adapt"
    job_name = "adapt"
    runs_remotely = True
    records_runs = True
    choice: EnumProperty(name="Choice", items=CHOICES, default="ask", options={"SKIP_SAVE", "HIDDEN"},
                         description="What the artist chose when asked about long work")

    # For scripts and quick looks; 0 keeps the preset's value.
    iterations: IntProperty(name="Iterations", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                            description="Restyling steps (0: the quality preset's)")
    model_resolution: IntProperty(name="Model resolution", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                                  description="Image size the diffusion model works at (0: the quality preset's)")
    render_size: IntProperty(name="Render size", default=0, min=0, options={"SKIP_SAVE", "HIDDEN"},
                             description="Size of the views of the asset it looks at (0: the quality preset's)")
    resume: StringProperty(name="Resume", default="", options={"SKIP_SAVE", "HIDDEN"}, subtype="DIR_PATH",
                           description="A cancelled adaptation's folder to continue (Resume in the run list)")

    def prepare(self, context):
        settings = context.scene.scenefit
        texture = ""
        if settings.mode != "generate":
            try:
                texture = str(asset_texture(context, asset_layout(context)))
            except InputError as error:
                raise InputError(f"Adapt starts from the asset's converted texture: {error}") from None
        return work.adapt, gather_adapt(self, context, texture)

    def long_local_work(self, context) -> LocalWork | None:
        return adapt_seconds_here(context, self.iterations or None)

    def apply(self, context, result) -> str:
        if getattr(self, "_layout", None):
            mats = apply_layout_results(context, self._layout, result, "adapt")
        else:
            mats = [apply_result_material(context, self._object_name, result, "adapt")]
        return f"Adapted ({result.numbers['iterations']:.0f} iterations): {materials_words(mats)}"


classes = (SCENEFIT_OT_adapt,)

register, unregister = bpy.utils.register_classes_factory(classes)
