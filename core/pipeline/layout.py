"""A run folder's files, each named once: the stage registry says what each stage writes where.

    layout = RunLayout(run_folder)
    layout.file("light", "light")        # <run>/light/light.exr
    layout.file("camera", "camera")      # <run>/camera/camera.json
    layout.report                        # <run>/report.json
    camera, record = camera_of(run_folder, width, height)   # the camera stage's camera, lens shift kept
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..scene.camera import PhotoCamera
from ..stages.camera_stage import read_camera
from .registry import names, stage

STAGE_FILE = "stage.json"     # each stage folder's record: its key and report (core/pipeline/run.py)
REPORT_FILE = "report.json"   # the run's report


@dataclass(frozen=True)
class RunLayout:
    """Where a run folder keeps each stage's folder, record and outputs."""

    folder: Path

    def stage(self, name: str) -> Path:
        return self.folder / name

    def record(self, name: str) -> Path:
        return self.folder / name / STAGE_FILE

    @staticmethod
    def relative(name: str, output: str) -> str:
        """Stage `name`'s output `output` as a path inside a run folder ("light/light.exr")."""
        return f"{name}/{stage(name).writes[output]}"

    def file(self, name: str, output: str) -> Path:
        """Stage `name`'s output `output` (the registry's `writes`); an output the stage does not write is a KeyError."""
        return self.folder / name / stage(name).writes[output]

    @property
    def report(self) -> Path:
        return self.folder / REPORT_FILE


def run_folder_of(output: str | Path) -> Path | None:
    """The run folder a stage's output lies in (<run>/<stage>/<file>, or a single-stage command's folder
    <out>/<file>): the nearest folder above it that holds a camera stage; None: none does."""
    for folder in Path(output).absolute().parents[:3]:
        if RunLayout(folder).file(names().CAMERA_STAGE, "camera").is_file():
            return folder
    return None


def camera_of(run_folder: str | Path, width: int, height: int) -> tuple[PhotoCamera, dict[str, object]]:
    """The photo's camera as the run's camera stage found it (lens shift included), at an image of `width` x
    `height`, and where it came from; a camera.json that is missing or not a camera's is one sentence."""
    return read_camera(RunLayout(Path(run_folder)).file(names().CAMERA_STAGE, "camera"), width, height)
