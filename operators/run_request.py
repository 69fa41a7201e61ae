"""A Run All's request gathered at the click (main thread): the asset by its identity, the panel's prompt,
negative prompt, seed, placement, size, turn, preset and photo, the preferences' models, one RunConfig. The
same request goes to a run here and to a worker; Resume reads it back from the run's folder."""
from __future__ import annotations

from pathlib import Path

import bpy

from ..core.base.errors import InputError
from ..workers.blender_jobs import quick_overrides, view_config
from ..workers.job_seam import RunRequest, read_request, run_guidance
from .asset import asset_layout, scene_layout
from .folders import run_folder
from .identity import object_by_id
from .photo import photo_view
from .prefs import depth_model_preference, model_config
from .results import result_targets


def gather_run(op, context, refusal: str, guidance: str) -> tuple[RunRequest, object]:
    """(request, AssetLayout) of a new Run All on the selection; `guidance` is the panel's (or the script's)
    Adaptation, which the question's Skip adaptation and an empty prompt turn off (job_seam.run_guidance)."""
    settings = context.scene.scenefit
    photo, layout = scene_layout(op, context, refusal)
    guidance_type, why_no_adapt = run_guidance(getattr(op, "choice", "ask"), guidance, settings.prompt)
    # The artist's camera when it shows the photo, else the panel's or the estimate; the Cycles set-up
    # takes the camera the run used, so both composites agree.
    view = photo_view(context, photo, [bpy.data.objects[name] for name in layout.objects])
    targets = result_targets(layout)
    op._layout = targets
    preset = op.run_preset(context) if hasattr(op, "run_preset") else settings.preset
    config = view_config(view, preset=preset, prompt=settings.prompt,
                         negative_prompt=settings.negative_prompt, seed=None if settings.seed < 0 else settings.seed,
                         guidance_type=guidance_type, models=model_config(context), scene_type=settings.scene_type,
                         depth_model=depth_model_preference(context), stage_overrides=quick_overrides(op))
    request = RunRequest(asset_id=targets["owner_id"], asset_name=layout.name,
                         object_ids=tuple(targets["object_ids"]),
                         slots=tuple(tuple(pairs) for pairs in targets["slots"]), photo=str(photo),
                         placement=(float(view["placement"][0]), float(view["placement"][1])), config=config,
                         out=str(run_folder(context, op.job_name, layout.name)), why_no_adapt=why_no_adapt,
                         scene_camera=view["scene_camera"], scene=context.scene.name)
    return request, layout


def resumed_run(op, context, folder: str) -> tuple[RunRequest, object]:
    """(request, AssetLayout) of the unfinished run in `folder`, as it was clicked: its asset (by identity,
    whatever is selected now), settings and photo; the preferences' models of today."""
    request = read_request(Path(folder), model_config(context)).resumed(folder)
    objects = [object_by_id(i) for i in request.object_ids]
    owner = object_by_id(request.asset_id)
    if owner is None or any(o is None for o in objects):
        raise InputError(f"The asset '{request.asset_name}' of the run '{folder}' is no longer in this file; its "
                         "folder keeps what the run made.")
    layout = asset_layout(context, objects, owner.name)
    op._object_name = layout.name
    op._layout = result_targets(layout)
    return request, layout
