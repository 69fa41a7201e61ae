"""The camera stage: the photo's camera, found once a run (core/stages/camera.py), written as the typed
camera/camera.json that light, adapt and compose read as a PhotoCamera.

    report = write_camera(camera, estimate_record, folder)      # the stage's write
    camera = read_camera(folder / CAMERA_FILE, width, height)    # at the reader's image size

A camera.json is data from wherever the run folder came from (an earlier run, a worker): read_camera
takes it only when every value is a finite number a camera can have, else says so in one sentence.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

from ..base.atomic import write_json_atomic
from ..base.errors import InputError
from ..scene.camera import PhotoCamera
from .camera import check_camera_values

CAMERA_FILE = "camera.json"
MAX_CAMERA_FILE_BYTES = 1 << 20   # a camera and its estimate's record are a few kilobytes
_ANGLES = ("yaw_deg", "pitch_deg", "fov_deg", "roll_deg")
_SHIFTS = ("shift_x", "shift_y")   # optional: a camera.json without them has no lens shift


def write_camera(camera: PhotoCamera, estimate: dict, folder: str | Path) -> dict:
    """camera.json in `folder`: the camera as the run uses it and the estimate's record (where each value
    came from); returns the stage's report."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / CAMERA_FILE
    write_json_atomic(path, {"photo_camera": asdict(camera), "estimate": estimate})
    return {"stage": "camera", "photo_camera": asdict(camera), "source": estimate.get("source", ""),
            "outputs": {"camera": str(path)}}


def read_camera(path: str | Path, width: int, height: int) -> tuple[PhotoCamera, dict]:
    """(the camera of `path` at an image of `width` x `height`, the estimate's record); one sentence
    (InputError) for a file that is not a camera.json of finite, possible values."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_CAMERA_FILE_BYTES:
            raise ValueError(f"it is over {MAX_CAMERA_FILE_BYTES} bytes")
        saved = json.loads(path.read_text(encoding="utf-8"), parse_constant=_no_constant)
        camera, estimate = saved["photo_camera"], saved.get("estimate", {})
        values = {**{k: camera[k] for k in _ANGLES}, **{k: camera.get(k, 0.0) for k in _SHIFTS}}
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                   for v in values.values()) or not isinstance(estimate, dict):
            raise ValueError("its angles and shift are not all finite numbers")
        check_camera_values({k: values[k] for k in ("fov_deg", "pitch_deg", "roll_deg", *_SHIFTS)})
    except (OSError, UnicodeDecodeError, RecursionError, ValueError, KeyError, TypeError, InputError) as error:
        raise InputError(f"The camera stage's '{path}' cannot be used ({_why(error)}); run again with --replace "
                         "to find the camera anew.") from None
    return PhotoCamera(**{k: float(v) for k, v in values.items()}, width=width, height=height), estimate


def _no_constant(name: str):
    raise ValueError(f"it holds {name}, which is not a number")


def _why(error: BaseException) -> str:
    if isinstance(error, KeyError):
        return f"it has no {error}"
    if isinstance(error, RecursionError):
        return "it nests too deep"
    return str(error).rstrip(".") or type(error).__name__
