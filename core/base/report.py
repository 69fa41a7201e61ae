"""A stage's report.json: strict JSON, written atomically, paths inside its folder made relative."""
from __future__ import annotations

import time
from pathlib import Path

from .atomic import write_json_atomic


def write_report(path: str | Path, report: dict) -> Path:
    """report.json in strict JSON; paths inside the report's folder are written relative to it, so
    they stay right when the run's folder is swapped into place or moved."""
    path = Path(path)
    report = dict(report)
    report.setdefault("written_at", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    return write_json_atomic(path, relative_paths(report, path.parent.absolute()))


def relative_paths(value, folder: Path):
    if isinstance(value, dict):
        return {k: relative_paths(v, folder) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [relative_paths(v, folder) for v in value]
    if isinstance(value, (str, Path)) and str(value):
        candidate = Path(value)
        if candidate.is_absolute() or isinstance(value, Path):
            try:
                return candidate.absolute().relative_to(folder).as_posix()
            except ValueError:
                return str(value) if isinstance(value, Path) else value
    return value
