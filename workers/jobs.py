"""The jobs file of `scenefit batch` (and of the headless Blender recipe): a list of asset x scene pairs.

    [batch]                       # optional: how the batch runs
    retries = 1                   # extra attempts for a job that fails (then it is reported, not dropped)
    num_gpus = "auto"             # per job: "auto" (1 when the Ray cluster has GPUs, else 0) or a number
    num_cpus = 1                  # per job
    memory_gb = 8                 # per job, what Ray reserves (optional)
    workers = 2                   # Ray workers (actors, each loads its models once); default: what fits

    [models]                      # optional: the diffusion models (hub ids or folders), as ModelConfig
    base_model = "models/sd2-base"         # a folder beside this file (refused when missing), or a hub id
    inpaint_model = "models/sd2-inpainting"
    local_files_only = true

    [defaults]                    # optional: keys every [[job]] gets unless it sets them
    preset = "draft"

    [[job]]
    name = "sofa-swamp"           # the output folder DIR/<name>/ (letters, digits, '.', '_', '-')
    asset = "assets/sofa"         # asset folder, or a file Blender reads (.blend with `object`)
    object = "Sofa"               # optional: the object inside a .blend / .glb
    photo = "photos/swamp.jpg"    # the scene photo (a job of the convert stage alone needs none)
    at = [0.5, 0.7]               # where the asset stands: fractions of the photo's width and height
    preset = "balanced"           # draft | balanced | final
    stages = ["convert", "light", "adapt", "compose", "bake"]   # which stages run, as `scenefit run` orders them
    mode = "scene"                # scene | generate | edit (adapt)
    prompt = "a leather sofa, soggy and stained with mud"   # optional prompts: also negative_prompt, and for
    # mode "edit" object_prompt and instruction (the prompt is made of them when it is left out)
    seed = 0                      # optional: convert's fit and adapt's noise
    overrides = { adapt = { iterations = 50 } }   # optional: stage settings over the preset's
    object_size = 0.3             # optional: the asset's height as a fraction of the photo's (compose)
    camera = { fov = 50, pitch = -14, roll = 2 }  # optional, degrees: over the camera found from the photo
    sun = [-30, 45]               # optional: the dominant light's azimuth and elevation, as --sun takes them
    sun_uncertainty = 10          # optional: degrees that direction may be off (Blender's Pick Sun sends its own)
    scene = "indoor"              # optional: the light stage's scene type, as --scene (default: "auto")
    depth_model = "depth-anything/Depth-Anything-V2-Small-hf"   # optional: the light stage's depth model
    turn = 0                      # optional: degrees the asset turns about its up axis after facing the camera
    # also guidance_type, shadow_type, compose_spp, fspy, sun_shadow: the table in docs/technical/jobs-file.md

A job's keys other than name, asset, object, photo, at and stages are `scenefit run`'s settings, its
RunConfig (core/pipeline/run_table.py holds the one table of them); a key the run does not take is
refused. A job lists its stages in any order; the subsets that run (core/pipeline/run.stage_subset) are
convert and/or light alone, or the pipeline (convert, light, compose; adapt and bake optional); any
other is refused.

Relative paths are relative to the jobs file. Everything is checked when the file is read, and a
problem is one sentence naming the job and the key.
"""
from __future__ import annotations

import math
import os
import re
import struct
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from ..core.base.errors import InputError
from ..core.pipeline.registry import PHOTO_STAGES, STAGES
from ..core.guidance.models import ModelConfig
from ..core.pipeline.run_config import RunConfig, stage_subset
from ..core.pipeline.run_table import KEYS as RUN_KEYS, run_config, run_table

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_ASSET_FOLDER_FILE = "mesh.npz"
# What a jobs file may be: its size, and how deep its tables and arrays nest (a job's overrides are the deepest,
# about 5). Beyond them it is refused in one sentence before (size) or after (depth) TOML reads it.
MAX_JOBS_FILE_BYTES = 16 * 1024 * 1024
MAX_DEPTH = 16


