"""One job on a worker: `JobWorker` runs a payload's job through run_pipeline in a temporary folder and
returns its report and folder packed (`JobResult`); what it loads (models) stays loaded for its next
job. On Ray it is the actor; in-process one instance serves the whole batch; a worker environment
reached from Blender calls `run_plain` with plain data."""
from __future__ import annotations

import os
import shutil
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

from ..core.base.atomic import write_json_atomic
from ..core.base.errors import Cancelled, SceneFitError
from ..core.base.report import relative_paths
from .job_inputs import user_report
from .jobs import BatchSettings, Job, with_user_paths
from .packing import pack
from .payload import JobPayload, unpacked_job


REPORT = "report.json"
# A job's unpacked inputs and its output, in the system's temp folder: scenefit-job-<pid>-XXXX. A worker
# killed mid-job (a Ray actor stopped, a process killed) cannot remove its own; the next worker on the
# machine removes those whose process is gone.
JOB_FOLDER_PREFIX = "scenefit-job-"


@dataclass(frozen=True)
class JobResult:
    name: str
    report: dict
    outputs: bytes          # the job's folder, packed


def remove_orphaned_job_folders(root: str | Path | None = None) -> list[Path]:
    """Remove the job folders (JOB_FOLDER_PREFIX<pid>-...) in `root` (the temp folder) whose process no
    longer runs; a folder of a running process, or any other name, is left alone. Returns those removed."""
    removed = []
    for folder in Path(root or tempfile.gettempdir()).glob(f"{JOB_FOLDER_PREFIX}*-*"):
        pid = folder.name[len(JOB_FOLDER_PREFIX):].split("-", 1)[0]
        if not pid.isdigit() or not folder.is_dir() or folder.is_symlink() or _running(int(pid)):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # another user's process
        return True
    return True


class JobWorker:
    """Runs jobs one after another; what it loads (models) stays loaded for its next job.

    On Ray this class is the actor; in-process one instance serves the whole batch. `models` (a
    ModelCache) holds the diffusion models: the first job that needs them loads them, and every
    later job of this worker gets the same loaded modules.
    """

    def __init__(self, threads: int | None = None) -> None:
        from ..core.guidance.models import ModelCache

        self.threads_before = set_threads(threads) if threads is not None else None
        remove_orphaned_job_folders()
        self.cancel_event = threading.Event()
        self.models = ModelCache()
        self.jobs_run = 0

    def run(self, payload: JobPayload, progress_sink=None) -> JobResult:
        """Run one job; progress events go to `progress_sink` (a queue: ray.util.queue.Queue on Ray)."""
        started = time.perf_counter()
        self.cancel_event.clear()
        progress = None if progress_sink is None else SinkProgress(progress_sink, payload.job.name)
        with tempfile.TemporaryDirectory(prefix=f"{JOB_FOLDER_PREFIX}{os.getpid()}-") as tmp:
            job, earlier = unpacked_job(payload, Path(tmp) / "in")
            out = Path(tmp) / "out"
            out.mkdir()
            try:
                stages = run_job_stages(job, out, progress=progress, cancel=self.cancel_event, models=self.models,
                                        reuse_from=earlier)
            except SceneFitError as error:   # name the user's files, not the unpacked copies
                raise type(error)(with_user_paths(str(error), job, payload.job)) from None
            self.jobs_run += 1
            name_user_files(out, job, payload.job, Path(tmp))
            report = {"status": "done", "job": payload.job.to_dict(), "digest": payload.digest, "attempts": payload.attempt,
                      "seconds": round(time.perf_counter() - started, 3), "quality": quality_figures(stages),
                      "stage_status": stages.get("run", {}).get("stage_status", {}),
                      "stages": stages, "worker": worker_info(self.jobs_run, self.models.loads)}
            report = relative_paths(user_report(report, job, payload.job, Path(tmp)), out)   # no temporary paths
            write_json_atomic(out / REPORT, report)
            return JobResult(payload.job.name, report, pack({".": out}))

    def cancel(self) -> None:
        """Stop the running job at its next check (a Ray actor takes this call while `run` runs)."""
        self.cancel_event.set()

    def ping(self) -> str:
        return "ready"


def name_user_files(out: Path, copy: Job, job: Job, folder: Path) -> None:
    """The stages' records and reports (stage.json, report.json) naming the user's files, not the copies
    unpacked in the worker's temporary `folder` (job_inputs.user_report): a job's folder is the same
    wherever it ran, and names no folder that is gone once the job ends."""
    import json

    for path in out.rglob("*.json"):
        text = path.read_text()
        if str(folder) in text:
            write_json_atomic(path, user_report(json.loads(text), copy, job, folder))


def run_plain(worker: JobWorker, job: dict, inputs: bytes, progress_sink=None) -> dict:
    """`worker.run` with plain data in and out: the job as `Job.to_dict`, a dict back ({"report",
    "outputs"} or {"error", "kind"}). What a caller whose copy of SceneFit has another package name
    (the Blender add-on: bl_ext.<repo>.scenefit) exchanges with a worker, since neither side can
    unpickle the other's classes."""
    try:
        result = worker.run(JobPayload(Job.from_dict(job), inputs), progress_sink)
    except (SceneFitError, Cancelled) as error:
        return {"error": str(error), "kind": type(error).__name__}
    except Exception as error:
        return {"error": error_text(error), "kind": "SceneFitError", "traceback": traceback.format_exc()[-4000:]}
    return {"report": result.report, "outputs": result.outputs}


