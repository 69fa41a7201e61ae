"""`scenefit batch`: many asset x scene jobs, in this process or as Ray tasks on a cluster.

The driver (this process) owns the output folder. A job travels to a worker as a `JobPayload`
(the job plus its input files packed as bytes, so a worker on another node needs no shared disk),
runs there in a temporary folder, and comes back as a `JobResult` (its report and output folder
packed as bytes). The driver swaps the folder into DIR/<name>/ in one step, so a job's folder is
always one whole run. Workers (`JobWorker`; on Ray an actor with declared CPUs, GPUs and memory)
keep their loaded models between jobs. The in-process executor runs the very same `JobWorker`.

Resuming: a job whose DIR/<name>/report.json says "done" with the same settings and the same input
files (by content) is skipped. One changed since runs again, and the finished stages of its earlier
folder travel with it (`earlier/` in its payload): the worker reuses each whose inputs and settings
are the same, as `scenefit run` does. Failures: a job is tried 1 + retries times; after that its folder
holds a report with status "failed" and the error, the summary lists it, and the next run tries it again.
"""
from __future__ import annotations

import io
import math
import os
import shutil
import tarfile
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Protocol, Sequence

from ..core.base.atomic import write_json_atomic, write_text_atomic
from ..core.base.errors import Cancelled, InputError, SceneFitError
from .job_inputs import job_digest, job_files, read_job_report, user_report
from ..core.base.report import relative_paths
from .interrupt import CtrlCStops
from .jobs import BatchSettings, Job, JobsFile, with_user_paths
from ..core.base.output_folder import (FINISHED_JOBS_ATTRIBUTE, check_output_folder, check_subfolder,
                                      folder_in_place, install_folder)

REPORT = "report.json"
# A job's unpacked inputs and its output, in the system's temp folder: scenefit-job-<pid>-XXXX. A worker
# killed mid-job (a Ray actor stopped, a process killed) cannot remove its own; the next worker on the
# machine removes those whose process is gone.
JOB_FOLDER_PREFIX = "scenefit-job-"
SUMMARY_JSON, SUMMARY_MD, CONTACT_SHEET = "summary.json", "summary.md", "contact_sheet.png"
RESERVED_NAMES = (SUMMARY_JSON, SUMMARY_MD, CONTACT_SHEET)
# What a job's contact-sheet cell shows, the first that exists (the composite once compose runs).
SHEET_IMAGES = ("composite.png", "compose/composite.png", "light/light_preview.png", "convert/maps/base_color.png")


# -- packing files as bytes ------------------------------------------------------------------------

