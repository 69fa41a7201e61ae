"""A run's output folder as one unit: written beside, swapped in whole, locked, never mixed, and
never anything but SceneFit's own folder replaced.

    with output_folder("out", replace=args.replace, inputs=[asset, photo]) as staging:
        ...write everything into `staging`...
    # now "out" holds exactly this run's files

The contract (docs/technical/output-folder.md):
- Before any work: an `out` that is a file, a symbolic link, a place that cannot be written, the
  root, the home folder, the working folder or an ancestor of one of them, or a folder that holds
  any input of the run, is refused in one sentence.
- An `out` holding files is refused unless `replace` is given, and `replace` only ever replaces a
  SceneFit run folder: one holding the marker file `.scenefit-run` that SceneFit writes into every
  run folder it makes. A folder without it is never deleted, whatever it is called.
- Files go into the hidden sibling `.out.partial`; only a finished run is renamed to `out` (the old
  folder moved aside first, then deleted), so a crash, Ctrl-C or kill never leaves old and new files
  mixed: until the swap, an earlier finished folder stays whole.
- A lock file `.out.lock` (an OS lock, released when the process dies) refuses a second run into
  the same folder while one is writing.
- Leftovers of a killed run (a `.partial` folder, a folder moved aside, dot-temp files) are
  recognised by the marker, not by their names, and cleaned up by the next run; a resumable stage
  (adapt) keeps its `.partial` folder to resume from; `scenefit run` (reuse) starts its staging
  folder from the earlier finished folder's files, so finished stages are reused, and keeps it when
  stopped.
"""
from __future__ import annotations

import errno
import filecmp
import json
import os
import shutil
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

from .atomic import is_temp_name
from .errors import Cancelled, InputError

MARKER = ".scenefit-run"
MARKER_FORMAT = "scenefit.run-folder"
LOCK_TEXT = b"scenefit lock\n"


def staging_path(out: Path) -> Path:
    return out.parent / f".{out.name}.partial"


def _aside_prefix(out: Path) -> str:
    return f".{out.name}.old-"


def _lock_path(out: Path) -> Path:
    return out.parent / f".{out.name}.lock"


# -- the marker ------------------------------------------------------------------------------------

def write_marker(folder: Path, role: str = "run") -> None:
    """Mark `folder` as SceneFit's own (role: run, or aside for a folder moved aside in a swap)."""
    (folder / MARKER).write_text(json.dumps({"format": MARKER_FORMAT, "role": role}) + "\n")


def is_run_folder(folder: Path, role: str = "run") -> bool:
    """Whether `folder` is a real folder (not a link) that SceneFit made: it holds the marker."""
    marker = folder / MARKER
    if folder.is_symlink() or not folder.is_dir() or marker.is_symlink() or not marker.is_file():
        return False
    try:
        data = json.loads(marker.read_text()[:1000])
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and data.get("format") == MARKER_FORMAT and data.get("role") == role


# -- refusals before any work ------------------------------------------------------------------------

def _protected_folders() -> list[tuple[Path, str]]:
    """Folders a run may never be written over (nor any of their ancestors)."""
    found = [(Path(Path.cwd().anchor).resolve(), "the root of the file system")]
    for path, what in ((Path.home(), "your home folder"), (Path.cwd(), "the working folder")):
        try:
            found.append((path.resolve(), what))
        except OSError:
            pass
    return found


def _real_inputs(inputs: Iterable) -> list[Path]:
    paths = []
    for item in inputs:
        if item is None or str(item) == "":
            continue
        path = Path(item).expanduser()
        if path.exists():
            paths.append(path.resolve())
    return paths


