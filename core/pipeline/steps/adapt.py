"""The adapt stage's work: the texture restyled with Stable Diffusion 2's guidance (core/stages/adapt/),
of the photo when the run reads one; it runs only when the guidance's weights are found."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...render.environment import load_environment
from ...scene.asset_pose import place_asset
from ...scene.placement import Placement
from ...stages.adapt import adapt_and_bake
from ...stages.adapt.config import AdaptConfig
from ...stages.adapt.global_views import placement_turns
from ...stages.adapt.sampling import view_azimuths
from ...texture.bake import load_neural_texture
from .. import stage_configs

if TYPE_CHECKING:
    from ..run import PipelineRun


@dataclass(frozen=True)
class AdaptPlan:
    config: AdaptConfig
    placement: Placement | None   # where the global views place the asset (None: no photo, local views only)


def skipped(run: PipelineRun) -> str | None:
    if run.found:
        return None
    if run.config.guidance_type == "auto":
        return (f"no weights: Stable Diffusion 2's weights are not on this machine, so the converted texture is "
                f"composed as it is ({run.where})")
    return run.where


def adapt_config(run: PipelineRun) -> AdaptConfig:
    """Of the photo when the run reads one; its local views lit by the given light map."""
    has_envmap = run.given is not None and run.given.light is not None
    return stage_configs.adapt_config(run.config, run.mesh.name, has_photo=run.photo_path is not None,
                                      has_envmap=has_envmap)


def adapt_placement(run: PipelineRun) -> Placement:
    """Where adapt's global views place the asset: compose's point, at most the photo's height."""
    h, w = run.photo.shape[:2]
    return Placement((run.placement_px[0] / w, run.placement_px[1] / h), min(1.0, run.config.size))


def configure(run: PipelineRun) -> AdaptPlan:
    # The global views are the compose stage's composite: same point, size and camera as compose.
    return AdaptPlan(adapt_config(run), adapt_placement(run) if run.photo_path is not None else None)


def key_of(plan: AdaptPlan) -> Any:
    return plan.config.to_dict()


def check(run: PipelineRun) -> None:
    """Adapt's global views place the asset at each of its azimuths' turns: where it cannot stand is one sentence."""
    camera, size = run.photo_camera()[0], adapt_placement(run).size
    for turn in placement_turns(view_azimuths(adapt_config(run).views)):
        place_asset(run.normalized, camera, run.placement_px, size, turn)


def work(run: PipelineRun, plan: AdaptPlan, folder: Path) -> dict[str, Any]:
    config, placement = plan.config, plan.placement
    texture_path, light_path = run.output("texture"), run.output("light")
    # (the light stage shares the loaded models when it ran beside; alone, adapt loads what its views need)
    need_inpaint = run.given is None or config.views_type == "local+global"
    camera = None if placement is None else run.stage_camera(run.photo.shape[1], run.photo.shape[0])[0]
    envmap = load_environment(light_path) if config.light_type == "envmap" and light_path else None
    return adapt_and_bake(run.mesh, load_neural_texture(texture_path) if texture_path else None, config,
                          folder, photo=run.photo if placement is not None else None,
                          placement=placement, envmap=envmap, photo_camera=camera, progress=run.progress,
                          cancel=run.cancel, models=run.cache.get(config.models, need_inpaint))[1]
