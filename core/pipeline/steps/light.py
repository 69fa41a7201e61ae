"""The light stage's work: the photo's light map (core/stages/light/stage.py), with what the run decides
for it: the critic (the run's guidance; light alone as `scenefit light`) and, for a run that converts the
asset, a map as sharp as its glossiest reflections, capped by the preset."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from ...base.decision import Decision
from ...data.scene_needs import envmap_height_for, report as needs_report
from ...data.uv_raster import rasterize_uv
from ...stages.light.config import LightConfig
from ...stages.light.shadow_hint import sun_from_shadow_points
from ...stages.light.stage import LightInputs, run_light, write_light
from ...texture.bake import load_neural_texture
from ...texture.surface_layout import texture_view
from .. import stage_configs
from ..presets import stage_config

if TYPE_CHECKING:
    from ..run import PipelineRun


@dataclass(frozen=True)
class LightPlan:
    """The light stage's config and the decisions that made it (its report says them)."""

    config: LightConfig
    critic: Decision
    height: Decision | None   # the map height the asset's reflections call for (None: the preset's)


def configure(run: PipelineRun) -> LightPlan:
    pipeline = "compose" in run.stages
    critic = stage_configs.light_critic(run.config, (run.found, run.where) if pipeline else None)
    height = None
    if "convert" in run.stages:
        # (the coverage mask only picks which roughness texels count: 1024² is plenty, never the
        # texture's long side squared, which for a 16384x16 map is 16384²)
        raster = rasterize_uv(run.normalized, min(max(run.maps.resolution), 1024))
        height = envmap_height_for(run.maps, raster.mask)
        preset_height = stage_config("light", run.config.preset).map_height
        if height.choice > preset_height:
            height = replace(height, choice=preset_height, reason=f"{height.reason}; capped at the "
                             f"{run.config.preset} preset's {preset_height} rows")
    without_diffusion = pipeline and run.config.guidance_type == "none"
    config = stage_configs.light_config(run.config, critic.choice, None if height is None else height.choice,
                                        without_diffusion=without_diffusion)
    return LightPlan(config, critic, height)


def key_of(plan: LightPlan) -> Any:
    return plan.config


def check(run: PipelineRun) -> None:
    """A shadow point in the sky is one sentence before any work (the points need the photo's camera)."""
    if run.config.sun_shadow is not None:
        h, w = run.photo.shape[:2]
        sun_from_shadow_points(run.config.sun_shadow, run.photo_camera()[0], tuple(run.photo_info["size"]), (h, w))


def work(run: PipelineRun, plan: LightPlan, folder: Path) -> dict[str, Any]:
    config = plan.config
    camera, estimate = run.stage_camera(run.photo.shape[1], run.photo.shape[0])
    with_sun = stage_configs.with_shadow_sun(config, run.config, camera, tuple(run.photo_info["size"]),
                                             (run.photo.shape[0], run.photo.shape[1]))
    asset: dict[str, Any] = {}
    texture_path = run.output("texture")
    # The diffusion critic scores renders of the asset itself (as converted), not a stand-in sphere.
    if config.critic_type == "diffusion" and "convert" in run.keys and texture_path is not None:
        texture = load_neural_texture(texture_path)
        stack = texture_view(texture, run.normalized).stack(texture)   # convert's: the own UVs
        asset = {"mesh": run.mesh, "maps": torch.as_tensor(stack)}
    inputs = LightInputs(run.photo, run.photo_info, run.placement_px, camera, estimate)
    result = run_light(inputs, with_sun, run.progress, run.cancel, models=run.light_models(), asset=asset)
    if plan.height is not None:
        result.decisions["envmap_height"] = needs_report(plan.height)
    result.decisions.setdefault("critic", {})["choice"] = {"chosen": plan.critic.choice, "why": plan.critic.reason}
    if run.config.sun_shadow is not None:
        result.decisions["sun"]["from"] = "the shadow's foot, top and tip given (" + \
            ", ".join(run.config.sun_shadow) + ")"
    return write_light(result, folder)