def check_output_folder(out: str | os.PathLike, replace: bool = False, inputs: Iterable = (),
                        reuse: bool = False) -> Path:
    """Refuse, before any work, an output that cannot become this run's folder; returns it absolute.

    inputs: the run's input files and folders; `out` may not be one or hold one.
    reuse: an earlier SceneFit run folder is taken up rather than refused (`scenefit run`).
    """
    given = Path(out).expanduser()
    out = given.absolute()
    if given.is_symlink():
        raise InputError(f"The output '{out}' is a symbolic link (to '{os.readlink(given)}'); SceneFit does not "
                         "write through links: give the real folder's path, or a new one, as --out.")
    if out.exists() and not out.is_dir():
        raise InputError(f"The output '{out}' is a file; give a folder path for --out.")
    resolved = out.resolve()
    for folder, what in _protected_folders():
        if resolved == folder or resolved in folder.parents:
            raise InputError(f"The output folder '{out}' is {what} or holds it, which SceneFit never replaces; "
                             f"choose a new folder for --out, such as '{out / 'scenefit-out'}'.")
    for path in _real_inputs(inputs):
        if path == resolved or resolved in path.parents:
            raise InputError(f"The output folder '{out}' holds the input '{path}', and SceneFit never writes over "
                             "its inputs; choose a new folder for --out.")
    parent = out.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"'{parent}' is a file, so '{out}' cannot be made inside it; choose another --out folder.")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"Cannot write into '{parent}' (no permission); choose another --out folder.")
    if out.is_dir() and any(out.iterdir()):
        ours = is_run_folder(out)
        if not ours:
            raise InputError(f"The output folder '{out}' holds files that SceneFit did not write (it has no "
                             f"{MARKER} marker), so SceneFit will not replace them even with --replace; choose an "
                             "empty or new folder for --out.")
        if not replace and not reuse:
            raise InputError(f"The output folder '{out}' already holds an earlier SceneFit run; pass --replace to "
                             "replace it, or choose an empty or new folder.")
    if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
        raise InputError(f"Cannot write into '{out}' (no permission); choose another --out folder.")
    return out


# -- the lock ------------------------------------------------------------------------------------------

class _FolderLock:
    """An exclusive, non-blocking OS lock on `.out.lock`; the OS drops it if the process is killed.

    The file holds LOCK_TEXT; a file of that name with anything else in it is the user's and is
    neither used nor deleted."""

    def __init__(self, path: Path):
        self.path = path
        self.fd: int | None = None

    def acquire(self, out: Path) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            if self.path.is_symlink() or (self.path.exists() and not self._ours()):
                raise InputError(f"'{self.path}' is in the way and was not made by SceneFit; move it, or choose "
                                 "another --out folder.")
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
                os.ftruncate(fd, 0)
                os.write(fd, LOCK_TEXT)
                self.fd = fd
                return
            os.close(fd)

    def _ours(self) -> bool:
        try:
            with open(self.path, "rb") as f:
                text = f.read(64)
        except OSError:
            return False
        return text in (b"", LOCK_TEXT)   # empty: created by a holder killed before it wrote

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
        import msvcrt  # lazy: Windows only

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    import fcntl  # lazy: POSIX only

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False


# -- leftovers and the swap ----------------------------------------------------------------------------

def remove_stale_temps(folder: Path) -> list[Path]:
    """Delete dot-temp files a killed write left behind (anywhere under `folder`)."""
    removed = []
    for path in folder.rglob(".*"):
        if path.is_file() and not path.is_symlink() and is_temp_name(path.name):
            path.unlink()
            removed.append(path)
    return removed


def _asides(out: Path) -> list[Path]:
    """Folders a swap moved `out` into (each holds `out`'s name inside it), newest last."""
    found = [p for p in out.parent.glob(_aside_prefix(out) + "*") if is_run_folder(p, role="aside")]
    return sorted(found, key=lambda p: p.stat().st_mtime)


def _recover(out: Path) -> None:
    """Undo what a run killed mid-swap left: put the moved-aside folder back, or delete it."""
    for aside in reversed(_asides(out)):
        inside = aside / out.name
        if not out.exists() and inside.is_dir():
            inside.rename(out)
        shutil.rmtree(aside)


def _swap_in(staging: Path, out: Path) -> None:
    """Rename `staging` to `out`; an earlier run folder there is moved aside first, then deleted."""
    aside = None
    if out.is_dir() and is_run_folder(out):
        aside = Path(tempfile.mkdtemp(prefix=_aside_prefix(out), dir=out.parent))
        write_marker(aside, role="aside")
        out.rename(aside / out.name)
    elif out.is_dir():
        try:
            out.rmdir()   # an empty folder the user made for this run
        except OSError as error:
            if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                raise
            raise InputError(f"Files appeared in '{out}' while SceneFit was writing; this run is kept beside it in "
                             f"'{staging.name}' and '{out}' is untouched: move them away and run again.") from None
    try:
        staging.rename(out)
    except OSError:
        if aside is not None and not out.exists():
            (aside / out.name).rename(out)   # the earlier folder back in place, whole
        raise
    if aside is not None:
        shutil.rmtree(aside)


