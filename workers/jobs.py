"""The jobs file of `scenefit batch` (and of the headless Blender recipe): a list of asset x scene pairs.

    [batch]                       # optional: how the batch runs
    retries = 1                   # extra attempts for a job that fails (then it is reported, not dropped)
    num_gpus = "auto"             # per job: "auto" (1 when the Ray cluster has GPUs, else 0) or a number
    num_cpus = 1                  # per job
    memory_gb = 8                 # per job, what Ray reserves (optional)
    workers = 2                   # Ray workers (actors, each loads its models once); default: what fits

    [models]                      # optional: the diffusion models (hub ids or folders), as ModelConfig
    base_model = "models/sd2-base"
    inpaint_model = "models/sd2-inpainting"
    local_files_only = true

    [defaults]                    # optional: keys every [[job]] gets unless it sets them
    preset = "draft"

    [[job]]
    name = "sofa-swamp"           # the output folder DIR/<name>/ (letters, digits, '.', '_', '-')
    asset = "assets/sofa"         # asset folder, or a file Blender reads (.blend with `object`)
    object = "Sofa"               # optional: the object inside a .blend / .glb
    photo = "photos/swamp.jpg"
    at = [0.5, 0.7]               # where the asset stands: fractions of the photo's width and height
    preset = "balanced"           # draft | balanced | final
    stages = ["convert", "light", "adapt", "compose", "bake"]
    prompt = "a leather sofa, soggy and stained with mud"   # optional prompts
    seed = 0                      # optional
    overrides = { adapt = { iterations = 50 } }   # optional: stage settings over the preset's
    object_size = 0.3             # optional: the asset's height as a fraction of the photo's (compose)
    camera = { fov = 50, pitch = -14, roll = 2 }  # optional, degrees: over the camera found from the photo
    sun = [-30, 45]               # optional: the dominant light's azimuth and elevation, as --sun takes them
    sun_uncertainty = 10          # optional: degrees that direction may be off (Blender's Pick Sun sends its own)
    scene = "indoor"              # optional: the light stage's scene type, as --scene (default: "auto")
    depth_model = "depth-anything/Depth-Anything-V2-Small-hf"   # optional: the light stage's depth model
    turn = 0                      # optional: degrees the asset turns about its up axis after facing the camera

Relative paths are relative to the jobs file. Everything is checked when the file is read, and a
problem is one sentence naming the job and the key.
"""
from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from ..core.base.errors import InputError
from ..core.guidance.models import ModelConfig

STAGE_TYPES = ("convert", "light", "adapt", "compose", "bake")   # pipeline order
PRESET_TYPES = ("draft", "balanced", "final")
MODE_TYPES = ("scene", "generate", "edit")
PROMPT_KEYS = ("prompt", "negative_prompt", "object_prompt", "instruction")
# Stages that read the photo and the placement.
PHOTO_STAGES = ("light", "compose")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_ASSET_FOLDER_FILE = "mesh.npz"


