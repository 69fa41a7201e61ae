"""A run folder's files, each named once: the stage registry says what each stage writes where.

    layout = RunLayout(run_folder)
    layout.file("light", "light")        # <run>/light/light.exr
    layout.file("camera", "camera")      # <run>/camera/camera.json
    layout.report                        # <run>/report.json
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .registry import stage

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

    def file(self, name: str, output: str) -> Path:
        """Stage `name`'s output `output` (the registry's `writes`); an output the stage does not write is a KeyError."""
        return self.folder / name / stage(name).writes[output]

    @property
    def report(self) -> Path:
        return self.folder / REPORT_FILE
