"""A run's output folder as one unit: written beside, swapped in whole, locked, never mixed.

    with output_folder("out", replace=args.replace) as staging:
        ...write everything into `staging`...
    # now "out" holds exactly this run's files

- Before any work: `out` that is a file, or a place that cannot be written, is refused; so is an
  `out` holding files (an earlier run's results) unless `replace` is given.
- Files go into the hidden sibling `.out.partial`; only a finished run is renamed to `out` (the old
  folder moved aside first, then deleted), so a crash or Ctrl-C never leaves old and new files mixed.
- A lock file `.out.lock` (an OS lock, released when the process dies) refuses a second run into
  the same folder while one is writing.
- Leftovers of a killed run (a `.partial` folder, a folder moved aside, dot-temp files) are
  cleaned up by the next run; a resumable stage (adapt) keeps its `.partial` folder to resume from.
"""
from __future__ import annotations

import os
import shutil
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from .atomic import is_temp_name
from .errors import Cancelled, InputError


def staging_path(out: Path) -> Path:
    return out.parent / f".{out.name}.partial"


def _aside_path(out: Path) -> Path:
    return out.parent / f".{out.name}.old"


def _lock_path(out: Path) -> Path:
    return out.parent / f".{out.name}.lock"


def check_output_folder(out: str | os.PathLike, replace: bool = False) -> Path:
    """Refuse, before any work, an output that cannot become this run's folder; returns it absolute."""
    out = Path(out).expanduser().absolute()
    if out.exists() and not out.is_dir():
        raise InputError(f"The output '{out}' is a file; give a folder path for --out.")
    parent = out.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"Cannot write into '{parent}' (no permission); choose another --out folder.")
    if out.is_dir() and not replace and any(out.iterdir()):
        raise InputError(f"The output folder '{out}' already holds files (an earlier run's results?); "
                         "pass --replace to replace them, or choose an empty or new folder.")
    if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
        raise InputError(f"Cannot write into '{out}' (no permission); choose another --out folder.")
    return out


class _FolderLock:
    """An exclusive, non-blocking OS lock on `.out.lock`; the OS drops it if the process is killed."""

    def __init__(self, path: Path):
        self.path = path
        self.fd: int | None = None

    def acquire(self, out: Path) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            if not _try_lock(fd):
                os.close(fd)
                raise InputError(f"Another SceneFit run is writing into '{out}'; wait for it to finish "
                                 "or choose another --out folder.")
            # The holder before us may have deleted the file after we opened it: lock the file on disk.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                self.fd = fd
                return
            os.close(fd)

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.path)  # while still holding it, so no waiter is left locking a deleted file
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None


def _try_lock(fd: int) -> bool:
    if sys.platform == "win32":
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False


def remove_stale_temps(folder: Path) -> list[Path]:
    """Delete dot-temp files a killed write left behind (anywhere under `folder`)."""
    removed = []
    for path in folder.rglob(".*"):
        if path.is_file() and is_temp_name(path.name):
            path.unlink()
            removed.append(path)
    return removed


def _recover(out: Path) -> None:
    """Undo what a run killed mid-swap left: put the moved-aside folder back, or delete it."""
    aside = _aside_path(out)
    if aside.exists():
        if out.exists():
            shutil.rmtree(aside)
        else:
            aside.rename(out)


def _swap_in(staging: Path, out: Path) -> None:
    aside = _aside_path(out)
    if out.exists():
        out.rename(aside)
    staging.rename(out)
    if aside.exists():
        shutil.rmtree(aside)


@contextmanager
def output_folder(out: str | os.PathLike, replace: bool = False, resume: bool = False) -> Iterator[Path]:
    """Yield the staging folder to write this run into; on success it becomes `out`, whole.

    resume: keep the staging folder of an interrupted run (and keep it again if this one is
    interrupted), for stages that checkpoint into it.
    """
    out = check_output_folder(out, replace)
    lock = _FolderLock(_lock_path(out))
    lock.acquire(out)
    staging = staging_path(out)
    keep_staging = False
    try:
        _recover(out)
        check_output_folder(out, replace)  # a restored folder counts as an earlier run's results
        if staging.exists() and not resume:
            shutil.rmtree(staging)
        staging.mkdir(parents=True, exist_ok=True)
        remove_stale_temps(staging)
        try:
            yield staging
        except (KeyboardInterrupt, Cancelled):
            keep_staging = resume
            raise
        remove_stale_temps(staging)
        _swap_in(staging, out)
    finally:
        if staging.exists() and not keep_staging:
            shutil.rmtree(staging, ignore_errors=True)
        lock.release()


def interrupted_message(out: str | os.PathLike, resumable: bool = False, by_stage: bool = False) -> str:
    """What the user is told after Ctrl-C or a cancel inside `output_folder` (by_stage: `scenefit run`,
    whose finished stages stay in `out` with their stage.json and are reused by the next run)."""
    if by_stage:
        return (f"interrupted; the stages finished so far are kept in '{out}' and the unfinished one is redone: "
                "run the same command again to resume.")
    if resumable:
        return (f"interrupted; '{out}' is unchanged and the progress so far is kept: run the same command again "
                "to resume.")
    return f"interrupted; '{out}' is unchanged (nothing of this run was written to it)."
