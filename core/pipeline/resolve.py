"""Each configured stage's config from its preset's values and the caller's overrides (the registry's
`Stage.config`; core/pipeline/presets.stage_config looks the preset up and calls it)."""
from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

from ..base.errors import InputError
from ..guidance.critic_config import CriticConfig
from ..stages.adapt.config import MODE_SETTINGS, MODE_TYPES, SCENE_STAGES, AdaptConfig, StageSpec
from ..stages.compose import ComposeConfig
from ..stages.convert_config import ConvertConfig
from ..stages.light.config import LightConfig
from .preset_tables import texture_preset


def resolve_convert(table: dict[str, Any], overrides: dict[str, Any]) -> ConvertConfig:
    overrides = dict(overrides)
    # Fitting settings ask for the fit: without them the asset's own maps are the exact start.
    if "init_type" not in overrides and {"iterations", "method_type"} & set(overrides):
        overrides["init_type"] = "fit"
    values = {**table, **overrides}
    if isinstance(values.get("texture"), str):   # a texture preset's name: its hash grid, resolved here
        values["texture"] = texture_preset(values["texture"])
    return ConvertConfig(**values)


def resolve_light(table: dict[str, Any], overrides: dict[str, Any]) -> LightConfig:
    return nested(LightConfig(), {**table, **overrides})


def resolve_compose(table: dict[str, Any], overrides: dict[str, Any]) -> ComposeConfig:
    return ComposeConfig(**{**table, **overrides})


def resolve_adapt(table: dict[str, Any], overrides: dict[str, Any]) -> AdaptConfig:
    """For adapt, `mode_type` (default "scene") picks the mode's settings from the appendix first."""
    table, overrides = dict(table), dict(overrides)
    mode = overrides.pop("mode_type", "scene")
    if mode not in MODE_TYPES:
        raise InputError(f"mode_type must be one of {MODE_TYPES}, got {mode!r}.")
    values = dict(MODE_SETTINGS[mode])
    size_scale, spp_scale = table.pop("size_scale", 1.0), table.pop("spp_scale", 1.0)
    values["stages"] = tuple(
        StageSpec(s.fraction, max(8, int(round(s.render_size * size_scale / 8)) * 8),
                  max(1, int(round(s.spp * spp_scale))), s.t_range)
        for s in values.get("stages", SCENE_STAGES))
    values.update(table)
    if isinstance(overrides.get("critic"), dict):   # a table of critic settings changes only what it names
        overrides["critic"] = replace(values.get("critic", CriticConfig()), **overrides["critic"])
    values.update(overrides)
    return AdaptConfig(mode_type=mode, **values)


def nested(config: Any, values: dict[str, Any]) -> Any:
    """`config` with `values` replaced; a dict value updates that field's own (nested) config."""
    names = {f.name for f in fields(config)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise InputError(f"{type(config).__name__} has no setting {', '.join(unknown)}.")
    changes = {k: replace(getattr(config, k), **v) if isinstance(v, dict) else v for k, v in values.items()}
    return replace(config, **changes)
