"""Files and folders as bytes (a gzip tar), so a job's inputs and outputs travel to and from a worker on
another node without a shared disk."""
from __future__ import annotations

import io
import tarfile
from pathlib import Path


def pack(paths: dict[str, Path]) -> bytes:
    """A tar (gzip) of files and folders, each stored under its given name; a link as the file it points at."""
    buffer = io.BytesIO()
    # Level 1: a job's files are mostly compressed already (PNG, EXR, torch's zip), so gzip's default 9 took
    # 1.6x the time for 0.6% less.
    with tarfile.open(fileobj=buffer, mode="w:gz", compresslevel=1, dereference=True) as tar:
        for name, path in paths.items():
            tar.add(str(path), arcname=name)
    return buffer.getvalue()


def unpack(data: bytes, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        tar.extractall(folder, filter="data")   # refuses absolute paths and '..'
    return folder