@dataclass(frozen=True)
class Job:
    """One asset x scene pair: which files, where the asset stands, which stages, and the run's settings
    (`run`, the same RunConfig `scenefit run` builds). Paths are absolute (resolved against the jobs file)."""

    name: str
    asset: Path
    stages: tuple[str, ...]
    photo: Path | None = None
    at: tuple[float, float] | None = None
    object: str | None = None
    run: RunConfig = field(default_factory=RunConfig)

    @property
    def models(self) -> ModelConfig:
        return self.run.models

    def to_dict(self) -> dict:
        """The job as plain data: its own keys, [models] as a table, and the run's keys that differ from
        the defaults (core/pipeline/run_table.py), as a jobs file would give them."""
        # (what equals the default is left out, guidance's default being the stages' (run_table.run_config): a
        # worker of an earlier version takes a job that uses none of the keys it does not know)
        defaults = run_table(RunConfig(guidance_type="auto" if "adapt" in self.stages else "none"))
        settings = {k: v for k, v in run_table(self.run).items() if v != defaults[k]}
        fspy = {"fspy": str(self.run.fspy)} if self.run.fspy else {}
        return {"name": self.name, "asset": str(self.asset), "photo": None if self.photo is None else str(self.photo),
                "at": None if self.at is None else list(self.at), "object": self.object, "stages": list(self.stages),
                "models": _plain_models(self.run.models), **settings, **fspy}

    @classmethod
    def from_dict(cls, d: dict) -> "Job":
        """The job from `to_dict`'s plain form (how it crosses to a worker that names the package otherwise)."""
        own = ("name", "asset", "photo", "at", "object", "stages", "models")
        _check_keys(d, (*own, *RUN_KEYS), f"job '{d.get('name')}'")
        stages = tuple(d["stages"])
        run = run_config({k: v for k, v in d.items() if k not in own}, f"job '{d.get('name')}'", stages,
                         models=ModelConfig(**d.get("models", {})))
        return cls(name=d["name"], asset=Path(d["asset"]), stages=stages,
                   photo=None if d.get("photo") is None else Path(d["photo"]),
                   at=None if d.get("at") is None else tuple(d["at"]), object=d.get("object"), run=run)


def _plain_models(models: ModelConfig) -> dict:
    return {f.name: getattr(models, f.name) for f in fields(models)}


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


OWN_KEYS = ("name", "asset", "object", "photo", "at", "stages")   # a job's own; the rest are the run's
JOB_KEYS = (*OWN_KEYS, *RUN_KEYS)
MODEL_KEYS = tuple(f.name for f in fields(ModelConfig))
BATCH_KEYS = tuple(BatchSettings.__dataclass_fields__)