@dataclass(frozen=True)
class Job:
    """One asset x scene pair; paths are absolute (resolved against the jobs file)."""

    name: str
    asset: Path
    stages: tuple[str, ...]
    preset: str = "balanced"
    photo: Path | None = None
    at: tuple[float, float] | None = None
    object: str | None = None
    mode: str = "scene"
    prompt: str = ""
    negative_prompt: str = ""
    object_prompt: str = ""
    instruction: str = ""
    seed: int | None = None
    models: ModelConfig = field(default_factory=ModelConfig)   # the file's [models] table
    overrides: dict = field(default_factory=dict)   # {"convert"|"light"|"adapt": {setting: value}}
    # Where the asset stands and how the photo is seen, as `scenefit run`'s options and Run All's panel say it:
    object_size: float | None = None                # None: the default (DEFAULT_OBJECT_SIZE)
    camera: dict = field(default_factory=dict)      # {"fov"|"pitch"|"roll": degrees} over the estimate
    camera_source: str = "user"                     # "blender": the values are the artist's scene camera's (a
    camera_why: str = "given by the user"           # remote Run All), and camera_why says how they were read
    sun: tuple[float, float] | None = None          # the artist's dominant light (azimuth, elevation), degrees
    sun_uncertainty: float = 0.0                    # how far off `sun` may be, degrees
    scene: str = "auto"                             # the light stage's scene type: auto | indoor | outdoor
    depth_model: str | None = None                  # the light stage's depth model (hub id or folder; None: default)
    turn: float = 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(asset=str(self.asset), photo=None if self.photo is None else str(self.photo),
                 stages=list(self.stages), at=None if self.at is None else list(self.at),
                 sun=None if self.sun is None else list(self.sun))
        if not self.sun_uncertainty:   # (left out when unused, so a worker of an earlier version still takes the job)
            del d["sun_uncertainty"]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Job":
        """The job from `to_dict`'s plain form (how it crosses to a worker that names the package otherwise)."""
        values = dict(d)
        values.update(asset=Path(d["asset"]), photo=None if d.get("photo") is None else Path(d["photo"]),
                      stages=tuple(d["stages"]), at=None if d.get("at") is None else tuple(d["at"]),
                      models=ModelConfig(**d.get("models", {})), overrides=dict(d.get("overrides", {})),
                      sun=None if d.get("sun") is None else tuple(d["sun"]), camera=dict(d.get("camera", {})))
        return cls(**values)


@dataclass(frozen=True)
class BatchSettings:
    """The [batch] table: retries and what each job asks the scheduler for."""

    retries: int = 1
    num_gpus: float | str = "auto"
    num_cpus: float = 1.0
    memory_gb: float | None = None
    workers: int | None = None


@dataclass(frozen=True)
class JobsFile:
    path: Path
    jobs: tuple[Job, ...]
    settings: BatchSettings = field(default_factory=BatchSettings)


JOB_KEYS = ("name", "asset", "object", "photo", "at", "preset", "stages", "mode", *PROMPT_KEYS, "seed", "overrides",
            "object_size", "camera", "camera_source", "camera_why", "sun", "sun_uncertainty", "scene", "depth_model", "turn")
CAMERA_KEYS = {"fov": "fov_deg", "pitch": "pitch_deg", "roll": "roll_deg"}   # a job's names -> the pipeline's
MODEL_KEYS = ("base_model", "inpaint_model", "cache_dir", "local_files_only", "device_type", "dtype_type",
              "attention_slicing", "vae_slicing", "vae_tiling", "channels_last", "cpu_offload")
OVERRIDE_STAGES = ("convert", "light", "adapt", "compose")
BATCH_KEYS = tuple(BatchSettings.__dataclass_fields__)


