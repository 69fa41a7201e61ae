"""The names a run is spoken in: its stages, presets, adaptation modes, guidance and scene types.

Every entry point (the command line, a jobs file, Blender's panel and operators, a remote worker) and
every config that checks a choice imports them from here. It sits in core/base, the bottom layer,
because the stage configs (adapt's modes, light's scene types) check these names too, and a stage
may not import core/pipeline.
"""
from __future__ import annotations

# The pipeline's stages, in the order they run: those a job lists.
STAGES = ("convert", "light", "adapt", "compose", "bake")
# Every stage of a run in its order: the camera stage (the photo's camera, camera/camera.json, which light,
# adapt and compose read) runs before light. A job does not list it: every run that reads the photo has it.
CAMERA_STAGE = "camera"
RUN_ORDER = ("convert", CAMERA_STAGE, "light", "adapt", "compose", "bake")
# The stages whose config a preset resolves and a run's overrides reach (the bake is a child process).
CONFIG_STAGES = ("convert", "light", "adapt", "compose")
# The stages that read the photo and where the asset stands in it.
PHOTO_STAGES = ("light", "compose")
# What a job may list: stages that run on their own (each its stage function), or the pipeline, which runs
# every stage but the optional ones (adapt when its guidance is found, the bake when asked for).
ALONE_STAGES = ("convert", "light")
OPTIONAL_STAGES = ("adapt", "bake")
PIPELINE_STAGES = tuple(stage for stage in STAGES if stage not in OPTIONAL_STAGES)
# What runs on a photo alone, without an asset (Blender's Estimate Light before any asset is chosen).
PHOTO_ONLY_STAGES = ("light",)
# What runs from outputs made before (Blender's Adapt after its Convert and Estimate Light): adapt alone,
# given the texture it starts from and, optionally, the light map its local views are lit by.
FROM_GIVEN_STAGES = ("adapt",)

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
