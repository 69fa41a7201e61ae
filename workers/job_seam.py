"""The typed seam between Blender and the pipeline: what a Run All click asked for (RunRequest, frozen at the
click) and what its run folder holds (RunOutcome, built by `run_outcome` alone, for a local and a remote run).

bpy-free: the operators build a request on the main thread from the artist's selection; everything after
(the job, the result, the history entry, the composite, Resume) reads the request, never the selection. A
request is written into its run folder (REQUEST_FILE) so Resume continues the run as it was clicked.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

from ..core.base.errors import InputError
from ..core.guidance.models import ModelConfig
from ..core.pipeline.layout import RunLayout, camera_of
from ..core.pipeline.registry import CAMERA_STAGE
from ..core.pipeline.run_config import RunConfig
from ..core.pipeline.run_table import run_config, run_table
from ..core.scene.camera import PhotoCamera

REQUEST_FILE = "request.json"
REQUEST_FORMAT = "scenefit.blender-run-request"
TEXTURE_KEYS = ("base_color", "roughness", "metallic")


@dataclass(frozen=True)
class RunRequest:
    """A Run All as the artist clicked it.

    asset_id: the asset's stable identity (its root object's id property, operators/identity.py), which a
    rename keeps; object_ids / slots: where each material's result goes (object id, slot number);
    asset_name: its name at the click, for words only. config holds the prompt, negative prompt, seed,
    size, turn, preset, camera, sun and models; photo and placement are the run's inputs; out is the
    run's folder (new at the click, or the folder Resume continues)."""

    asset_id: str
    asset_name: str
    object_ids: tuple[str, ...]
    slots: tuple[tuple[tuple[str, int], ...], ...]
    photo: str
    placement: tuple[float, float]
    config: RunConfig
    out: str
    why_no_adapt: str = ""
    scene_camera: str = ""   # the artist's camera that shows the photo (its name at the click), or ""
    scene: str = ""          # the scene the run was clicked in (its World gets the light)

    def to_table(self) -> dict:
        """The request as plain data for REQUEST_FILE (models aside: they are the preferences' when resumed)."""
        return {"format": REQUEST_FORMAT, "asset_id": self.asset_id, "asset_name": self.asset_name,
                "object_ids": list(self.object_ids), "slots": [[list(p) for p in pairs] for pairs in self.slots],
                "photo": self.photo, "placement": list(self.placement), "out": self.out,
                "why_no_adapt": self.why_no_adapt, "scene_camera": self.scene_camera, "scene": self.scene,
                "run": run_table(self.config)}

    @classmethod
    def from_table(cls, table: Mapping[str, Any], models: ModelConfig, where: str) -> "RunRequest":
        """The request `to_table` wrote (one sentence, InputError, for anything else), with today's `models`."""
        try:
            if table.get("format") != REQUEST_FORMAT:
                raise ValueError("it is not a SceneFit run request")
            config = run_config(dict(table["run"]), where, models=models)
            return cls(asset_id=str(table["asset_id"]), asset_name=str(table["asset_name"]),
                       object_ids=tuple(str(i) for i in table["object_ids"]),
                       slots=tuple(tuple((str(o), int(n)) for o, n in pairs) for pairs in table["slots"]),
                       photo=str(table["photo"]), placement=(float(table["placement"][0]), float(table["placement"][1])),
                       config=config, out=str(table["out"]), why_no_adapt=str(table.get("why_no_adapt", "")),
                       scene_camera=str(table.get("scene_camera", "")), scene=str(table.get("scene", "")))
        except (KeyError, TypeError, ValueError, IndexError) as error:
            raise InputError(f"{where} cannot be resumed: its {REQUEST_FILE} is unreadable ({error}).") from None

    def resumed(self, out: str) -> "RunRequest":
        return replace(self, out=out)


def write_request(folder: Path, request: RunRequest) -> None:
    from ..core.base.atomic import write_json_atomic

    write_json_atomic(Path(folder) / REQUEST_FILE, request.to_table())


def read_request(folder: Path, models: ModelConfig) -> RunRequest:
    """The request a run folder (or its hidden, unfinished sibling) was started with."""
    from ..core.base.output_folder import staging_path

    folder = Path(folder)
    for where in (folder, staging_path(folder)):
        path = where / REQUEST_FILE
        if path.is_file() and path.stat().st_size < 1_000_000:
            try:
                table = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, UnicodeDecodeError, ValueError) as error:
                raise InputError(f"The run '{folder}' cannot be resumed: its {REQUEST_FILE} is unreadable "
                                 f"({error}).") from None
            return RunRequest.from_table(table, models, f"The run '{folder}'")
    raise InputError(f"The run '{folder}' kept no {REQUEST_FILE}; start a new Run All instead.")