def pack(paths: dict[str, Path]) -> bytes:
    """A tar (gzip) of files and folders, each stored under its given name; a link as the file it points at."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", dereference=True) as tar:
        for name, path in paths.items():
            tar.add(str(path), arcname=name)
    return buffer.getvalue()


def unpack(data: bytes, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        tar.extractall(folder, filter="data")   # refuses absolute paths and '..'
    return folder


@dataclass(frozen=True)
class JobPayload:
    """A job with its inputs packed: what a worker anywhere needs to run it. `digest`: what its settings
    and input files were (job_digest), which its report keeps so a later batch can tell it unchanged."""

    job: Job
    inputs: bytes
    attempt: int = 1
    digest: str = ""


# Where a payload carries the finished stages of the job's earlier folder, beside asset/ and photo/.
EARLIER = "earlier"


def make_payload(job: Job, attempt: int = 1, stages: Sequence[Path] = (), files: dict[str, Path] | None = None,
                 digest: str | None = None) -> JobPayload:
    """The job and its inputs packed (job_inputs.job_files; `files` and `digest`: already worked out);
    `stages`: finished stage folders of an earlier run of the job (finished_stage_folders), which travel
    with it for the worker to reuse where their inputs and settings are the same."""
    files = files if files is not None else job_files(job)
    digest = digest if digest is not None else job_digest(job, files)   # (before packing: an edit meanwhile re-runs)
    return JobPayload(job, pack({**files, **{f"{EARLIER}/{stage.name}": stage for stage in stages}}), attempt, digest)


def finished_stage_folders(folder: Path | None) -> list[Path]:
    """The stage folders of a run folder that hold a finished stage (its stage.json) and no link, which
    would be sent as the file it points at: those are run again instead."""
    from ..core.base.names import RUN_ORDER
    from ..core.pipeline.run import STAGE_FILE

    if folder is None or not folder.is_dir():
        return []
    return [folder / name for name in RUN_ORDER if (folder / name / STAGE_FILE).is_file()
            and not (folder / name).is_symlink() and not any(p.is_symlink() for p in (folder / name).rglob("*"))]


def unpacked_job(payload: JobPayload, folder: Path) -> tuple[Job, Path | None]:
    """The payload's job with its paths pointing at the unpacked copies in `folder`, and the earlier
    stages it carries (None: none)."""
    unpack(payload.inputs, folder)
    job = payload.job
    photo = None if job.photo is None else folder / "photo" / job.photo.name
    run = job.run if job.run.fspy is None else replace(job.run, fspy=str(folder / "fspy" / Path(job.run.fspy).name))
    earlier = folder / EARLIER
    return replace(job, asset=folder / "asset" / job.asset.name, photo=photo, run=run), \
        earlier if earlier.is_dir() else None


# -- one job on a worker ---------------------------------------------------------------------------

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
        return {"error": _error_text(error), "kind": "SceneFitError", "traceback": traceback.format_exc()[-4000:]}
    return {"report": result.report, "outputs": result.outputs}


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


# -- the driver's side: folders, resume, retries ----------------------------------------------------

def job_report(out_dir: Path, name: str) -> dict | None:
    return read_job_report(Path(out_dir) / name / REPORT)   # (data: a planted report reads as none)


@dataclass
class JobOutcome:
    name: str
    status: str                 # done | failed | skipped (done by an earlier run)
    attempts: int = 0
    seconds: float = 0.0
    quality: dict = field(default_factory=dict)
    error: str | None = None
    reused: tuple[str, ...] = ()   # the stages taken from an earlier run, not run again


def reused_stages(report: dict) -> tuple[str, ...]:
    """The stages a job's report says were reused."""
    stages = report.get("stages", {}).get("run", {}).get("stages", {})
    return tuple(name for name, stage in stages.items() if isinstance(stage, dict) and stage.get("status") == "reused")


def _error_text(error: BaseException) -> str:
    """One line for people: SceneFit's own sentences as they are, anything else with its type."""
    cause = getattr(error, "cause", None)   # ray.exceptions.RayTaskError wraps the worker's exception
    if isinstance(cause, BaseException):
        error = cause
    if isinstance(error, SceneFitError):
        return str(error)
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[-1] if text else ''}"


EventCallback = Callable[[str, str], None]   # (job name, message)


class Dispatcher(Protocol):
    """Hands payloads to workers and gives back (payload, JobResult | exception) as they finish."""

    def submit(self, payload: JobPayload) -> None: ...
    def next_done(self) -> tuple[JobPayload, JobResult | BaseException]: ...
    def close(self) -> None: ...


class InProcessDispatcher(Dispatcher):
    """One JobWorker in this process, jobs one after another."""

    def __init__(self, settings: BatchSettings = BatchSettings(), worker_class: type[JobWorker] = JobWorker,
                 progress_sink=None) -> None:
        self.worker = worker_class(threads=job_threads(settings))
        self.progress_sink = progress_sink
        self.queue: list[JobPayload] = []
        self.workers = 1

    def submit(self, payload: JobPayload) -> None:
        self.queue.append(payload)

    def next_done(self):
        payload = self.queue.pop(0)
        try:
            return payload, self.worker.run(payload, self.progress_sink)
        except Exception as error:   # reported and retried by the driver, never lost
            return payload, error

    def close(self) -> None:
        if self.worker.threads_before is not None:   # this process goes on after the batch
            set_threads(self.worker.threads_before)


def run_batch(jobs: JobsFile, out_dir: str | Path, dispatcher: Dispatcher | None = None,
              on_event: EventCallback | None = None, redo: bool = False,
              reuse_from: Path | None = None, listed: dict | None = None) -> list[JobOutcome]:
    """Run every job not yet done; write the per-job folders, summary.json/.md and the contact sheet.

    The folder follows every command's contract (core/base/output_folder.py): locked while the batch runs,
    never a folder holding an input or files SceneFit did not write; each job's folder is swapped in
    whole. redo: run the jobs done by an earlier batch again (`--replace`). reuse_from: an earlier batch's
    folder, whose REUSE_FROM/<job>/ stages a job with no earlier folder of its own in out_dir takes along.
    listed: what check_batch returned, when the caller checked already (each asset is listed once)."""
    listed = listed if listed is not None else check_batch(jobs, out_dir, reuse_from)
    with folder_in_place(out_dir, batch_inputs(jobs)) as out_dir:
        return _run_jobs(jobs, out_dir, CtrlCStops(dispatcher or InProcessDispatcher(jobs.settings)), on_event, redo,
                         reuse_from, listed)


