"""What run_pipeline returns: a RunResult of StageRecords, typed, and its report.json as `to_report()`.

    result = run_pipeline(...)
    result.stages["light"].status          # "ran" | "reused" | "skipped" | "not listed"
    result.reused                           # ("convert", "light")
    result.texture_stage                    # "adapt" when adapt made the texture, else "convert"
    result.outputs("compose")["composite"]  # a stage's own outputs
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .layout import RunLayout


# A stage's status when the run was not asked for it (a job's stages leave it out): not a skip to be said.
NOT_LISTED = "not listed"


@dataclass(frozen=True)
class StageRecord:
    """One stage of a run: ran, reused (from this folder or, `source`, an earlier run's), skipped (`why`), or
    not listed (the run was not asked for it)."""

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

    def status_words(self) -> dict[str, str]:
        """{"status", "why"}: report.json's `stage_status` entry, the same shape in demo, run and batch."""
        return {"status": self.status, "why": self.why}

    def to_report(self) -> dict[str, Any]:
        if not self.done:
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

    def stage_status(self) -> dict[str, dict[str, str]]:
        """Each stage's status and why: report.json's `stage_status`, one place and shape in demo, run and batch."""
        return {name: stage.status_words() for name, stage in self.stages.items()}

    def to_report(self) -> dict[str, Any]:
        """report.json's content (paths as they are here; write_report makes them relative to the folder)."""
        return {"stage": "run", "config": self.config, "inputs": self.inputs, "stage_status": self.stage_status(),
                "stages": {name: stage.to_report() for name, stage in self.stages.items()},
                "camera": None if self.camera is None else self.camera.to_report(),
                "composite": str(self.composite) if "compose" in self.stages else None, "reused": list(self.reused),
                "environment": self.environment, "seconds_total": self.seconds}


# -- what a run's stage_status ({stage: {"status", "why"}}) says in a line: the terminal, summary.md --------

def reason(why: str) -> str:
    """Why a stage was skipped, in a few words: `why`'s first clause ("no weights", "--no-bake was given")."""
    return re.split(r": | \(|; |, so ", why, maxsplit=1)[0].strip()


def skipped_reasons(stage_status: dict[str, Any]) -> dict[str, str]:
    """{stage: its reason in a few words} of the stages a run skipped."""
    return {name: reason(stage.get("why", "")) for name, stage in stage_status.items()
            if isinstance(stage, dict) and stage.get("status") == "skipped"}


def stage_words(stage_status: dict[str, Any]) -> str:
    """Each stage and what became of it, a skipped one with its reason: "convert ran, adapt skipped: no weights"."""
    skipped = skipped_reasons(stage_status)
    return ", ".join(f"{name} {stage.get('status')}" + (f": {skipped[name]}" if name in skipped else "")
                     for name, stage in stage_status.items() if isinstance(stage, dict))


def skipped_lines(stage_status: dict[str, Any]) -> list[str]:
    """One line per skipped stage whose why says more than its reason (what to do to have it run)."""
    return [f"  {name} skipped: {stage_status[name]['why']}" for name, short in skipped_reasons(stage_status).items()
            if stage_status[name].get("why", "") != short]
