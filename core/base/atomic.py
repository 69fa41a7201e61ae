"""Atomic file writes: a temp file in the target folder, then a rename."""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any


# mkstemp creates files readable by their owner only; results are ordinary files for others to read.
FILE_MODE = 0o644
# Temp files are named ".<name>.<random>.scenefit-tmp<ext>" so a later run can tell a killed write's leftovers.
TEMP_MARK = ".scenefit-tmp"


def temp_affixes(path: Path, keep_suffix: bool = False) -> dict:
    """mkstemp prefix/suffix for a temp file beside `path` (keep_suffix: end in path's extension, for
    writers that pick the format from it)."""
    return {"prefix": f".{path.name}.", "suffix": TEMP_MARK + (path.suffix if keep_suffix else ""),
            "dir": path.parent}


def is_temp_name(name: str) -> bool:
    return name.startswith(".") and TEMP_MARK in name


def replace_atomic(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Give a finished temp file normal permissions and move it over `path` in one step."""
    os.chmod(tmp, FILE_MODE)
    os.replace(tmp, path)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(**temp_affixes(path))
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        replace_atomic(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Strict JSON (what every parser accepts): NaN and infinities are written as null."""
    return write_text_atomic(path, json.dumps(strict_json(obj), indent=2, sort_keys=False, allow_nan=False) + "\n")


def strict_json(value: Any) -> Any:
    """`value` with numpy arrays/scalars and paths made plain, and non-finite floats made None."""
    if isinstance(value, dict):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return strict_json(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
