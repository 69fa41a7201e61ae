"""A stage's report.json: strict JSON, written atomically, paths inside its folder made relative."""
from __future__ import annotations

import os
import re
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
    """`value` with every path inside `folder` relative to it: whole strings (and Paths) as relative
    paths, and inside text ("read asset folder '/x/.out.partial/asset'") too; a staging folder's name
    anywhere (`.out.partial`, `.job.partial-1a2b`) is the name of the folder it becomes, which is where
    the path leads once the run is swapped into place."""
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
                pass
        return final_names(str(value).replace(f"{folder}{os.sep}", "")) if isinstance(value, Path) or \
            "partial" in value or str(folder) in value else value
    return value


# A staging folder's name: `.NAME.partial` (a run's, core/base/output_folder.staging_path) or
# `.NAME.partial-XXXX` (a batch job's, install_folder), as a path component.
_STAGING = re.compile(r"(?<![^/\\'\"])\.([^/\\'\"]+?)\.partial(?:-[A-Za-z0-9_]+)?(?=$|[/\\'\"])")


def final_names(text: str) -> str:
    """`text` with each staging folder's name in a path replaced by the name of the folder it becomes."""
    return _STAGING.sub(r"\1", text)
