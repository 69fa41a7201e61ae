"""Each stage's config from a run's RunConfig: the one place a stage's settings are assembled.

    config = light_config(run, light_critic(run, guidance).choice, map_height)

Every entry point (`scenefit run` and the single-stage commands, a batch job, Blender's Run All and its
per-stage buttons, a remote worker) builds a RunConfig and asks here; what the run's inputs decide beside
it (the light critic found on this machine, the map height the asset's glossiness calls for, the screen
size the photo gives the texture, the sun a shadow's points give through the photo's camera) is passed
in as plain values. The preset's settings come first, then those values, then the run's own overrides
(`RunConfig.stage_overrides`), which a jobs file, a command's options and an operator's quick-look
properties all give.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from ..base.decision import Decision
from ..scene.camera import PhotoCamera
from ..stages.adapt.config import AdaptConfig
from ..stages.compose import ComposeConfig
from ..stages.convert_config import ConvertConfig
from ..stages.light.config import LightConfig
from ..stages.light.critic_choice import critic_choice
from ..stages.light.depth import depth_config_for
from ..stages.light.shadow_hint import sun_from_shadow_points
from .presets import stage_config, with_overrides
from .run_config import RunConfig


def _resolved(stage: str, run: RunConfig, values: dict[str, Any]) -> Any:
    """The preset's config for `stage` with `values` over it, then the run's own overrides for it."""
    return stage_config(stage, run.preset, **with_overrides(values, run.overrides(stage)))


def convert_config(run: RunConfig, screen_px: int | None = None) -> ConvertConfig:
    """screen_px: how many pixels of the photo the asset spans (no more texels than the composite shows);
    None where no photo is read (a convert alone fits at the preset's size)."""
    return _resolved("convert", run, {"screen_px": screen_px, "seed": run.seed})


def light_critic(run: RunConfig, guidance: tuple[bool, str] | None = None) -> Decision:
    """The light stage's critic: the one the run's light overrides name ("auto" included), else with
    `guidance` (a run that may adapt: `guidance_found`'s answer) the diffusion critic exactly when
    adapt's weights are found, else (light alone, as `scenefit light`) "auto": diffusion when the SD2
    base weights are on this machine."""
    asked = run.overrides("light").get("critic_type")
    if asked is not None or guidance is None:
        return critic_choice(asked or "auto", run.models)
    found, where = guidance
    return Decision("diffusion" if found else "none", where)


def light_config(run: RunConfig, critic: str, map_height: int | None = None,
                 without_diffusion: bool = False) -> LightConfig:
    """critic: light_critic's choice; map_height: what the asset's glossiest reflections call for (None:
    the preset's); without_diffusion: the run asked for no diffusion model at all (a pipeline's guidance
    "none"), so the sky/ground prior completes an outdoor map unless its overrides say otherwise. The run
    gives the sun, the scene type, the models and the depth model, looked for where the models are."""
    values = {"critic_type": critic, "map_height": map_height, "scene_type": run.scene_type,
              "sun_deg": None if run.sun_deg is None else tuple(run.sun_deg),
              "sun_uncertainty_deg": float(run.sun_uncertainty_deg), "models": run.models,
              "depth": depth_config_for(run.models, model=run.depth_model)}
    overrides = run.overrides("light")
    overrides.pop("critic_type", None)   # (light_critic's to decide: "auto" is no LightConfig value)
    config = stage_config("light", run.preset, **with_overrides(values, overrides))
    if without_diffusion and "completion_type" not in overrides.get("outpaint", {}):
        config = replace(config, outpaint=replace(config.outpaint, completion_type="prior"))
    return config


def with_shadow_sun(config: LightConfig, run: RunConfig, camera: PhotoCamera, stored_size: tuple[int, int],
                    working_shape: tuple[int, int]) -> LightConfig:
    """`config` with the sun the run's shadow points (foot, top, tip) give through the photo's `camera`
    (at the light stage's working copy of `working_shape`; the points are in the photo as stored, of
    `stored_size` (w, h)); `config` itself when the run gives none."""
    if run.sun_shadow is None:
        return config
    sun, spread = sun_from_shadow_points(run.sun_shadow, camera, stored_size, working_shape)
    return replace(config, sun_deg=sun, sun_uncertainty_deg=spread)


def adapt_config(run: RunConfig, asset_name: str, has_photo: bool = True, has_envmap: bool = False) -> AdaptConfig:
    """The run's mode, prompts and seed (a scene run without a prompt gets one from the asset's name; an
    edit's prompt may be made of its object prompt and instruction). has_photo: a scene run without its
    photo (Blender's Adapt before a photo is chosen) adapts local views only; has_envmap: the local views
    are lit by the light stage's map."""
    prompt = run.prompt or (f"a {asset_name} in this scene, photo" if run.mode == "scene" else "")
    values = {"mode_type": run.mode, "prompt": prompt, "negative_prompt": run.negative_prompt,
              "object_prompt": run.object_prompt, "instruction": run.instruction, "seed": run.seed,
              "models": run.models}
    if run.mode == "scene" and not has_photo:
        values["views_type"] = "local"
    if has_envmap:
        values["light_type"] = "envmap"
    return _resolved("adapt", run, values)


def compose_config(run: RunConfig) -> ComposeConfig:
    """The run's size, shadow and samples over the preset's."""
    return _resolved("compose", run, {"size": run.size, "shadow_type": run.shadow_type, "spp": run.compose_spp})
