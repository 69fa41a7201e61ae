"""An OSError as one sentence for the person running SceneFit: the path, what went wrong, what to do.

The command line ends every OSError here (cli/__init__.py) rather than with a traceback: a full
disk, a read-only or forbidden folder, a file where a folder should be, a busy rename. Paths are the
user's: a write into a run's hidden staging folder (or into an atomic write's temp file) is named
by the file it was going to become.
"""
from __future__ import annotations

import errno
import os
from pathlib import Path

from .atomic import TEMP_MARK, is_temp_name
from .output_folder import staging_path


_DISK_FULL = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)}   # EDQUOT: the user's quota is full
# Errors only a write gets (a full disk, a read-only mount).
_WRITE_ONLY = _DISK_FULL | {errno.EROFS}


def os_error_sentence(error: OSError, out: str | os.PathLike | None = None) -> str:
    """One sentence for `error`; `out` is the run's --out (None: the command writes no folder)."""
    out_path = Path(out).expanduser().absolute() if out else None
    first, second = error.filename, error.filename2
    code = error.errno
    # Creating or replacing a file: the destination of a rename is the one in the way.
    path = second if second is not None and code in (errno.EEXIST, errno.ENOTEMPTY) else first
    shown = _user_path(path, out_path) if path is not None else None
    if shown is None and out_path is not None and code in _WRITE_ONLY:
        shown = str(out_path)   # a write() to an open file names no path: the run's folder is where it went
    writing = shown is not None and out_path is not None and _is_output(Path(shown), out_path)
    # What to do instead: another --out when the run's own folder is the trouble, else another path.
    instead = "choose another --out folder" if writing else "give another path"
    reason = error.strerror or str(error) or type(error).__name__
    if shown is None:
        return (f"A file operation failed ({reason}); check that the disk has space and the paths given exist "
                "and may be written, and try again.")
    if code in _DISK_FULL:
        return (f"Cannot write '{shown}' (the disk is full); free space on it"
                f"{' or choose another --out folder' if writing else ' and try again'}.")
    if code == errno.EROFS:
        return f"Cannot write '{shown}' (the file system is read-only); {instead} on a writable disk."
    if code in (errno.EACCES, errno.EPERM):
        return (f"Cannot {'write' if writing else 'use'} '{shown}' (permission denied); change its permissions "
                f"or {instead}.")
    if code in (errno.EEXIST, errno.ENOTEMPTY):
        return f"'{shown}' already exists and is in the way; move it aside or {instead}."
    if code == errno.ENOTDIR:
        return f"'{shown}' is not a folder (a file of that name is in the way); move that file aside or {instead}."
    if code == errno.EISDIR:
        return f"'{shown}' is a folder where a file was expected; move it aside or {instead}."
    if code in (errno.EBUSY, getattr(errno, "ETXTBSY", -1)):
        return (f"'{shown}' is busy (open in another program, or a mount point); close what uses it and try "
                f"again, or {instead}.")
    if code == errno.ENOENT:
        return f"'{shown}' does not exist (moved or deleted while SceneFit ran?); check the path and try again."
    if code == errno.EXDEV:
        return f"Cannot move '{shown}' to another disk; {instead} on the same disk as its parent folder."
    if code == errno.ENAMETOOLONG:
        return f"The path '{shown}' is too long for the file system; {instead} with a shorter path."
    if code in (errno.EMFILE, errno.ENFILE):
        return f"Too many files are open to open '{shown}'; close other programs or raise the limit (ulimit -n)."
    return f"Cannot use '{shown}' ({reason}); check the path and the disk, and try again."


def with_out_paths(text: str, out: str | os.PathLike | None) -> str:
    """`text` with the run's hidden staging folder named as the --out it becomes."""
    if not out:
        return text

    out_path = Path(out).expanduser().absolute()
    return text.replace(str(staging_path(out_path)), str(out_path))


def _user_path(path, out: Path | None) -> str:
    """The path the user knows: a temp file's final name, a staging folder's place in `out`."""
    if isinstance(path, int):   # an OSError on a file descriptor
        return f"file descriptor {path}"
    p = Path(os.fsdecode(path))
    if is_temp_name(p.name):   # ".<name>.<random>.scenefit-tmp<ext>" -> "<name>"
        p = p.with_name(p.name[1:].split(TEMP_MARK)[0].rsplit(".", 1)[0])
    if out is not None:
        staging = staging_path(out)
        absolute = p if p.is_absolute() else p.absolute()
        if absolute == staging or staging in absolute.parents:
            return str(out / absolute.relative_to(staging))
    return str(p)


def _is_output(path: Path, out: Path) -> bool:
    """`path` is the run's output folder, inside it, a SceneFit file beside it (lock, staging) or its parent."""
    path = path if path.is_absolute() else path.absolute()
    if path in (out, out.parent) or out in path.parents:
        return True
    return path.parent == out.parent and path.name.startswith(f".{out.name}.")