def error_text(error: BaseException) -> str:
    """One line for people: SceneFit's own sentences as they are, anything else with its type."""
    cause = getattr(error, "cause", None)   # ray.exceptions.RayTaskError wraps the worker's exception
    if isinstance(cause, BaseException):
        error = cause
    if isinstance(error, SceneFitError):
        return str(error)
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[-1] if text else ''}"


class SinkProgress:
    """A progress callback that puts plain dicts into a queue, at most every `interval` seconds
    (always for a stage's last step and for previews); a full queue drops the event rather than wait."""

    def __init__(self, sink, job: str, interval: float = 0.25) -> None:
        self.sink, self.job, self.interval = sink, job, interval
        self._last = 0.0

    def __call__(self, event) -> None:
        now = time.perf_counter()
        last_step = event.step >= event.total
        if not last_step and event.preview is None and now - self._last < self.interval:
            return
        self._last = now
        metrics = {k: v for k, v in (event.metrics or {}).items() if isinstance(v, (int, float, str))}
        try:
            self.sink.put_nowait({"job": self.job, "stage": event.stage, "step": event.step, "total": event.total,
                                  "message": event.message, "metrics": metrics, "preview": event.preview})
        except Exception:   # queue.Full / ray.util.queue.Full: progress is best effort, the job goes on
            pass


def set_threads(threads: int | tuple[int, int]) -> tuple[int, int]:
    """Use as many threads as the job was given (torch, Mitsuba's LLVM backend); returns the old counts.

    Also what makes a job's outputs the same wherever it runs: sums split over a different number
    of threads round differently (Mitsuba's gradient atomics even reorder run to run above one).
    """
    import drjit
    import torch

    before = (torch.get_num_threads(), drjit.thread_count())
    torch_threads, drjit_threads = threads if isinstance(threads, tuple) else (threads, threads)
    torch.set_num_threads(max(1, torch_threads))
    drjit.set_thread_count(max(1, drjit_threads))
    return before


def job_threads(settings: BatchSettings) -> int:
    return max(1, int(settings.num_cpus))


def worker_info(jobs_run: int, model_loads: int) -> dict:
    import os
    import platform

    import torch

    return {"host": platform.node(), "pid": os.getpid(), "jobs_run_by_this_worker": jobs_run,
            "model_loads_by_this_worker": model_loads, "torch_threads": torch.get_num_threads()}


def run_job_stages(job: Job, out: Path, progress=None, cancel=None, models=None, reuse_from: Path | None = None) -> dict:
    """Run the job's stages into `out` through core/pipeline/run.py's run_pipeline (the subset it lists:
    convert and/or light alone, or the pipeline, adapt when listed and its weights are found), reusing the
    stages of `reuse_from` (an earlier run of the job) whose inputs and settings are the same; returns
    {"run": the run's report}. `models`: the worker's ModelCache (None: the pipeline loads what it needs
    for this job alone)."""
    return _relative_outputs({"run": run_pipeline_for_job(job, out, progress, cancel, models, reuse_from)}, out)


def run_pipeline_for_job(job: Job, out: Path, progress=None, cancel=None, models=None,
                         reuse_from: Path | None = None) -> dict:
    """The job through run_pipeline, its settings the RunConfig the jobs file's keys were read into. A job
    that converts without composing fits every material at its own cell's size, as `scenefit convert`
    does; one that composes fits their atlas, as `scenefit run` does."""
    from ..blender_io.asset_file import load_asset_materials   # a Blender/glTF file: bpy in this worker
    from ..core.pipeline.run import run_pipeline
    from ..core.stages.bake.process import asset_file_bake

    asset = load_asset_materials(str(job.asset), job.object)
    mesh, maps = (asset, None) if "compose" not in job.stages else asset.fitting_view()
    bake, why_not = asset_file_bake(job.asset, job.object) if "bake" in job.stages else (None, "the job's stages "
                                                                                         "do not list bake")
    return run_pipeline(mesh, maps, job.photo, job.at, out, job.run, progress=progress, cancel=cancel, models=models,
                        bake=bake, bake_skipped_why=why_not, reuse_from=reuse_from, stages=job.stages).to_report()


def _relative_outputs(value, out: Path):
    """Output paths relative to the job folder (the folder moves from the worker to DIR/<name>/)."""
    if isinstance(value, dict):
        return {k: _relative_outputs(v, out) for k, v in value.items()}
    if isinstance(value, list):
        return [_relative_outputs(v, out) for v in value]
    if isinstance(value, str) and value.startswith(str(out) + "/"):
        return value[len(str(out)) + 1:]
    return value


def quality_figures(stages: dict) -> dict:
    """The numbers the summary shows per job, from whichever stages ran."""
    if "run" in stages:   # the pipeline's report: each stage's own report inside
        run = stages["run"].get("stages", {})
        stages = {name: s["report"] for name, s in run.items() if isinstance(s, dict) and "report" in s}
    q: dict = {}
    convert = stages.get("convert", {})
    if "psnr_covered_texels_db" in convert:
        q["convert_psnr_db"] = convert["psnr_covered_texels_db"]
    light = stages.get("light", {})
    if light:
        q["light_scene"] = light.get("decisions", {}).get("scene_type", {}).get("chosen")
        q["light_hdr_max"] = round(float(light.get("hdr_max", float("nan"))), 3)
    adapt = stages.get("adapt", {})
    if adapt:
        q["adapt_iterations"] = adapt.get("iterations")
    for name, stage in stages.items():
        for key, value in stage.get("quality", {}).items() if isinstance(stage, dict) else ():
            q[f"{name}_{key}"] = value
    return q
