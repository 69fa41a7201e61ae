"""One preset concept for every stage: draft / balanced / final, resolved here into each stage's config.

"final" is the paper's setting wherever the paper gives one (appendix "Implementation Details");
"balanced" and "draft" trade quality for speed on one machine without a big GPU. A table says what a
preset changes from the stage's config defaults; `stage_config` applies it, then the caller's own
overrides. The docs' presets table (docs/technical/presets.md) and `scenefit adapt|light --dry-run` show the result.
"""
from __future__ import annotations

from dataclasses import is_dataclass, replace
from typing import Any

from ..base.errors import InputError
from .preset_tables import PRESET_DESCRIPTIONS, PRESET_NAMES, TABLES, texture_preset  # noqa: F401
from .registry import REGISTRY, names


def preset_stages() -> tuple[str, ...]:
    """What a preset resolves: the neural texture's table, then each configured stage's (the registry's)."""
    return ("texture", *names().CONFIG_STAGES)


def with_overrides(values: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
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


def stage_config(stage: str, name: str, **overrides: Any) -> Any:
    """The config of `stage` ("texture", or a configured stage of the registry) at preset `name`, then
    `overrides`; an override that is None is left to the preset (a command-line option not given).

    For "adapt", `mode_type` (default "scene") picks the mode's settings from the appendix first.
    """
    stages = preset_stages()
    if stage not in stages:
        raise InputError(f"Unknown stage {stage!r}; presets cover {', '.join(stages)}.")
    if name not in PRESET_NAMES:
        raise InputError(f"Unknown {stage} preset {name!r}; choose one of {', '.join(PRESET_NAMES)}.")
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if stage == "texture":
        return texture_preset(name, **overrides)
    record = next(s for s in REGISTRY if s.name == stage)
    assert record.config is not None and record.presets is not None   # (configured)
    return record.config(dict(record.presets[name]), overrides)
