"""One preset concept for every stage: draft / balanced / final, resolved here into each stage's config.

"final" is the paper's setting wherever the paper gives one (appendix "Implementation Details");
"balanced" and "draft" trade quality for speed on one machine without a big GPU. A table says what a
preset changes from the stage's config defaults; `stage_config` applies it, then the caller's own
overrides. The README's table and `scenefit adapt|light --dry-run` show the result.
"""
from __future__ import annotations

from dataclasses import fields, replace

from .errors import InputError

PRESET_NAMES = ("draft", "balanced", "final")
# What a person picking one should know (the Blender panel's choices say the same).
PRESET_DESCRIPTIONS = {
    "draft": "Fewest iterations, small renders: a quick look",
    "balanced": "The default trade-off between time and quality",
    "final": "The paper's settings: slowest, best",
}
STAGES = ("texture", "convert", "light", "adapt", "compose")

TABLES: dict[str, dict[str, dict]] = {
    # The neural texture's hash grid: "final" is the paper's / Instant-NGP's (NeuralTextureConfig defaults).
    "texture": {
        "draft": {"n_levels": 8, "log2_table": 17, "finest_resolution": 512},
        "balanced": {"n_levels": 12, "log2_table": 18, "finest_resolution": 1024},
        "final": {},
    },
    # Conversion: the paper's 1000 iterations (lr 0.02 -> 0.001) in "final". The sparse encoding plan
    # costs ~2 GB at 1024² with the full hash grid (8 GB at 2048²), hence the resolution cap.
    "convert": {
        "draft": {"texture_preset": "draft", "iterations": 150, "max_resolution": 512},
        "balanced": {"texture_preset": "balanced", "iterations": 400, "max_resolution": 1024},
        "final": {"texture_preset": "final", "iterations": 1000, "max_resolution": 1024},
    },
    # Light: the paper's 2000 iterations at lr 0.01 in "final"; fewer iterations take a larger lr so the
    # scales can travel as far. (The paper renders the apparatus at 512 px, 128 spp on GPUs.)
    "light": {
        "draft": {"map_height": 64, "apparatus": {"render_size": 48, "spp": 4},
                  "optimise": {"iterations": 60, "lr": 0.1}},
        "balanced": {"map_height": 128, "apparatus": {"render_size": 64, "spp": 8},
                     "optimise": {"iterations": 200, "lr": 0.05}},
        "final": {"map_height": 256, "apparatus": {"render_size": 256, "spp": 32},
                  "optimise": {"iterations": 2000, "lr": 0.01}},
    },
    # Adapt: "final" is setup (m) exactly. size_scale / spp_scale shrink every stage's render size and
    # samples per pixel; fewer views per step cost proportionally less.
    "adapt": {
        "draft": {"iterations": 300, "size_scale": 0.5, "spp_scale": 0.25, "views_per_step": 1,
                  "preview_every": 25, "checkpoint_every": 100},
        "balanced": {"iterations": 1500, "size_scale": 0.75, "spp_scale": 0.5, "views_per_step": 2},
        "final": {},
    },
    # Compose: the final render's noise target and sample cap (the paper renders evaluation at 1024 spp;
    # here a denoised render aims at a noise level, see README "Composition").
    "compose": {
        "draft": {"noise_target": 0.06, "max_spp": 16},
        "balanced": {"noise_target": 0.03, "max_spp": 64},
        "final": {"noise_target": 0.015, "max_spp": 256},
    },
}


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
        from .texture.neural_texture import NeuralTextureConfig

        return NeuralTextureConfig(**{**table, **overrides})
    if stage == "convert":
        from .convert import ConvertConfig

        return ConvertConfig(**{**table, **overrides})
    if stage == "light":
        from .lighting.estimate import LightConfig

        return _nested(LightConfig(), {**table, **overrides})
    if stage == "compose":
        from .compose import ComposeConfig

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
    from .adapt.config import MODE_SETTINGS, MODE_TYPES, SCENE_STAGES, AdaptConfig, StageSpec

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
    values.update(overrides)
    return AdaptConfig(mode_type=mode, **values)
