"""`scenefit batch`: many asset x scene jobs, in this process or as Ray tasks on a cluster (the driver's side).

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

Its parts: payload.py (a job and its files packed, packing.py the bytes), job_worker.py (one job on a
worker), summary.py (summary.json/.md and the contact sheet); this module is the driver.
"""
from __future__ import annotations

import shutil
import traceback
from dataclasses import replace
from pathlib import Path
from typing import Callable, Protocol

from ..core.base.atomic import write_json_atomic
from ..core.base.errors import Cancelled, InputError
from ..core.pipeline.result import skipped_reasons
from ..core.base.output_folder import (FINISHED_JOBS_ATTRIBUTE, check_output_folder, check_subfolder,
                                      folder_in_place, install_folder)
from .interrupt import CtrlCStops
from .job_inputs import job_digest, job_files, read_job_report
from .job_worker import REPORT, JobResult, JobWorker, error_text, job_threads, set_threads
from .jobs import BatchSettings, JobsFile
from .packing import unpack
from .payload import JobPayload, finished_stage_folders, make_payload
from .summary import RESERVED_NAMES, JobOutcome, write_summary


def job_report(out_dir: Path, name: str) -> dict | None:
    return read_job_report(Path(out_dir) / name / REPORT)   # (data: a planted report reads as none)


def skipped_stages(report: dict) -> dict[str, str]:
    """{stage: why in a few words} of the stages a job's report says were skipped."""
    status = report.get("stage_status")
    return skipped_reasons(status) if isinstance(status, dict) else {}


def reused_stages(report: dict) -> tuple[str, ...]:
    """The stages a job's report says were reused."""
    stages = report.get("stages", {}).get("run", {}).get("stages", {})
    return tuple(name for name, stage in stages.items() if isinstance(stage, dict) and stage.get("status") == "reused")


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
                                                reused=reused_stages(report), skipped=skipped_stages(report))
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
                reused, skipped = reused_stages(result.report), skipped_stages(result.report)
                outcomes[job.name] = JobOutcome(job.name, "done", payload.attempt, result.report["seconds"],
                                                result.report.get("quality", {}), reused=reused, skipped=skipped)
                say(job.name, f"done in {result.report['seconds']:.1f} s (attempt {payload.attempt})"
                              + (f"; {', '.join(reused)} reused" if reused else "")
                              + "".join(f"; {name} skipped: {why}" for name, why in skipped.items()))
                continue
            error = error_text(result)
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
