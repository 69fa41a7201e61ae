"""A RunConfig as a table of plain values: a jobs file's [[job]] (TOML) and a job sent to a worker (JSON).

Each RunConfig field has one key here (`RUN_KEYS`), spelled as `scenefit run`'s option says it
(`object_size` for --object-size, `sun` for --sun, `camera = { fov, pitch, roll }` for --fov, --pitch,
--roll); the two fields a table cannot hold are named in `NOT_IN_A_TABLE` with the reason. So a key the
run does not take is refused, and a key it takes reaches it: `run_config(table)` builds the config,
`run_table(config)` writes it back, and a test walks RunConfig's fields against both.

Overrides are checked against the stage configs' own fields and types here, when the table is read,
so a misspelt or mistyped setting is one sentence before any job runs.
"""
from __future__ import annotations

import math
import types
import typing
from dataclasses import dataclass, fields, is_dataclass
from typing import Any, Callable

from ..base.errors import InputError
from ..base.names import CAMERA_SOURCES, GUIDANCE_TYPES, MODES, PRESETS, SCENE_TYPES
from ..stages.camera import CAMERA_VALUES
from ..stages.compose import SHADOW_TYPES
from .presets import stage_config, with_overrides
from .registry import names
from .run_config import RunConfig

# Fields a table does not carry: photo_camera is a PhotoCamera object a Python caller already holds (a table
# gives camera values instead); models come from the jobs file's [models] table, shared by its jobs.
NOT_IN_A_TABLE = {"photo_camera": "a PhotoCamera object; a table gives camera = { fov, pitch, roll, shift_x, shift_y } instead",
                  "models": "the jobs file's [models] table, shared by every job"}
# camera = { fov, pitch, roll, shift_x, shift_y }: degrees, and the lens shift in the photo's longer side
CAMERA_TABLE = {"fov": "fov_deg", "pitch": "pitch_deg", "roll": "roll_deg", "shift_x": "shift_x", "shift_y": "shift_y"}
assert set(CAMERA_TABLE.values()) == set(CAMERA_VALUES)


@dataclass(frozen=True)
class RunKey:
    """A table key and the RunConfig field it gives: `read(value, where)` checks the value's shape and returns
    the field's value; `write(field value)` gives the table's value back. `help` is what the key means, said
    once for the jobs file and `scenefit run`'s option of the same name (cli/run.py makes each option from
    its key); `kind` is how a command line spells its value ("text", "number", "whole", "angles": AZ,EL,
    "points": three X,Y, "camera": --fov/--pitch/--roll, "settings": --set stage.setting=value, "blender":
    Blender's own, no option) and `choices` the names it takes."""

    key: str
    field: str
    read: Callable[[Any, str], Any]
    write: Callable[[Any], Any] = lambda value: value
    help: str = ""
    kind: str = "text"
    choices: tuple[str, ...] | None = None


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _text(key: str, optional: bool = False) -> Callable[[Any, str], Any]:
    def read(value: Any, where: str) -> Any:
        if optional and value is None:
            return None
        if not isinstance(value, str):
            raise InputError(f"{where}: {key} must be a string, got {_shown(value)}.")
        return value
    return read


def _number(key: str) -> Callable[[Any, str], float]:
    def read(value: Any, where: str) -> float:
        if not (_is_number(value) and math.isfinite(value)):
            raise InputError(f"{where}: {key} must be a finite number, got {_shown(value)}.")
        return float(value)
    return read


def _whole(key: str) -> Callable[[Any, str], int | None]:
    def read(value: Any, where: str) -> int | None:
        if value is not None and not (isinstance(value, int) and not isinstance(value, bool)):
            raise InputError(f"{where}: {key} must be a whole number, got {_shown(value)}.")
        return value
    return read


def _sun(value: Any, where: str) -> tuple[float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(_is_number(v) for v in value)):
        raise InputError(f"{where}: sun must be [azimuth, elevation] in degrees, e.g. [-30, 45], got {_shown(value)}.")
    return float(value[0]), float(value[1])


def _shadow(value: Any, where: str) -> tuple[str, str, str]:
    if not (isinstance(value, (list, tuple)) and len(value) == 3 and all(isinstance(v, str) for v in value)):
        raise InputError(f"{where}: sun_shadow must be the shadow's foot, top and tip, three points as --at takes "
                         f"them, e.g. [\"0.4,0.8\", \"0.4,0.5\", \"0.6,0.85\"], got {_shown(value)}.")
    return tuple(value)


def _camera(value: Any, where: str) -> dict[str, float]:
    if not isinstance(value, dict) or set(value) - set(CAMERA_TABLE) or not all(_is_number(v) for v in value.values()):
        raise InputError(f"{where}: camera must be a table of fov, pitch and roll in degrees (and shift_x, shift_y), e.g. "
                         f"{{ fov = 50, pitch = -14 }}, got {_shown(value)}.")
    return {CAMERA_TABLE[k]: float(v) for k, v in value.items()}