def load_jobs(path: str | Path) -> JobsFile:
    """Read and check a jobs file; raises InputError with one sentence on the first problem."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"The jobs file '{path}' does not exist.") from None
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"The jobs file '{path}' cannot be read ({error}).") from None
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"The jobs file '{path}' is not valid TOML: {error}.") from None
    return parse_jobs(data, path)


def parse_jobs(data: dict, path: Path) -> JobsFile:
    """Check the parsed TOML of the jobs file at `path` (relative paths are taken from its folder)."""
    path = Path(path).resolve()
    unknown = sorted(set(data) - {"batch", "models", "defaults", "job"})
    if unknown:
        raise InputError(f"{path.name}: unknown table '{unknown[0]}'; a jobs file has [batch], [models], [defaults] "
                         f"and [[job]].")
    settings = _parse_settings(data.get("batch", {}), path)
    models = _parse_models(data.get("models", {}), path)
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise InputError(f"{path.name}: [defaults] must be a table of job keys.")
    _check_keys(defaults, JOB_KEYS, f"{path.name} [defaults]")
    if "name" in defaults:
        raise InputError(f"{path.name} [defaults]: 'name' cannot have a default; every job names its own folder.")
    entries = data.get("job", [])
    if not isinstance(entries, list) or not entries:
        raise InputError(f"{path.name}: no jobs; add at least one [[job]] table.")
    jobs, seen = [], set()
    for i, entry in enumerate(entries):
        job = replace(_parse_job({**defaults, **entry}, i, path), models=models)
        if job.name in seen:
            raise InputError(f"{path.name}: two jobs are named '{job.name}'; each job needs its own name (its folder).")
        seen.add(job.name)
        jobs.append(job)
    return JobsFile(path=path, jobs=tuple(jobs), settings=settings)


def _check_keys(table: dict, allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key '{unknown[0]}'; the keys are {', '.join(allowed)}.")


def _parse_settings(table: dict, path: Path) -> BatchSettings:
    if not isinstance(table, dict):
        raise InputError(f"{path.name}: [batch] must be a table.")
    where = f"{path.name} [batch]"
    _check_keys(table, BATCH_KEYS, where)
    retries = table.get("retries", 1)
    if not isinstance(retries, int) or isinstance(retries, bool) or not 0 <= retries <= 100:
        raise InputError(f"{where}: retries must be a whole number from 0 to 100, got {retries!r}.")
    num_gpus = table.get("num_gpus", "auto")
    if num_gpus != "auto" and not (_is_number(num_gpus) and num_gpus >= 0):
        raise InputError(f"{where}: num_gpus must be \"auto\" or a number >= 0, got {num_gpus!r}.")
    num_cpus = table.get("num_cpus", 1)
    if not (_is_number(num_cpus) and num_cpus > 0):
        raise InputError(f"{where}: num_cpus must be a number > 0, got {num_cpus!r}.")
    memory_gb = table.get("memory_gb")
    if memory_gb is not None and not (_is_number(memory_gb) and memory_gb > 0):
        raise InputError(f"{where}: memory_gb must be a number > 0, got {memory_gb!r}.")
    workers = table.get("workers")
    if workers is not None and not (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1):
        raise InputError(f"{where}: workers must be a whole number >= 1, got {workers!r}.")
    return BatchSettings(retries=retries, num_gpus=num_gpus if num_gpus == "auto" else float(num_gpus),
                         num_cpus=float(num_cpus), memory_gb=None if memory_gb is None else float(memory_gb),
                         workers=workers)


def _parse_models(table: dict, path: Path) -> ModelConfig:
    """The [models] table: ModelConfig's fields; a model or cache given as a path ('.', '/', '~') is
    taken relative to the jobs file, a hub id as it is."""
    if not isinstance(table, dict):
        raise InputError(f"{path.name}: [models] must be a table.")
    where = f"{path.name} [models]"
    _check_keys(table, MODEL_KEYS, where)
    values = {}
    for key, value in table.items():
        kind = bool if key not in ("base_model", "inpaint_model", "cache_dir", "device_type", "dtype_type") else str
        if not isinstance(value, kind):
            raise InputError(f"{where}: {key} must be a {'true/false' if kind is bool else 'string'}, got {value!r}.")
        if key in ("base_model", "inpaint_model", "cache_dir") and value.startswith((".", "/", "~")):
            value = str(_resolve(value, path))
        values[key] = value
    try:
        return ModelConfig(**values)
    except InputError as error:
        raise InputError(f"{where}: {error}") from None


def _parse_overrides(value, where: str) -> dict:
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise InputError(f"{where}: overrides must be a table of stage tables, e.g. {{ adapt = {{ iterations = 50 }} }}.")
    unknown = sorted(set(value) - set(OVERRIDE_STAGES))
    if unknown:
        raise InputError(f"{where}: overrides names unknown stage '{unknown[0]}'; it takes {', '.join(OVERRIDE_STAGES)}.")
    return {stage: dict(settings) for stage, settings in value.items()}


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _parse_job(entry: dict, index: int, path: Path) -> Job:
    if not isinstance(entry, dict):
        raise InputError(f"{path.name}: job {index + 1} must be a [[job]] table.")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"{path.name}: job {index + 1} needs a name of letters, digits, '.', '_' or '-' "
                         f"(it becomes its folder), got {name!r}.")
    where = f"{path.name} job '{name}'"
    _check_keys(entry, JOB_KEYS, where)

    def text(key: str) -> str:
        value = entry.get(key, "")
        if not isinstance(value, str):
            raise InputError(f"{where}: {key} must be a string, got {value!r}.")
        return value

    stages = entry.get("stages", list(STAGE_TYPES))
    if not isinstance(stages, list) or not stages or not all(isinstance(s, str) for s in stages):
        raise InputError(f"{where}: stages must be a non-empty list from {', '.join(STAGE_TYPES)}.")
    bad = [s for s in stages if s not in STAGE_TYPES]
    if bad:
        raise InputError(f"{where}: unknown stage '{bad[0]}'; the stages are {', '.join(STAGE_TYPES)}.")
    if len(set(stages)) != len(stages):
        raise InputError(f"{where}: stages lists a stage twice.")
    stages = tuple(s for s in STAGE_TYPES if s in stages)

    preset = entry.get("preset", "balanced")
    if preset not in PRESET_TYPES:
        raise InputError(f"{where}: preset must be one of {', '.join(PRESET_TYPES)}, got {preset!r}.")
    mode = entry.get("mode", "scene")
    if mode not in MODE_TYPES:
        raise InputError(f"{where}: mode must be one of {', '.join(MODE_TYPES)}, got {mode!r}.")

    asset_text = text("asset")
    if not asset_text:
        raise InputError(f"{where}: asset is missing (an asset folder or a file Blender reads).")
    asset = _resolve(asset_text, path)
    if not asset.exists():
        raise InputError(f"{where}: the asset '{asset}' does not exist.")
    if asset.is_dir() and not (asset / _ASSET_FOLDER_FILE).is_file():
        from ..core.data.asset_io import resolve_asset_path   # a folder holding one glTF/FBX/...: that file

        try:
            asset = resolve_asset_path(asset)
        except InputError as error:
            raise InputError(f"{where}: {error}") from None
        if asset.is_dir():
            raise InputError(f"{where}: the folder '{asset}' is not a SceneFit asset folder (it has no mesh.npz) "
                             "and holds no file Blender reads.")
    obj = entry.get("object")
    if obj is not None and (not isinstance(obj, str) or not obj):
        raise InputError(f"{where}: object must name an object in the asset file, got {obj!r}.")
    if obj is not None and asset.is_dir():
        raise InputError(f"{where}: object is for a Blender/glTF file; '{asset.name}' is an asset folder.")

    photo_text = text("photo")
    photo = _resolve(photo_text, path) if photo_text else None
    if photo is not None and not photo.is_file():
        raise InputError(f"{where}: the photo '{photo}' does not exist.")
    needs_photo = [s for s in stages if s in PHOTO_STAGES] + (["adapt"] if "adapt" in stages and mode == "scene" else [])
    if photo is None and needs_photo:
        raise InputError(f"{where}: stage '{needs_photo[0]}' needs a photo; add photo = \"...\".")
    at = entry.get("at")
    if at is not None:
        if not (isinstance(at, list) and len(at) == 2 and all(_is_number(v) for v in at)
                and all(0.0 <= v <= 1.0 for v in at)):
            raise InputError(f"{where}: at must be [x, y], fractions of the photo's width and height in [0, 1], "
                             f"got {at!r}.")
        at = (float(at[0]), float(at[1]))
    elif needs_photo:
        raise InputError(f"{where}: stage '{needs_photo[0]}' needs the placement; add at = [x, y] (fractions).")

    prompts = {k: text(k) for k in PROMPT_KEYS}
    if "adapt" in stages:
        if mode == "edit" and not (prompts["prompt"].strip() or (prompts["object_prompt"].strip()
                                                                 and prompts["instruction"].strip())):
            raise InputError(f"{where}: stage 'adapt' in mode 'edit' needs prompt, or object_prompt and instruction.")
    seed = entry.get("seed")
    if seed is not None and not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
        raise InputError(f"{where}: seed must be a whole number >= 0, got {seed!r}.")
    overrides = _parse_overrides(entry.get("overrides", {}), where)
    return Job(name=name, asset=asset, stages=stages, preset=preset, photo=photo, at=at, object=obj, mode=mode,
               seed=seed, overrides=overrides, **prompts, **_parse_view(entry, where))


def _parse_view(entry: dict, where: str) -> dict:
    """object_size, camera (and where its values come from), sun, scene and turn: how the job sees the photo,
    checked as `scenefit run` checks them."""
    view: dict = {}
    size = entry.get("object_size")
    if size is not None:
        if not (_is_number(size) and 0.0 < size <= 1.0):
            raise InputError(f"{where}: object_size must be a fraction of the photo's height in (0, 1], got {size!r}.")
        view["object_size"] = float(size)
    camera = entry.get("camera", {})
    if not isinstance(camera, dict) or set(camera) - set(CAMERA_KEYS) \
            or not all(_is_number(v) and math.isfinite(v) for v in camera.values()):
        raise InputError(f"{where}: camera must be a table of fov, pitch and roll in degrees, e.g. "
                         f"{{ fov = 50, pitch = -14 }}, got {camera!r}.")
    if "fov" in camera and not 0.0 < camera["fov"] < 180.0:
        raise InputError(f"{where}: camera fov must be within (0, 180) degrees, got {camera['fov']!r}.")
    view["camera"] = {k: float(v) for k, v in camera.items()}
    source, why = entry.get("camera_source", "user"), entry.get("camera_why", "given by the user")
    if source not in ("user", "blender") or not isinstance(why, str):
        raise InputError(f"{where}: camera_source must be 'user' or 'blender' and camera_why a string, got "
                         f"{source!r} and {why!r}.")
    view.update(camera_source=source, camera_why=why)
    sun = entry.get("sun")
    if sun is not None:
        if not (isinstance(sun, list) and len(sun) == 2 and all(_is_number(v) and math.isfinite(v) for v in sun)
                and -90.0 <= sun[1] <= 90.0):
            raise InputError(f"{where}: sun must be [azimuth, elevation] in degrees (elevation within +-90), "
                             f"e.g. [-30, 45], got {sun!r}.")
        view["sun"] = (float(sun[0]), float(sun[1]))
    spread = entry.get("sun_uncertainty", 0.0)
    if not (_is_number(spread) and 0.0 <= spread <= 180.0):
        raise InputError(f"{where}: sun_uncertainty must be degrees within 0 and 180, got {spread!r}.")
    view["sun_uncertainty"] = float(spread)
    scene = entry.get("scene", "auto")
    if scene not in ("auto", "indoor", "outdoor"):
        raise InputError(f"{where}: scene must be auto, indoor or outdoor, got {scene!r}.")
    view["scene"] = scene
    depth_model = entry.get("depth_model")
    if depth_model is not None:
        if not isinstance(depth_model, str) or not depth_model.strip():
            raise InputError(f"{where}: depth_model must be a hub id or a folder, got {depth_model!r}.")
        view["depth_model"] = depth_model
    turn = entry.get("turn", 0.0)
    if not (_is_number(turn) and math.isfinite(turn)):
        raise InputError(f"{where}: turn must be degrees, got {turn!r}.")
    view["turn"] = float(turn)
    return view


def _resolve(text: str, jobs_path: Path) -> Path:
    p = Path(text).expanduser()
    return (p if p.is_absolute() else jobs_path.parent / p).resolve()


def with_user_paths(text: str, copy: Job, job: Job) -> str:
    """`text` (a worker's error about `copy`, the job with its inputs unpacked into a temporary
    folder) naming the user's files instead: `.../scenefit-job-x/in/photo/broken.png` becomes the
    photo the jobs file named. Unpacked files keep their names below asset/ and photo/, so each
    folder maps to the folder of the user's file."""
    pairs = [(copy.asset, job.asset)] + ([(copy.photo, job.photo)] if copy.photo and job.photo else [])
    for unpacked, original in pairs:
        text = text.replace(str(unpacked), str(original))
        text = text.replace(f"{unpacked.parent}{os.sep}", f"{original.parent}{os.sep}")
    return text
