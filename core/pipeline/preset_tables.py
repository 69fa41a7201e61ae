"""The presets' data: what draft / balanced / final change from each stage's config defaults.

Data only (it imports nothing of SceneFit but the neural texture's config), resolved into
stage configs by core/pipeline/presets.py. No stage reads it: a stage config holds resolved values (a
convert row's "texture" names a texture preset, which stage_config turns into its NeuralTextureConfig).
"""
from __future__ import annotations

from typing import Any

from ..base.names import PRESETS
from ..texture.texture_config import NeuralTextureConfig

PRESET_NAMES = PRESETS
# What a person picking one should know (the Blender panel's choices say the same).
PRESET_DESCRIPTIONS = {
    "draft": "Fewest iterations, small renders: a quick look",
    "balanced": "The default trade-off between time and quality",
    "final": "The paper's settings: slowest, best",
}

TABLES: dict[str, dict[str, dict[str, Any]]] = {
    # The neural texture's hash grid: "final" is the paper's / Instant-NGP's (NeuralTextureConfig defaults).
    "texture": {
        "draft": {"n_levels": 8, "log2_table": 17, "finest_resolution": 512},
        "balanced": {"n_levels": 12, "log2_table": 18, "finest_resolution": 1024},
        "final": {},
    },
    # Conversion: the paper's 1000 iterations (lr 0.02 -> 0.001) in "final". The sparse encoding plan
    # costs ~2 GB at 1024² with the full hash grid (8 GB at 2048²), hence the resolution cap.
    "convert": {
        "draft": {"texture": "draft", "iterations": 150, "max_resolution": 512},
        "balanced": {"texture": "balanced", "iterations": 400, "max_resolution": 1024},
        "final": {"texture": "final", "iterations": 1000, "max_resolution": 1024},
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
        "final": {"iterations": 4000},
    },
    # Compose: the final render's noise target and sample cap (the paper renders evaluation at 1024 spp;
    # here a denoised render aims at a noise level, see benchmarks/FINDINGS.md). A draft is a quick look:
    # at most 2048 px on the long side (a 12 MP photo's composite costs a quarter), the others at the
    # photo's size up to COMPOSE_MAX_SIDE.
    "compose": {
        "draft": {"noise_target": 0.06, "max_spp": 16, "max_side": 2048},
        "balanced": {"noise_target": 0.03, "max_spp": 64},
        "final": {"noise_target": 0.015, "max_spp": 256},
    },
}


def texture_preset(name: str, **overrides: Any) -> NeuralTextureConfig:
    """The neural texture's config at preset `name` (the one place a texture preset is resolved)."""
    return NeuralTextureConfig(**{**TABLES["texture"][name], **overrides})