def _overrides(value: Any, where: str) -> dict[str, dict[str, Any]]:
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise InputError(f"{where}: overrides must be a table of stage tables, e.g. "
                         "{ adapt = { iterations = 50 } }.")
    configured = names().CONFIG_STAGES
    unknown = sorted(set(value) - set(configured))
    if unknown:
        raise InputError(f"{where}: overrides names unknown stage '{unknown[0]}'; it takes {', '.join(configured)}.")
    return {stage: dict(settings) for stage, settings in value.items()}


RUN_KEYS: tuple[RunKey, ...] = (
    RunKey("preset", "preset", _text("preset"), help="draft / balanced / final (the paper's values) for every stage",
           choices=PRESETS),
    RunKey("mode", "mode", _text("mode"), help="adapt: scene (fit the photo), generate (a new appearance from the "
           "prompt) or edit (change it as the instruction says)", choices=MODES),
    RunKey("prompt", "prompt", _text("prompt"), help="adapt: what the asset should become in this scene (default "
           "from its name)"),
    RunKey("negative_prompt", "negative_prompt", _text("negative_prompt"),
           help="adapt: what the asset should not look like"),
    RunKey("object_prompt", "object_prompt", _text("object_prompt"), help="adapt: the object, e.g. 'a leather sofa' "
           "(edit: with the instruction it makes the prompt; on the command line without --prompt, a language "
           "model writes the prompt from it and --scene-prompt)"),
    RunKey("instruction", "instruction", _text("instruction"), help="adapt, mode edit: how to change the asset, "
           "e.g. 'add dust to the sofa'"),
    RunKey("seed", "seed", _whole("seed"), help="convert's fit and adapt's noise (default: each stage's)",
           kind="whole"),
    RunKey("guidance_type", "guidance_type", _text("guidance_type"), help="adapt (and the light critic) with "
           "Stable Diffusion 2 (sd2), not at all (none), or when its weights are here (auto)", choices=GUIDANCE_TYPES),
    RunKey("object_size", "size", _number("object_size"), help="compose: the fraction of the photo's height the "
           "asset spans", kind="number"),
    RunKey("shadow_type", "shadow_type", _text("shadow_type"), help="compose: ratio (shadow catcher), paper "
           "(thresholded) or none", choices=SHADOW_TYPES),
    RunKey("compose_spp", "compose_spp", _whole("compose_spp"), help="compose: samples per pixel (default: from "
           "the preset's noise target)", kind="whole"),
    RunKey("fspy", "fspy", _text("fspy", optional=True), help="an fSpy project of the photo: its solved camera is "
           "used"),
    RunKey("camera", "camera_overrides", _camera,
           lambda value: {k: value[f] for k, f in CAMERA_TABLE.items() if value.get(f) is not None},
           help="the photo's camera over the estimate: fov, pitch and roll in degrees (and the lens shift)",
           kind="camera"),
    RunKey("camera_source", "camera_source", _text("camera_source"), help="where the camera values come from",
           kind="blender", choices=CAMERA_SOURCES),
    RunKey("camera_why", "camera_why", _text("camera_why"), help="the camera values' source, as the report says it",
           kind="blender"),
    RunKey("turn", "turn_deg", _number("turn"), help="compose: degrees the asset turns about its up axis after "
           "facing the camera", kind="number"),
    RunKey("sun", "sun_deg", lambda value, where: None if value is None else _sun(value, where),
           lambda value: None if value is None else list(value),
           help="light: the dominant light's azimuth (from the photo's view direction, positive to the right) and "
                "elevation above the horizon, degrees (default: guessed from the photo)", kind="angles"),
    RunKey("sun_shadow", "sun_shadow", lambda value, where: None if value is None else _shadow(value, where),
           lambda value: None if value is None else list(value),
           help="light: the sun from a shadow in the photo: the foot of something upright on the floor, its top "
                "and the tip of its shadow, each X,Y as --at takes it", kind="points"),
    RunKey("sun_uncertainty", "sun_uncertainty_deg", _number("sun_uncertainty"), help="light: degrees the sun's "
           "direction may be off", kind="number"),
    RunKey("scene", "scene_type", _text("scene"), help="light: the photo's scene type (default: decided from the "
           "photo)", choices=SCENE_TYPES),
    RunKey("depth_model", "depth_model", _text("depth_model", optional=True), help="light: hub id or local folder "
           "of a transformers depth model"),
    RunKey("overrides", "stage_overrides", _overrides, help="stage settings over the preset's, e.g. adapt's "
           "iterations (docs/technical/stage-settings.md lists them)", kind="settings"),
)
KEYS = tuple(k.key for k in RUN_KEYS)
_BY_KEY = {k.key: k for k in RUN_KEYS}


