"""The names a run is spoken in: its presets, adaptation modes, guidance and scene types.

Every entry point (the command line, a jobs file, Blender's panel and operators, a remote worker) and
every config that checks a choice imports them from here. It sits in core/base, the bottom layer,
because the stage configs (adapt's modes, light's scene types) check these names too, and a stage
may not import core/pipeline.
"""
from __future__ import annotations

# The stages' names (STAGES, RUN_ORDER, ...) are read off the stage registry: core/pipeline/registry.names().

PRESETS = ("draft", "balanced", "final")
# scene: restyle the asset to fit the photo; generate: a new appearance from the prompt; edit: change it as told.
MODES = ("scene", "generate", "edit")
# Whether adapt (and the light stage's diffusion critic) use Stable Diffusion 2: auto is sd2 when its weights are found.
GUIDANCE_TYPES = ("auto", "sd2", "none")
SCENE_TYPES = ("auto", "indoor", "outdoor")
# The composite's shadow: the floor passes' ratio, the paper's matte, or none (compose, and adapt's global views).
SHADOW_TYPES = ("ratio", "paper", "none")
# Where a run's camera values come from: the user (options, the panel), or the artist's Blender camera.
CAMERA_SOURCES = ("user", "blender")
