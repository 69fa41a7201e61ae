"""What a job does between a click and its end, without bpy: one bar for a run of several stages, its time
left, what Esc does, what a job's inputs still owe the main thread and what its worker takes, how long
Blender waits for a stopping job. operators/jobs.py is the Blender side (the modal operator, the runtime the
panel draws, the status bar, the handlers), which calls these."""
from __future__ import annotations

import dataclasses
import time

from ..core.data.map_plan import PendingAsset
from .background import JobState
from .time_model import eta_from_start


def whole_run(state: JobState, stages: tuple[str, ...]) -> tuple[float, str] | None:
    """(fraction, words) of a job that runs several stages in order (Run All: core.pipeline.registry.RUN_ORDER) as one
    bar, stage k of n, from the stage now running and its own fraction; None for a one-stage job."""
    if state.name != "run" or state.finished:
        return None
    n = len(stages)
    if state.stage in stages:
        k, inner = stages.index(state.stage), state.fraction
    elif state.stage == "run" and state.total:   # between stages: the pipeline's own count
        k, inner = min(state.step, n - 1), 0.0
    else:
        return None
    return (k + inner) / n, f"stage {k + 1} of {n} ({stages[k]})"


def time_left(expected: float, state: JobState, stages: tuple[str, ...]) -> float | None:
    """Seconds left of a job whose adaptation the bench projects at `expected` seconds: the projection until
    the adaptation starts, then weighed over to its own pace (time_model.eta_from_start); None once it is
    done (a run's later stages take seconds, their own guess stands)."""
    if state.stage == "adapt":
        return eta_from_start(expected, time.perf_counter() - state.started, state.fraction, state.eta_seconds)
    if "adapt" in stages and state.stage in stages and stages.index(state.stage) > stages.index("adapt"):
        return None
    return expected


# A job that has run longer than this asks before Esc cancels it (a stray Esc must not end hours of work).
CONFIRM_CANCEL_AFTER = 60.0
# How long loading another file, quitting or disabling SceneFit waits for a job's worker to stop: a worker
# checks its cancel within a UNet block or a download chunk (seconds); only one stuck in a call that checks
# none (a model's load) outlasts it, and it keeps the job slot until it stops (workers/background.py).
END_JOB_SECONDS = 30.0


def esc_action(over_progress: bool, seconds: float) -> str:
    """What Esc does during a job: "pass" (not meant for SceneFit: the pointer is elsewhere), "ask" (a
    job longer than CONFIRM_CANCEL_AFTER: confirm first) or "cancel"."""
    if not over_progress:
        return "pass"
    return "ask" if seconds > CONFIRM_CANCEL_AFTER else "cancel"


def _parts(data) -> dict:
    """A job's data by name: a dict's items, a frozen dataclass's fields (job_seam.RunInputs)."""
    if isinstance(data, dict):
        return data
    if dataclasses.is_dataclass(data) and not isinstance(data, type):
        return {f.name: getattr(data, f.name) for f in dataclasses.fields(data)}
    return {}


def _pending_assets(data) -> list[PendingAsset]:
    """The planned assets in a job's data, at any depth (a remote job's asset is inside its RemoteRun)."""
    found: list[PendingAsset] = []
    for value in _parts(data).values():
        if isinstance(value, PendingAsset):
            found.append(value)
        elif isinstance(value, dict) or (dataclasses.is_dataclass(value) and not isinstance(value, type)):
            found += _pending_assets(value)
    return found


def owed_bakes(data) -> list:
    """The Cycles bakes a job's inputs still owe the main thread (core/data/map_plan.PendingAsset.bakes)."""
    return [b for asset in _pending_assets(data) for b in asset.bakes if not b.done]


def for_the_worker(data):
    """A job's data as its worker takes it: each planned asset, at any depth, as plain data, its bakes' pixels
    in place."""
    planned: dict = {}
    for key, value in _parts(data).items():
        if isinstance(value, PendingAsset):
            planned[key] = value.for_job()
        elif isinstance(value, dict) or (dataclasses.is_dataclass(value) and not isinstance(value, type)):
            inner = for_the_worker(value)
            if inner is not value:
                planned[key] = inner
    if not planned:
        return data
    return {**data, **planned} if isinstance(data, dict) else dataclasses.replace(data, **planned)


def job_out(data) -> str:
    """The run folder a job writes (its request's, or a dict's "out"), or ""."""
    request = getattr(data, "request", None)
    if request is not None:
        return request.out
    return data.get("out", "") if isinstance(data, dict) else ""