def _prepare_staging(out: Path, staging: Path, resume: bool, reuse: bool) -> None:
    if staging.is_symlink() or (staging.exists() and not is_run_folder(staging)):
        raise InputError(f"'{staging}' is in the way and was not made by SceneFit; move it, or choose another "
                         "--out folder.")
    if staging.exists() and not (resume or reuse):
        shutil.rmtree(staging)
    if not staging.exists():
        if reuse and is_run_folder(out):
            # Hard links: every SceneFit write replaces a file (atomic rename), never writes into one,
            # so the earlier folder's files stay as they were while the new run reuses them.
            shutil.copytree(out, staging, symlinks=True, copy_function=_link_or_copy)
        else:
            staging.mkdir(parents=True)
    write_marker(staging)
    remove_stale_temps(staging)
    drop_links(staging)


def drop_links(folder: Path) -> list[Path]:
    """Delete every symbolic link under `folder` (the link itself, never what it points at): SceneFit makes
    none in its folders, so one there was planted, and a stage writing through it would write elsewhere."""
    dropped = []
    for root, dirs, names in os.walk(folder):   # (os.walk does not descend into linked folders)
        for name in dirs + names:
            path = Path(root) / name
            if path.is_symlink():
                path.unlink()
                dropped.append(path)
    return dropped


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _finished_here(staging: Path, out: Path) -> list[str]:
    """The stages finished in `staging` that `out` does not already hold (a `run` starts its staging folder
    from `out`'s files, hard-linked or, where links fail, copied: those are no work of this run), in the
    order they finished."""
    found = []
    for path in staging.glob("*/stage.json"):
        same = out / path.parent.name / "stage.json"
        try:
            if same.is_file() and filecmp.cmp(path, same, shallow=False):
                continue
            found.append((path.stat().st_mtime_ns, path.parent.name))
        except OSError:
            continue
    return [name for _, name in sorted(found)]


# The attribute an exception leaving `output_folder` carries: the stages kept beside `out` for the next run.
KEPT_ATTRIBUTE = "scenefit_kept_stages"


# On a Ctrl-C or cancel out of a batch: the jobs it finished, each swapped into its folder whole.
FINISHED_JOBS_ATTRIBUTE = "scenefit_finished_jobs"


def finished_jobs(error: BaseException) -> list[str] | None:
    """The jobs a `scenefit batch` stopped by `error` had finished (None: not a batch's stop)."""
    jobs = getattr(error, FINISHED_JOBS_ATTRIBUTE, None)
    return None if jobs is None else list(jobs)


def kept_stages(error: BaseException) -> list[str]:
    """The finished stages a `scenefit run` stopped by `error` kept beside its folder ([] when none, or
    when the run never reached its folder)."""
    return list(getattr(error, KEPT_ATTRIBUTE, []))


def kept_stages_sentence(error: BaseException, out: str | os.PathLike) -> str:
    """' The finished stages (convert, light) are kept beside 'out' ...' after a `scenefit run` stopped by
    `error`, or '' when it kept none, so a failed run never leaves work behind unsaid."""
    kept = kept_stages(error)
    if not kept:
        return ""
    return (f" The finished stages ({', '.join(kept)}) are kept beside '{out}' in "
            f"'{staging_path(Path(out)).name}'; the next run into it reuses each whose inputs and settings are "
            "the same.")


