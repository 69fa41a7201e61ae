"""What a worker anywhere needs to run a job: the job and its input files packed (`JobPayload`), with the
finished stages of its earlier run to reuse (`earlier/`), and the job unpacked again on the worker."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

from .job_inputs import job_digest, job_files
from .jobs import Job
from .packing import pack, unpack


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
    """The stage folders of a run folder that hold a finished stage (its stage.json) and nothing but plain
    files and folders: a link would be sent as the file it points at, and a named pipe, socket or device
    cannot travel (the payload's unpacking refuses them); those stages are run again instead."""
    from ..core.pipeline.layout import STAGE_FILE
    from ..core.pipeline.registry import RUN_ORDER

    if folder is None or not folder.is_dir():
        return []
    return [folder / name for name in RUN_ORDER if (folder / name / STAGE_FILE).is_file()
            and not (folder / name).is_symlink() and _plain(folder / name)]


def _plain(folder: Path) -> bool:
    """Whether everything under `folder` is a plain file or folder (no link, pipe, socket or device)."""
    return all(not p.is_symlink() and (p.is_dir() or p.is_file()) for p in folder.rglob("*"))


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
