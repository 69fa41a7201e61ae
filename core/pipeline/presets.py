"""One preset concept for every stage: draft / balanced / final, resolved here into each stage's config.

"final" is the paper's setting wherever the paper gives one (appendix "Implementation Details");
"balanced" and "draft" trade quality for speed on one machine without a big GPU. A table says what a
preset changes from the stage's config defaults; `stage_config` applies it, then the caller's own
overrides. The docs' presets table (docs/technical/presets.md) and `scenefit adapt|light --dry-run` show the result.
"""
from __future__ import annotations

from dataclasses import fields, is_dataclass, replace

from ..base.errors import InputError
from ..stages.compose import ComposeConfig
from .preset_tables import PRESET_DESCRIPTIONS, PRESET_NAMES, STAGES, TABLES, texture_preset  # noqa: F401


def with_overrides(values: dict, overrides: dict) -> dict:
    """`values` (a stage config's settings) with `overrides` over them; an override table over a settings
    object changes only what it names ({"depth": {"model": ...}} keeps the given DepthConfig's cache)."""
    merged = dict(values)
    for name, override in overrides.items():
        ours = merged.get(name)
        if isinstance(override, dict) and is_dataclass(ours) and not isinstance(ours, type):
            merged[name] = replace(ours, **override)
        else:
            merged[name] = override
    return merged


def stage_config(stage: str, name: str, **overrides):
    """The config of `stage` ("texture", "convert", "light", "adapt", "compose") at preset `name`, then
    `overrides`; an override that is None is left to the preset (a command-line option not given).

    For "adapt", `mode_type` (default "scene") picks the mode's settings from the appendix first.
    """
    if stage not in STAGES:
        raise InputError(f"Unknown stage {stage!r}; presets cover {', '.join(STAGES)}.")
    if name not in PRESET_NAMES:
        raise InputError(f"Unknown {stage} preset {name!r}; choose one of {', '.join(PRESET_NAMES)}.")
    table = dict(TABLES[stage][name])
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if stage == "texture":
        return texture_preset(name, **overrides)
    if stage == "convert":
        from ..stages.convert import ConvertConfig  # lazy: torch takes seconds to load

        # Fitting settings ask for the fit: without them the asset's own maps are the exact start.
        if "init_type" not in overrides and {"iterations", "method_type"} & set(overrides):
            overrides["init_type"] = "fit"
        values = {**table, **overrides}
        if isinstance(values.get("texture"), str):   # a texture preset's name: its hash grid, resolved here
            values["texture"] = stage_config("texture", values["texture"])
        return ConvertConfig(**values)
    if stage == "light":
        from ..stages.light.estimate import LightConfig  # lazy: torch takes seconds to load

        return _nested(LightConfig(), {**table, **overrides})
    if stage == "compose":
        return ComposeConfig(**{**table, **overrides})
    return _adapt_config(table, overrides)


def _nested(config, values: dict):
    """`config` with `values` replaced; a dict value updates that field's own (nested) config."""
    names = {f.name for f in fields(config)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise InputError(f"{type(config).__name__} has no setting {', '.join(unknown)}.")
    changes = {k: replace(getattr(config, k), **v) if isinstance(v, dict) else v for k, v in values.items()}
    return replace(config, **changes)


def _adapt_config(table: dict, overrides: dict):
    # lazy: torch takes seconds to load
    from ..guidance.critics import CriticConfig
    from ..stages.adapt.config import MODE_SETTINGS, MODE_TYPES, SCENE_STAGES, AdaptConfig, StageSpec

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
        values.setdefault("critic", CriticConfig())
    return AdaptConfig(mode_type=mode, **with_overrides(values, overrides))