@contextmanager
def output_folder(out: str | os.PathLike, replace: bool = False, resume: bool = False, inputs: Iterable = (),
                  reuse: bool = False) -> Iterator[Path]:
    """Yield the staging folder to write this run into; on success it becomes `out`, whole.

    resume: keep the staging folder of an interrupted run (and keep it again if this one is
    interrupted), for stages that checkpoint into it.
    reuse: start from an earlier run folder at `out` (without --replace) and keep the staging folder
    whenever the run stops with a finished stage in it (`scenefit run`, which reuses stages).
    inputs: the run's inputs, which `out` may not be or hold.
    """
    inputs = list(inputs)
    out = check_output_folder(out, replace, inputs, reuse)
    lock = _FolderLock(_lock_path(out))
    lock.acquire(out)
    staging = staging_path(out)
    keep_staging = False
    try:
        _recover(out)
        check_output_folder(out, replace, inputs, reuse)  # a restored folder counts as an earlier run's results
        _prepare_staging(out, staging, resume, reuse)
        try:
            yield staging
        except BaseException as error:
            finished = _finished_here(staging, out) if reuse else []
            interrupted = isinstance(error, (KeyboardInterrupt, Cancelled))
            keep_staging = (resume and interrupted) or bool(finished)
            if finished:
                setattr(error, KEPT_ATTRIBUTE, finished)
            raise
        remove_stale_temps(staging)
        try:
            _swap_in(staging, out)
        except InputError:   # files appeared in `out`: this run's files wait beside it, as the sentence says
            keep_staging = True
            raise
    finally:
        if staging.exists() and not keep_staging and is_run_folder(staging):
            shutil.rmtree(staging, ignore_errors=True)
        lock.release()


@contextmanager
def folder_in_place(out: str | os.PathLike, inputs: Iterable = ()) -> Iterator[Path]:
    """A folder updated part by part under the lock (`scenefit batch`: DIR/<job>/ swapped in one job at
    a time by `install_folder`): the same refusals as `output_folder`, then it is marked as SceneFit's."""
    out = check_output_folder(out, inputs=list(inputs), reuse=True)
    lock = _FolderLock(_lock_path(out))
    lock.acquire(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_marker(out)
        yield out
    finally:
        lock.release()


def check_subfolder(parent: Path, name: str) -> Path:
    """Refuse, before any work, a parent/name that is not SceneFit's to replace (a user's folder or file)."""
    final = Path(parent) / name
    if final.is_symlink() or (final.exists() and not final.is_dir()) or (
            final.is_dir() and any(final.iterdir()) and not is_run_folder(final)):
        raise InputError(f"'{final}' already exists and was not made by SceneFit, so it is not replaced; rename "
                         "the job or move that folder away.")
    return final


def install_folder(parent: str | os.PathLike, name: str, fill: Callable[[Path], object]) -> Path:
    """Make parent/name by filling a fresh staging folder beside it and swapping it in whole; an earlier
    folder there is replaced only when SceneFit made it."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    final = check_subfolder(parent, name)
    _recover(final)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.partial-", dir=parent))
    try:
        write_marker(staging)
        fill(staging)
        staging.chmod(0o755)
        write_marker(staging)   # `fill` may have unpacked a folder from elsewhere over it
        remove_stale_temps(staging)
        _swap_in(staging, final)
        return final
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)


def interrupted_message(out: str | os.PathLike, resumable: bool = False, by_stage: bool = False,
                        kept: Sequence[str] = (), jobs: list[str] | None = None) -> str:
    """What the user is told after Ctrl-C or a cancel inside `output_folder` (by_stage: `scenefit run`, with
    the stages it kept (`kept_stages`),
    whose finished stages are kept beside `out` and reused by the next run; jobs: `scenefit batch`, the jobs
    it finished, each swapped into `out` whole)."""
    if jobs is not None:
        if not jobs:
            return f"interrupted; '{out}' is unchanged but for its summary (no job had finished)."
        return (f"interrupted; the jobs finished before it ({', '.join(jobs)}) are in '{out}', each folder whole, the "
                "others as they were (summary.md says which): run the same command again to run them.")
    if by_stage:
        if not kept:
            return f"interrupted; '{out}' is unchanged (no stage had finished, so nothing of this run was kept)."
        return (f"interrupted; '{out}' is unchanged and the stages finished so far ({', '.join(kept)}) are kept "
                "beside it: run the same command again to resume (the unfinished stage is redone).")
    if resumable:
        return (f"interrupted; '{out}' is unchanged and the progress so far is kept: run the same command again "
                "to resume.")
    return f"interrupted; '{out}' is unchanged (nothing of this run was written to it)."
