"""A run's settings: RunConfig, the one description of a run that every entry point builds and
run_pipeline takes, checking its own choices and numbers (finite, in range) as it is made; and
stage_subset, which stages may run together (a jobs file's, run_pipeline's)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable

from ..base.errors import InputError
from ..base.names import CAMERA_SOURCES, GUIDANCE_TYPES, MODES, PRESETS, SCENE_TYPES, SHADOW_TYPES
from ..guidance.models import ModelConfig
from ..scene.camera import PhotoCamera
from ..scene.placement import DEFAULT_OBJECT_SIZE
from ..stages.camera import check_camera_values
from ..stages.light.shadow_hint import check_point_count
from .registry import names

# (The camera stage's report is the run report's "camera", beside the "stages" a job lists.)


@dataclass(frozen=True)
class RunConfig:
    """The one description of a run: the command line, a jobs file's job (core/pipeline/run_table.py, its TOML
    view), Blender's Run All and a remote worker all build this, and run_pipeline takes nothing else."""

    preset: str = "balanced"                  # draft | balanced | final, for every stage
    mode: str = "scene"                       # adapt: scene (fit the photo) | generate | edit
    prompt: str = ""                          # adapt: what the asset should become in this scene
    negative_prompt: str = ""                 # adapt: what it should not look like
    object_prompt: str = ""                   # adapt, mode edit: what the asset is ...
    instruction: str = ""                     # ... and how to change it (the prompt, when empty, is made of both)
    seed: int | None = None                   # convert's fit and adapt's noise (None: each stage's default)
    guidance_type: str = "auto"               # adapt (and the light critic): sd2 | none | auto (sd2 when found)
    size: float = DEFAULT_OBJECT_SIZE         # compose: fraction of the photo's height the asset spans (--object-size)
    shadow_type: str = "ratio"                # compose: ratio (a shadow catcher) | paper (the thresholded matte) | none
    compose_spp: int | None = None            # compose: samples per pixel (None: from the preset's noise target)
    photo_camera: PhotoCamera | None = None   # None: the photo's camera as estimated (core/stages/camera.py)
    fspy: str | None = None                   # an fSpy project of the photo: its solved camera is used
    camera_overrides: dict[str, float] = field(default_factory=dict)   # the photo's camera over the estimate:
                                              # field of view, pitch and roll (degrees), lens shift x and y
    camera_source: str = "user"               # where those camera values come from: "user", or "blender" (the scene camera)
    camera_why: str = "given by the user"     # ... said in the report's camera notes
    turn_deg: float = 0.0                     # compose: the asset turned about Z after facing the camera
    # The artist's dominant light for the light stage (neither given: guessed), as the sun's angles or a shadow's points.
    sun_deg: tuple[float, float] | None = None   # light: the sun's (azimuth, elevation) in degrees, as --sun takes it
    sun_shadow: tuple[str, str, str] | None = None   # light: a shadow's foot, top and tip (each as --at takes a
                                                     # point), which give the sun through the photo's camera
    sun_uncertainty_deg: float = 0.0          # how far off the sun's angles may be, degrees (Pick Sun's clicks); a
                                              # shadow gives its own
    scene_type: str = "auto"                  # light: indoor | outdoor | auto (decided from the photo, or unsure)
    depth_model: str | None = None            # light: hub id or folder of the depth model (None: the default),
                                              # looked for where the diffusion models are ([models]' cache)
    models: ModelConfig = field(default_factory=ModelConfig)
    # Settings over the preset's, per stage ("convert", "light", "adapt", "compose"), as the stage's config takes them:
    # quick looks, tests and benchmarks (e.g. {"adapt": {"iterations": 4}}). Part of each stage's key.
    stage_overrides: dict[str, dict[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _choice("preset", self.preset, PRESETS)
        _choice("mode", self.mode, MODES)
        _choice("guidance_type", self.guidance_type, GUIDANCE_TYPES)
        _choice("scene_type", self.scene_type, SCENE_TYPES)
        _choice("camera_source", self.camera_source, CAMERA_SOURCES)
        _choice("shadow_type", self.shadow_type, SHADOW_TYPES)
        if self.seed is not None and not (_whole(self.seed) and self.seed >= 0):
            raise _refused("seed", f"seed must be a whole number >= 0, got {self.seed!r}.")
        _check_view(self)
        if self.sun_deg is not None and self.sun_shadow is not None:
            raise _refused("sun_shadow", "Give the sun as an azimuth and elevation or as a shadow's three points, "
                                         "not both.")
        if self.sun_shadow is not None:
            check_point_count(self.sun_shadow)
        configured = names().CONFIG_STAGES
        unknown = sorted(set(self.stage_overrides) - set(configured))
        if unknown:
            raise _refused("stage_overrides", f"stage_overrides names unknown stage {unknown[0]!r}; it takes "
                             f"{', '.join(configured)}.")

    def overrides(self, stage: str) -> dict[str, Any]:
        return dict(self.stage_overrides.get(stage, {}))



def _choice(name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise _refused(name, f"{name} must be one of {', '.join(choices)}, got {value!r}.")


def _refused(field_name: str, sentence: str) -> InputError:
    """The sentence as an InputError that names the RunConfig field it refuses (a jobs file says its key)."""
    error = InputError(sentence)
    error.field = field_name
    return error


def _whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_view(config: RunConfig) -> None:
    """How the run sees the photo, in range: numbers from any entry point (a jobs file, Blender, a worker)
    are finite, the camera's values are those of a camera (core/stages/camera.check_camera_values), the
    sun is above or below the horizon by at most 90 degrees."""
    if not (_finite(config.size) and 0.0 < config.size <= 1.0):   # (as core/scene/placement.Placement takes it)
        raise _refused("size", f"The object size must be a fraction of the photo's height in (0, 1], got "
                               f"{config.size!r}.")
    if not _finite(config.turn_deg):
        raise _refused("turn_deg", f"The turn must be a finite angle in degrees, got {config.turn_deg!r}.")
    if config.compose_spp is not None and not (_whole(config.compose_spp) and 1 <= config.compose_spp <= 65536):
        raise _refused("compose_spp", f"compose_spp must be a whole number from 1 to 65536, got "
                                      f"{config.compose_spp!r}.")
    try:
        check_camera_values(config.camera_overrides)
    except InputError as error:
        raise _refused("camera_overrides", str(error)) from None
    sun = config.sun_deg
    if sun is not None and not (len(sun) == 2 and all(_finite(v) for v in sun) and -90.0 <= sun[1] <= 90.0):
        raise _refused("sun_deg", f"The sun must be (azimuth, elevation) in finite degrees, the elevation within "
                                  f"+-90, got {sun!r}.")
    if not (_finite(config.sun_uncertainty_deg) and 0.0 <= config.sun_uncertainty_deg <= 180.0):
        raise _refused("sun_uncertainty_deg", f"The sun's uncertainty must be degrees within 0 and 180, got "
                                              f"{config.sun_uncertainty_deg!r}.")


def stage_subset(stages: Iterable[str]) -> tuple[str, ...]:
    """`stages` in the run's order when they run together: convert and/or light alone (ALONE_STAGES), or the
    pipeline (PIPELINE_STAGES, with any of OPTIONAL_STAGES); any other subset is one sentence (InputError)."""
    n = names()
    STAGES, ALONE_STAGES, PIPELINE_STAGES, OPTIONAL_STAGES = n.STAGES, n.ALONE_STAGES, n.PIPELINE_STAGES, n.OPTIONAL_STAGES
    listed = tuple(stages)
    unknown = [s for s in listed if s not in STAGES]
    if unknown:
        raise InputError(f"unknown stage '{unknown[0]}'; the stages are {', '.join(STAGES)}.")
    if not listed:
        raise InputError(f"stages must be a non-empty list from {', '.join(STAGES)}.")
    if len(set(listed)) != len(listed):
        raise InputError("stages lists a stage twice.")
    ordered = tuple(s for s in STAGES if s in listed)
    if set(ordered) <= set(ALONE_STAGES) or set(PIPELINE_STAGES) <= set(ordered):
        return ordered
    raise InputError(f"stages {', '.join(ordered)} do not run together: list {' and/or '.join(ALONE_STAGES)} "
                     f"alone, or {', '.join(PIPELINE_STAGES)} ({' and '.join(OPTIONAL_STAGES)} optional), which the "
                     "pipeline runs.")