def load_jobs(path: str | Path) -> JobsFile:
    """Read and check a jobs file; raises InputError with one sentence on the first problem."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_JOBS_FILE_BYTES + 1)
        if len(raw) > MAX_JOBS_FILE_BYTES:
            raise InputError(f"The jobs file '{path}' is over {MAX_JOBS_FILE_BYTES // 2 ** 20} MiB; a jobs file "
                             "lists jobs, not data. Split it into several files.")
        data = tomllib.loads(raw.decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"The jobs file '{path}' does not exist.") from None
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"The jobs file '{path}' cannot be read ({error}).") from None
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"The jobs file '{path}' is not valid TOML: {error}.") from None
    except RecursionError:
        raise InputError(f"The jobs file '{path}' nests its arrays or tables too deep to read; a job's values "
                         f"nest at most {MAX_DEPTH} levels.") from None
    if _depth(data) > MAX_DEPTH:
        raise InputError(f"The jobs file '{path}' nests its arrays or tables more than {MAX_DEPTH} levels deep; "
                         "a job's values are never that deep.")
    return parse_jobs(data, path)


def _depth(value, level: int = 0) -> int:
    """How deep `value` nests, looked at no further than just past MAX_DEPTH."""
    if level > MAX_DEPTH or not isinstance(value, (dict, list)):
        return level
    items = value.values() if isinstance(value, dict) else value
    return max((_depth(v, level + 1) for v in items), default=level + 1)


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
        if not isinstance(entry, dict):
            raise InputError(f"{path.name}: job {i + 1} must be a [[job]] table.")
        job = _parse_job({**defaults, **entry}, i, path, models)
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
    if not _whole(retries) or not 0 <= retries <= 100:
        raise InputError(f"{where}: retries must be a whole number from 0 to 100, got {retries!r}.")
    num_gpus = table.get("num_gpus", "auto")
    if num_gpus != "auto" and not (_is_number(num_gpus) and 0 <= num_gpus <= 1024):
        raise InputError(f"{where}: num_gpus must be \"auto\" or a number from 0 to 1024, got {num_gpus!r}.")
    num_cpus = table.get("num_cpus", 1)
    if not (_is_number(num_cpus) and 0 < num_cpus <= 4096):
        raise InputError(f"{where}: num_cpus must be a number > 0 and at most 4096, got {num_cpus!r}.")
    memory_gb = table.get("memory_gb")
    if memory_gb is not None and not (_is_number(memory_gb) and 0 < memory_gb <= 2 ** 20):
        raise InputError(f"{where}: memory_gb must be a number > 0 (and below a million), got {memory_gb!r}.")
    workers = table.get("workers")
    if workers is not None and not (_whole(workers) and 1 <= workers <= 4096):
        raise InputError(f"{where}: workers must be a whole number from 1 to 4096, got {workers!r}.")
    return BatchSettings(retries=retries, num_gpus=num_gpus if num_gpus == "auto" else float(num_gpus),
                         num_cpus=float(num_cpus), memory_gb=None if memory_gb is None else float(memory_gb),
                         workers=workers)


def _parse_models(table: dict, path: Path) -> ModelConfig:
    """The [models] table: ModelConfig's fields; a model or cache given as a path is taken relative to the
    jobs file and must be a folder there, a hub id is taken as it is (_model_path)."""
    if not isinstance(table, dict):
        raise InputError(f"{path.name}: [models] must be a table.")
    where = f"{path.name} [models]"
    _check_keys(table, MODEL_KEYS, where)
    values = {}
    for key, value in table.items():
        kind = bool if key not in ("base_model", "inpaint_model", "cache_dir", "device_type", "dtype_type") else str
        if not isinstance(value, kind):
            raise InputError(f"{where}: {key} must be a {'true/false' if kind is bool else 'string'}, got {value!r}.")
        if key in MODEL_PATH_KEYS and isinstance(value, str):
            value = _model_path(key, value, path, where)
        values[key] = value
    try:
        return ModelConfig(**values)
    except InputError as error:
        raise InputError(f"{where}: {error}") from None


MODEL_PATH_KEYS = ("base_model", "inpaint_model", "cache_dir")


def _model_path(key: str, value: str, path: Path, where: str) -> str:
    """A [models] value as the run reads it: a folder (absolute) when it is given as a path ('.', '/', '~'), is
    a folder beside the jobs file, starts with one (`models/sd2-base` where `models/` is there), or is the
    cache; else a hub id. A folder that does not exist is refused now: a run would take it for a hub id,
    find no such model and go on without adaptation."""
    folder = _resolve(value, path)
    first = _resolve(Path(value).parts[0], path) if Path(value).parts else folder
    if key == "cache_dir" or value.startswith((".", "/", "~")) or folder.exists() or \
            (len(Path(value).parts) > 1 and first.is_dir()):
        if not folder.is_dir():
            hub = " or a hub id such as 'stabilityai/stable-diffusion-2-base'" if key != "cache_dir" else ""
            raise InputError(f"{where}: {key} '{value}' names the folder '{folder}', which does not exist; give "
                             f"an existing folder (relative to the jobs file){hub}.")
        return str(folder)
    return value


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _parse_job(entry: dict, index: int, path: Path, models: ModelConfig) -> Job:
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"{path.name}: job {index + 1} needs a name of letters, digits, '.', '_' or '-' "
                         f"(it becomes its folder), got {name!r}.")
    where = f"{path.name} job '{name}'"
    _check_keys(entry, JOB_KEYS, where)
    stages = _parse_stages(entry.get("stages", list(STAGES)), where)
    table = {k: v for k, v in entry.items() if k in RUN_KEYS}
    if isinstance(table.get("fspy"), str):
        table["fspy"] = str(_existing(table["fspy"], path, where, "fspy", "fSpy project"))
    if isinstance(table.get("depth_model"), str) and _names_a_path(table["depth_model"], path):
        table["depth_model"] = str(_resolve(table["depth_model"], path))   # a folder, from the jobs file's
    run = run_config(table, where, stages, models=models)
    asset, obj = _parse_asset(entry, path, where)
    photo_text = entry.get("photo", "")
    if not isinstance(photo_text, str):
        raise InputError(f"{where}: photo must be a string, got {photo_text!r}.")
    photo = _existing(photo_text, path, where, "photo", "photo") if photo_text else None
    needs_photo = [s for s in stages if s in PHOTO_STAGES] + (["adapt"] if "adapt" in stages and run.mode == "scene"
                                                              else [])
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
    if run.sun_shadow is not None and photo is not None:
        _check_shadow_points(run.sun_shadow, photo, where)
    return Job(name=name, asset=asset, stages=stages, photo=photo, at=at, object=obj, run=run)


def _parse_stages(stages, where: str) -> tuple[str, ...]:
    """The job's stages in the run's order when they run together (core/pipeline/run.stage_subset, what
    run_pipeline takes); any other subset is refused now, not failed and retried later."""
    if not isinstance(stages, list) or not all(isinstance(s, str) for s in stages):
        raise InputError(f"{where}: stages must be a non-empty list from {', '.join(STAGES)}.")
    try:
        return stage_subset(stages)
    except InputError as error:
        raise InputError(f"{where}: {error}") from None


def _check_shadow_points(points: tuple[str, str, str], photo: Path, where: str) -> None:
    """The shadow's points inside the photo, now rather than when the job runs (and fails, and is retried)."""
    from ..core.data.imageio import upright_size
    from ..core.stages.light.shadow_hint import shadow_pixels

    size = upright_size(photo)
    if size is None:
        return   # (a photo OpenImageIO cannot open is said when the job reads it)
    try:
        shadow_pixels(points, size, (size[1], size[0]))
    except InputError as error:
        raise InputError(f"{where}: sun_shadow: {error}") from None


