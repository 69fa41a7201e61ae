"""An fSpy project's solved camera, read as data from elsewhere: every number finite and in range, or one
sentence naming the file (core/stages/camera.py turns it into the photo's camera estimate)."""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..base.untrusted import parse_json
from ..scene.camera import pitch_roll_from_camera_to_world

FSPY_MAGIC = b"fspy"
FSPY_HEADER = struct.Struct("<4sIII")
MAX_FSPY_SIDE = 1 << 20   # pixels: larger than any photo, so a larger image size is a damaged project   # magic, version, state JSON bytes, image bytes (little-endian)


def read_fspy(path: str | Path) -> dict:
    """The solved camera of an fSpy project: fov_deg, pitch_deg, roll_deg, image size, principal point.

    fSpy's documented layout: 'fspy', uint32 version (1), uint32 state length, uint32 image length,
    the state as UTF-8 JSON, then the image. The state's cameraParameters holds horizontalFieldOfView
    (radians) and cameraTransform.rows, a camera-to-world 4x4 matrix (the camera looks down its -Z with
    +Y up; world Z is up with fSpy's default axes)."""
    path = Path(path)
    data = _fspy_bytes(path)
    magic, version, state_len, image_len = FSPY_HEADER.unpack_from(data)
    if magic != FSPY_MAGIC:
        raise InputError(f"'{path}' is not an fSpy project (it does not start with 'fspy'); give the .fspy file "
                         "fSpy saved.")
    if version != 1:
        raise InputError(f"The fSpy project '{path}' is format version {version}; SceneFit reads version 1, so "
                         "save it again with fSpy 1.x.")
    if FSPY_HEADER.size + state_len + image_len > len(data):
        raise InputError(f"The fSpy project '{path}' is truncated (its header promises {state_len + image_len} "
                         f"bytes of state and image, the file holds {len(data) - FSPY_HEADER.size}); save it again "
                         "in fSpy.")
    try:
        state = parse_json(data[FSPY_HEADER.size:FSPY_HEADER.size + state_len], f"the fSpy project '{path}': its state")
    except InputError as error:
        raise InputError(f"{error} Save it again in fSpy.") from None
    return _fspy_camera(state, path)


def _fspy_bytes(path: Path) -> bytes:
    if not path.is_file():
        raise InputError(f"The fSpy project '{path}' does not exist; give the .fspy file fSpy saved.")
    data = path.read_bytes()
    if len(data) < FSPY_HEADER.size:
        raise InputError(f"'{path}' is {len(data)} byte{'' if len(data) == 1 else 's'}, shorter than an fSpy "
                         f"project's {FSPY_HEADER.size}-byte header; give the .fspy file fSpy saved.")
    return data


def _fspy_camera(state, path: Path) -> dict:
    params = state.get("cameraParameters") if isinstance(state, dict) else None
    if not isinstance(params, dict):
        raise InputError(f"The fSpy project '{path}' holds no solved camera (cameraParameters is empty); adjust its "
                         "vanishing lines in fSpy until it shows a camera, then save it again.")
    try:
        fov = math.degrees(float(params["horizontalFieldOfView"]))
        matrix = np.asarray(params["cameraTransform"]["rows"], dtype=np.float64)
        size = (int(params["imageWidth"]), int(params["imageHeight"]))
        principal = params.get("principalPoint") or {"x": 0.0, "y": 0.0}
        principal = (float(principal["x"]), float(principal["y"]))
    except (KeyError, TypeError, ValueError, OverflowError) as error:   # (int(1e400): OverflowError)
        raise InputError(f"The fSpy project '{path}' has an incomplete camera ({type(error).__name__}: {error}); "
                         "save it again in fSpy.") from None
    if not all(math.isfinite(v) for v in principal) or max(size) > MAX_FSPY_SIDE:
        raise InputError(f"The fSpy project '{path}' has an unusable image size or principal point ({size[0]}x"
                         f"{size[1]}, {principal}); solve it again in fSpy and save.")
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)) or not 0.0 < fov < 180.0 or min(size) < 1:
        raise InputError(f"The fSpy project '{path}' has an unusable camera (field of view {fov:.3g} deg, transform "
                         f"of shape {matrix.shape}); solve it again in fSpy and save.")
    pitch, roll = pitch_roll_from_camera_to_world(matrix[:3, :3], path)
    return {"fov_deg": fov, "pitch_deg": pitch, "roll_deg": roll, "image_size": size, "principal_point": principal}