def run_config(table: dict[str, Any], where: str, stages: tuple[str, ...] | None = None, **given: Any) -> RunConfig:
    """The RunConfig of `table` (keys of RUN_KEYS; others are the caller's to refuse), with `given` fields
    (models) over it; every problem one sentence beginning with `where`. The settings of `stages` (those
    the run will resolve) are checked against the stage configs they go to."""
    stages = names().CONFIG_STAGES if stages is None else stages
    values = {_BY_KEY[k].field: _BY_KEY[k].read(v, where) for k, v in table.items() if k in _BY_KEY}
    # Guidance is adapt's (and the light critic's beside it): a run without adapt has none.
    values.setdefault("guidance_type", "auto" if "adapt" in stages else "none")
    if "adapt" not in stages and values["guidance_type"] != "none":
        raise InputError(f"{where}: guidance_type {values['guidance_type']!r} is for stage adapt, which is not "
                         "listed; add adapt to the stages or leave guidance_type out.")
    try:
        config = RunConfig(**values, **given)
    except InputError as error:   # (its field's key, where RunConfig says which)
        key = next((k.key for k in RUN_KEYS if k.field == getattr(error, "field", None)), None)
        raise InputError(f"{where}: {key + ': ' if key else ''}{error}") from None
    check_stage_settings(config, where, stages)
    return config


def run_table(config: RunConfig) -> dict[str, Any]:
    """`config` as a table `run_config` reads back to the same config (models aside: NOT_IN_A_TABLE)."""
    if config.photo_camera is not None:
        raise InputError("A run given a PhotoCamera object has no table; give its angles as camera values.")
    return {k.key: k.write(getattr(config, k.field)) for k in RUN_KEYS}


def check_stage_settings(config: RunConfig, where: str, stages: tuple[str, ...] | None = None) -> None:
    """The config of each of `stages` as the run resolves it, built now: an override the stage config does not
    have, or of the wrong type, and a mode without its prompts, are one sentence naming `where` and the key."""
    configured = names().CONFIG_STAGES
    stages = configured if stages is None else stages
    for stage in (s for s in configured if s in stages or s in config.stage_overrides):
        overrides = config.overrides(stage)
        # (a scene run without a prompt is given one from the asset's name: any text stands for it here)
        prompt = config.prompt or ("x" if config.mode == "scene" else "")
        owns: dict[str, dict[str, Any]] = {
            "adapt": {"mode_type": config.mode, "prompt": prompt, "object_prompt": config.object_prompt,
                      "instruction": config.instruction},
            "compose": {"size": config.size, "shadow_type": config.shadow_type, "spp": config.compose_spp}}
        own = owns.get(stage, {})
        try:
            _check_types(overrides, stage_config(stage, config.preset, **own), f"{where}: overrides.{stage}")
            stage_config(stage, config.preset, **with_overrides(own, overrides))
        except (TypeError, ValueError) as error:
            raise InputError(f"{where}: the {stage} stage's settings are refused ({error}).") from None
        except InputError as error:
            text = str(error)
            raise InputError(text if text.startswith(where) else f"{where}: {stage}: {text}") from None


def _check_types(overrides: dict[str, Any], config: Any, where: str) -> None:
    """Each override a field of `config` (a stage config, or one nested in it), of that field's type."""
    hints = typing.get_type_hints(type(config))
    names = [f.name for f in fields(config)]
    for key, value in overrides.items():
        if key not in names:
            raise InputError(f"{where}: {type(config).__name__} has no setting '{key}'; its settings are "
                             f"{', '.join(names)}.")
        current = getattr(config, key)
        if isinstance(value, dict) and is_dataclass(current):
            _check_types(value, current, f"{where}.{key}")
        elif value is not None and not _fits(value, hints.get(key, Any)):
            raise InputError(f"{where}.{key} must be {_type_words(hints.get(key))}, got {_shown(value)}.")


def _fits(value: Any, hint: Any) -> bool:
    """Whether a plain (TOML/JSON) value can stand for a field of type `hint`: numbers finite, a tuple as a list,
    a nested config as a table; types it does not know are left to the config's own checks."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return _is_number(value) and math.isfinite(value)
    if hint is str:
        return isinstance(value, str)
    if hint is tuple or origin is tuple:
        return isinstance(value, (list, tuple))
    if isinstance(hint, type) and is_dataclass(hint):
        return isinstance(value, (dict, hint))
    return True


def _type_words(hint: Any) -> str:
    words = {bool: "true or false", int: "a whole number", float: "a finite number", str: "a string"}
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    args = [a for a in typing.get_args(hint) if a is not type(None)] if union else [hint]
    return " or ".join(words.get(a, "a list" if a is tuple or typing.get_origin(a) is tuple else
                                 getattr(a, "__name__", str(a))) for a in args)


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."

