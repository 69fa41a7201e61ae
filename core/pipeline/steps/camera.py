"""The camera stage's work: the photo's camera, written as camera/camera.json (core/stages/camera_stage.py),
keyed by the photo and what was given about its camera."""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...stages.camera_stage import write_camera

if TYPE_CHECKING:
    from ..run import PipelineRun


def configure(run: PipelineRun) -> Any:
    """What the run gives about the camera: a PhotoCamera, or the fSpy project's bytes and the values over
    the estimate (the camera stage has no preset)."""
    given = run.config.photo_camera
    if given is not None:
        return asdict(given)
    return ["estimated", run.file_digest(run.config.fspy), run.config.camera_overrides, run.config.camera_source,
            run.config.camera_why]


def work(run: PipelineRun, config: Any, folder: Path) -> dict[str, Any]:
    return write_camera(*run.photo_camera(), folder)