def batch_inputs(jobs: JobsFile) -> list[Path]:
    return [jobs.path, *(Path(p) for job in jobs.jobs for p in (job.asset, job.photo, job.run.fspy) if p is not None)]


def check_batch(jobs: JobsFile, out_dir: str | Path, reuse_from: Path | None = None) -> dict:
    """Every refusal of the batch's folder, job names, assets and --reuse-from, before any work (and before
    Ray starts); returns each asset's files (job_inputs.job_files' `listed`), for run_batch."""
    for job in jobs.jobs:
        if job.name in RESERVED_NAMES or job.name.startswith("."):
            raise InputError(f"{jobs.path.name}: job '{job.name}' is named like a file the batch writes itself "
                             f"({', '.join(RESERVED_NAMES)}); give it another name.")
    out_dir = check_output_folder(out_dir, inputs=batch_inputs(jobs), reuse=True)
    for job in jobs.jobs:
        check_subfolder(out_dir, job.name)   # a user's folder of that name is refused, never replaced
    if reuse_from is not None and not reuse_from.is_dir():
        raise InputError(f"--reuse-from '{reuse_from}' is not a folder; give an earlier batch's --out folder.")
    listed: dict = {}
    for job in jobs.jobs:   # a file an asset names outside its folder is said now, not after other jobs ran
        job_files(job, listed)
    return listed


def _run_jobs(jobs: JobsFile, out_dir: Path, dispatcher: Dispatcher, on_event: EventCallback | None,
              redo: bool, reuse_from: Path | None, listed: dict) -> list[JobOutcome]:
    say = on_event or (lambda name, message: None)
    outcomes: dict[str, JobOutcome] = {}
    pending = 0
    try:
        for job in jobs.jobs:
            files = job_files(job, listed)
            digest = job_digest(job, files)
            report = job_report(out_dir, job.name) or {}
            done_before = report.get("status") == "done"   # (a report from before digests has none: runs once more)
            if not redo and done_before and report.get("digest") == digest:
                outcomes[job.name] = JobOutcome(job.name, "skipped", report.get("attempts", 0),
                                                report.get("seconds", 0.0), report.get("quality", {}),
                                                reused=reused_stages(report))
                say(job.name, "done by an earlier run; skipped")
                continue
            # Changed since an earlier run, or failed after one (not --replace): its finished stages go
            # along, to be reused by a job that runs the pipeline.
            stages = (finished_stage_folders(out_dir / job.name) if not redo else []) or \
                finished_stage_folders(reuse_from / job.name if reuse_from else None)
            dispatcher.submit(make_payload(job, stages=stages, files=files, digest=digest))
            pending += 1
            say(job.name, ("changed since the earlier run (settings or input files): queued" if done_before and not redo
                           else "queued") + (", its unchanged stages to be reused" if stages else ""))
        tries = 1 + jobs.settings.retries
        while pending:
            payload, result = dispatcher.next_done()
            pending -= 1
            job = payload.job
            if isinstance(result, JobResult):
                install_folder(out_dir, job.name, lambda folder: unpack(result.outputs, folder))
                reused = reused_stages(result.report)
                outcomes[job.name] = JobOutcome(job.name, "done", payload.attempt, result.report["seconds"],
                                                result.report.get("quality", {}), reused=reused)
                say(job.name, f"done in {result.report['seconds']:.1f} s (attempt {payload.attempt})"
                              + (f"; {', '.join(reused)} reused" if reused else ""))
                continue
            error = _error_text(result)
            if payload.attempt < tries:
                say(job.name, f"attempt {payload.attempt} failed ({error}); retrying")
                dispatcher.submit(replace(payload, attempt=payload.attempt + 1))
                pending += 1
                continue
            report = {"status": "failed", "job": job.to_dict(), "attempts": payload.attempt, "error": error,
                      "traceback": "".join(traceback.format_exception(result))[-4000:]}

            def failed(folder: Path) -> None:   # the earlier run's finished stages stay, for the next try
                kept = finished_stage_folders(out_dir / job.name) if not redo else []
                for stage in kept:
                    shutil.copytree(stage, folder / stage.name)
                if kept:
                    report["kept"] = {"stages": [stage.name for stage in kept],
                                      "why": "the earlier run's finished stages, for the next try to reuse"}
                write_json_atomic(folder / REPORT, report)

            install_folder(out_dir, job.name, failed)
            outcomes[job.name] = JobOutcome(job.name, "failed", payload.attempt, 0.0, {}, error)
            say(job.name, f"failed after {payload.attempt} attempt(s): {error}")
    except (KeyboardInterrupt, Cancelled) as stop:   # the folder's summary says what is in it now
        finished = [name for name, outcome in outcomes.items() if outcome.status != "skipped"]
        write_summary(out_dir, [outcomes.get(job.name) or JobOutcome(
            job.name, "interrupted", error="the batch was stopped before this job finished: its folder is as it was")
            for job in jobs.jobs], jobs)
        setattr(stop, FINISHED_JOBS_ATTRIBUTE, finished)
        raise
    finally:
        dispatcher.close()
    ordered = [outcomes[job.name] for job in jobs.jobs]
    write_summary(out_dir, ordered, jobs)
    return ordered