def _existing(text: str, path: Path, where: str, key: str, what: str) -> Path:
    found = _resolve(text, path)
    if not found.is_file():
        raise InputError(f"{where}: the {what} '{found}' does not exist.")
    return found


def _parse_asset(entry: dict, path: Path, where: str) -> tuple[Path, str | None]:
    asset_text = entry.get("asset", "")
    if not isinstance(asset_text, str):
        raise InputError(f"{where}: asset must be a string, got {asset_text!r}.")
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
    _check_readable(asset, where)
    obj = entry.get("object")
    if obj is not None and (not isinstance(obj, str) or not obj):
        raise InputError(f"{where}: object must name an object in the asset file, got {obj!r}.")
    if obj is not None and asset.is_dir():
        raise InputError(f"{where}: object is for a Blender/glTF file; '{asset.name}' is an asset folder.")
    return asset, obj


def _check_readable(asset: Path, where: str) -> None:
    """What of the asset can be read without Blender, read now (a job that would fail when it runs is refused
    when the file is read): an asset folder's mesh.npz is an archive, a glTF's JSON is a glTF document's."""
    import zipfile

    from ..core.data.glb import read_gltf

    if asset.is_dir():
        if not zipfile.is_zipfile(asset / _ASSET_FOLDER_FILE):
            raise InputError(f"{where}: the asset folder's '{asset / _ASSET_FOLDER_FILE}' cannot be read as a "
                             "mesh archive; save the asset again.")
        return
    if asset.suffix.lower() in (".gltf", ".glb"):
        try:
            read_gltf(asset)
        except InputError as error:
            raise InputError(f"{where}: {error}") from None
        except (ValueError, struct.error, OSError):
            raise InputError(f"{where}: the asset '{asset}' cannot be read as glTF; export it again.") from None


def _names_a_path(text: str, jobs_path: Path) -> bool:
    """Whether a model key's text is a folder (as the model manager tells them from hub ids: './', '/', '~',
    or a folder beside the jobs file), to be taken from the jobs file's folder."""
    return text.startswith((".", "/", "~")) or (jobs_path.parent / text).is_dir()


def _resolve(text: str, jobs_path: Path) -> Path:
    p = Path(text).expanduser()
    return (p if p.is_absolute() else jobs_path.parent / p).resolve()


def with_user_paths(text: str, copy: Job, job: Job) -> str:
    """`text` (a worker's error about `copy`, the job with its inputs unpacked into a temporary
    folder) naming the user's files instead: `.../scenefit-job-x/in/photo/broken.png` becomes the
    photo the jobs file named. Unpacked files keep their names below asset/ and photo/, so each
    folder maps to the folder of the user's file."""
    pairs = [(copy.asset, job.asset)] + ([(copy.photo, job.photo)] if copy.photo and job.photo else []) + \
        ([(Path(copy.run.fspy), Path(job.run.fspy))] if copy.run.fspy and job.run.fspy else [])
    for unpacked, original in pairs:
        text = text.replace(str(unpacked), str(original))
        text = text.replace(f"{unpacked.parent}{os.sep}", f"{original.parent}{os.sep}")
    return text