def run_guidance(choice: str, guidance: str, prompt: str) -> tuple[str, str]:
    """(guidance_type, why adaptation is skipped or "") for a Run All, local or sent to a worker: the
    question's Skip adaptation, else the panel's Adaptation, "auto" without a prompt adapting nothing."""
    if choice == "skip":
        return "none", "skipped at the question before the run (Skip adaptation)"
    if guidance == "auto" and not prompt.strip():
        return "none", "the Style section has no prompt"
    return guidance, ""


@dataclass(frozen=True)
class RunInputs:
    """What a Run All's worker gets: the request, the asset as planned on the main thread (decoded in the job),
    each material's bake data when there are several, and a finished run whose stages may be reused."""

    request: RunRequest
    asset: Any                      # core/data/map_plan.PendingAsset until the job starts, then PlannedAsset
    materials: Mapping[str, Any] | None = None
    reuse_from: str | None = None


# -- the outcome -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TextureOutcome:
    """A job's texture and maps as Blender applies them: paths into its run folder; material_maps: each
    material's own maps (an asset of several materials), else () and `maps` is the one material's."""

    folder: str
    report: str
    texture: str
    maps: Mapping[str, str | float]
    material_maps: tuple[Mapping[str, Any], ...] = ()
    numbers: Mapping[str, float] = field(default_factory=dict)   # e.g. psnr_db, iterations: the status line's


@dataclass(frozen=True)
class RunOutcome(TextureOutcome):
    """A Run All's folder as Blender applies it: the stage whose texture it is, the light, the composite, the
    camera the camera stage settled on (lens shift included), each stage's status."""

    stage: str = "convert"
    hdr: str = ""
    composite: str = ""
    camera: PhotoCamera | None = None
    stages: Mapping[str, str] = field(default_factory=dict)
    adapt_skipped: str = ""


def run_camera(folder: Path) -> PhotoCamera | None:
    """The camera a run folder's camera stage wrote (None when the run has none). Width and height are the
    photo's, which the Cycles set-up puts in."""
    has_camera = RunLayout(Path(folder)).file(CAMERA_STAGE, "camera").is_file()
    return camera_of(folder, 1, 1)[0] if has_camera else None


def run_outcome(folder: str | Path, run_report: Mapping[str, Any],
                material_maps: tuple[Mapping[str, Any], ...] = ()) -> RunOutcome:
    """The outcome of a finished run folder from its run report (report.json's, paths relative to the folder):
    the last texture's maps (adapt's when it ran or was reused, else convert's), the light, the composite,
    the camera stage's camera. The one builder, for a run here and a run a worker sent back."""
    folder = Path(folder)
    stages = run_report["stages"]
    last = "adapt" if stages.get("adapt", {}).get("status") in ("ran", "reused") else "convert"
    outputs = stages[last]["report"]["outputs"]

    def path(value):
        return str(folder / value) if isinstance(value, str) else value

    light, composite = folder / "light" / "light.exr", folder / "compose" / "composite.png"
    return RunOutcome(folder=str(folder), report=str(folder / "report.json"), texture=path(outputs["weights"]),
                      maps={k: path(outputs[k]) for k in TEXTURE_KEYS}, material_maps=tuple(material_maps),
                      stage=last, hdr=str(light) if light.is_file() else "",
                      composite=str(composite) if composite.is_file() else "", camera=run_camera(folder),
                      stages={name: stage["status"] for name, stage in stages.items()},
                      adapt_skipped=stages.get("adapt", {}).get("why", ""))


def read_run_outcome(folder: str | Path, material_maps: tuple[Mapping[str, Any], ...] = ()) -> RunOutcome:
    """run_outcome of a run folder here, its report.json read (a worker's job report holds the run's under
    stages.run)."""
    from ..core.base.untrusted import parse_json, read_bytes

    path = Path(folder) / "report.json"
    report = parse_json(read_bytes(path, what="run report"), f"the run report '{path}'")
    inner = report.get("stages", {}).get("run") if report.get("stage") != "run" else None
    return run_outcome(folder, inner if isinstance(inner, dict) and "stages" in inner else report, material_maps)