# -- summary -----------------------------------------------------------------------------------------

def summary_table(outcomes: list[JobOutcome]) -> str:
    keys = sorted({k for o in outcomes for k in o.quality})
    head = "| job | status | attempts | seconds | reused | " + " | ".join(keys) + (" |" if keys else "") + " error |"
    rule = "|" + "---|" * (6 + len(keys))
    rows = []
    for o in outcomes:
        cells = [o.name, o.status, str(o.attempts), f"{o.seconds:.1f}", ", ".join(o.reused)]
        cells += ["" if o.quality.get(k) is None else _cell(o.quality[k]) for k in keys]
        cells.append((o.error or "").replace("|", "/"))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, rule, *rows])


def _cell(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return str(value)


def write_summary(out_dir: Path, outcomes: list[JobOutcome], jobs: JobsFile) -> None:
    counts = {s: sum(o.status == s for o in outcomes) for s in ("done", "skipped", "failed")}
    if any(o.status == "interrupted" for o in outcomes):
        counts["interrupted"] = sum(o.status == "interrupted" for o in outcomes)
    write_json_atomic(out_dir / SUMMARY_JSON, {
        "jobs_file": str(jobs.path), "counts": counts,
        "jobs": [{"name": o.name, "status": o.status, "attempts": o.attempts, "seconds": o.seconds,
                  "reused": list(o.reused), "quality": o.quality, "error": o.error} for o in outcomes]})
    stopped = f", {counts['interrupted']} not run (the batch was interrupted)" if "interrupted" in counts else ""
    text = (f"# Batch {jobs.path.name}\n\n{counts['done']} done, {counts['skipped']} skipped (done before), "
            f"{counts['failed']} failed{stopped}.\n\n{summary_table(outcomes)}\n")
    write_text_atomic(out_dir / SUMMARY_MD, text)
    sheet = contact_sheet_image(out_dir, [o.name for o in outcomes if o.status in ("done", "skipped")])
    if sheet is not None:
        from ..core.data.imageio import write_image

        write_image(out_dir / CONTACT_SHEET, sheet)


def contact_sheet_image(out_dir: Path, names: list[str], cell: int = 192, columns: int = 4):
    """A grid of each job's composite (or its best preview), labelled with the job's name; sRGB [0, 1]."""
    import cv2
    import numpy as np

    from ..core.data.imageio import read_image

    cells = []
    for name in names:
        path = next((out_dir / name / p for p in SHEET_IMAGES if (out_dir / name / p).is_file()), None)
        if path is None:
            continue
        image = read_image(path)[..., :3]
        if image.shape[2] == 1:
            image = np.repeat(image, 3, axis=2)
        h, w = image.shape[:2]
        scale = cell / max(h, w)
        image = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
        canvas = np.full((cell + 22, cell, 3), 0.12, np.float32)
        canvas[22:22 + image.shape[0], :image.shape[1]] = np.clip(image, 0.0, 1.0)
        cv2.putText(canvas, name[:24], (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0.95, 0.95, 0.95), 1, cv2.LINE_AA)
        cells.append(canvas)
    if not cells:
        return None
    while len(cells) % columns and len(cells) > columns:
        cells.append(np.full_like(cells[0], 0.12))
    rows = [np.concatenate(cells[i:i + columns], axis=1) for i in range(0, len(cells), columns)]
    return np.concatenate(rows, axis=0)

