"""What run_pipeline returns: a RunResult of StageRecords, typed, and its report.json as `to_report()`.

    result = run_pipeline(...)
    result.stages["light"].status          # "ran" | "reused" | "skipped"
    result.reused                           # ("convert", "light")
    result.texture_stage                    # "adapt" when adapt made the texture, else "convert"
    result.outputs("compose")["composite"]  # a stage's own outputs
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .layout import RunLayout


@dataclass(frozen=True)
class StageRecord:
    """One stage of a run: ran, reused (from this folder or, `source`, an earlier run's) or skipped (`why`)."""

    name: str
    status: str
    key: str | None = None
    seconds: float = 0.0
    report: dict[str, Any] = field(default_factory=dict)   # the stage's own report; its outputs as paths from here
    why: str = ""
    source: str | None = None                    # the earlier run's folder a reused stage was copied from

    @property
    def done(self) -> bool:
        """Whether the stage's outputs are there (it ran or was reused)."""
        return self.status in ("ran", "reused")

    def to_report(self) -> dict[str, Any]:
        if self.status == "skipped" or not self.done:
            return {"status": self.status, "why": self.why}
        out = {"status": self.status, "key": self.key, "seconds": self.seconds, "report": self.report}
        return out if self.source is None else dict(out, **{"from": self.source})

    @classmethod
    def from_runner(cls, name: str, record: dict[str, Any]) -> "StageRecord":
        return cls(name, record["status"], record.get("key"), record.get("seconds", 0.0), record.get("report", {}),
                   record.get("why", ""), record.get("from"))


@dataclass(frozen=True)
class RunResult:
    """A finished run: its folder, the config it ran with, each stage's record and the camera stage's."""

    folder: Path
    config: dict[str, Any]                                 # the RunConfig as plain data (as report.json keeps it)
    inputs: dict[str, Any]
    stages: dict[str, StageRecord]               # the stages a job lists, in the pipeline's order
    camera: StageRecord | None
    seconds: float
    environment: dict[str, Any] = field(default_factory=dict)

    @property
    def reused(self) -> tuple[str, ...]:
        return tuple(name for name, stage in self.stages.items() if stage.status == "reused")

    @property
    def composite(self) -> Path:
        return RunLayout(self.folder).file("compose", "composite")

    @property
    def texture_stage(self) -> str:
        """The stage whose texture is the run's last: adapt's when it ran or was reused, else convert's."""
        adapt = self.stages.get("adapt")
        return "adapt" if adapt is not None and adapt.done else "convert"

    def outputs(self, name: str) -> dict[str, Any]:
        return dict(self.stages[name].report.get("outputs", {}))

    def to_report(self) -> dict[str, Any]:
        """report.json's content (paths as they are here; write_report makes them relative to the folder)."""
        return {"stage": "run", "config": self.config, "inputs": self.inputs,
                "stages": {name: stage.to_report() for name, stage in self.stages.items()},
                "camera": None if self.camera is None else self.camera.to_report(),
                "composite": str(self.composite) if "compose" in self.stages else None, "reused": list(self.reused),
                "environment": self.environment, "seconds_total": self.seconds}
