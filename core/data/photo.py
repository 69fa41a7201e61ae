"""A photo read once: sRGB in [0, 1] at the light stage's working size, upright, with what was decided
reading it (its stored size, its 35 mm focal length); every stage and entry point that reads a photo
(the camera, light and compose stages, the pipeline, `scenefit compose`, Blender's Estimate Light, the demo)
reads it here.
"""
from __future__ import annotations

import copy
import functools
import math
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from .imageio import linear_to_srgb, read_image

# A focal length outside this is not one (EXIF text, zero, a huge number); the camera's EXIF reading shares it.
FOCAL_RANGE_MM = (1.0, 5000.0)


def plausible_focal_mm(value) -> float | None:
    """`value` as a focal length in mm when it is a finite number in FOCAL_RANGE_MM, else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value) if FOCAL_RANGE_MM[0] <= value <= FOCAL_RANGE_MM[1] else None


def camera_exposure(radiance: np.ndarray, key: float = 0.18) -> float:
    """Auto-exposure as a camera meters: the scene's log-average luminance maps to middle grey."""
    lum = radiance[..., :3] @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    log_average = float(np.exp(np.mean(np.log(np.maximum(lum, 1e-6)))))
    return key / max(log_average, 1e-6)


# Nothing in the light stage looks at a photo more closely than this: the panorama splats at most
# 768 px on the long side, the depth model sees 518, the critics 512. Larger photos are reduced while
# they are read (an 8000x6000 photo peaked at 5.1 GB to make a 64x128 map).
PHOTO_WORKING_SIDE = 1024


def load_photo(path: str | Path, max_side: int | None = PHOTO_WORKING_SIDE) -> tuple[np.ndarray, dict]:
    """A photo as sRGB-encoded float32 RGB in [0, 1], and what was decided reading it.

    Photos longer than `max_side` are area-reduced by a whole factor while read (linear radiance
    for EXR/HDR, so a small bright light keeps its energy); the report gives both sizes.

    8/16-bit files are taken as stored (sRGB). Float files (EXR/HDR) hold linear radiance: they are
    exposed as a camera meters (log-average luminance -> 0.18), clipped and sRGB-encoded, so every
    photo reaches the panorama as the LDR image a camera would have stored. Photos are turned
    upright as their EXIF Orientation says (a phone's portrait photo is stored sideways), so `--at`
    and the composite refer to the photo as every viewer shows it.
    """
    path = Path(path)
    try:
        stat = path.stat()
        key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    except OSError:
        key = None   # read_image says what is wrong with it
    if key is None or max_side is None or max_side > PHOTO_WORKING_SIDE:   # (a full-size copy is read once a run)
        return _decoded_photo(path, max_side)
    rgb, info = _decoded_photo_once(key, path, max_side)
    return rgb.copy(), copy.deepcopy(info)


@functools.lru_cache(maxsize=2)
def _decoded_photo_once(key: tuple, path: Path, max_side: int | None) -> tuple[np.ndarray, dict]:
    """A run reads its photo at the light stage's size several times (inputs, camera, light): once
    decoded here while the file stays the same (`key`: its path, time and size). Two such copies at
    most (about 9 MB each) stay in a long-lived process such as Blender."""
    return _decoded_photo(path, max_side)


def _decoded_photo(path: Path, max_side: int | None) -> tuple[np.ndarray, dict]:
    pixels = read_image(path, max_side=max_side, upright=True)
    if pixels.shape[2] == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    elif pixels.shape[2] == 2:
        pixels = np.repeat(pixels[..., :1], 3, axis=2)
    rgb = np.ascontiguousarray(pixels[..., :3], np.float32)
    h, w = rgb.shape[:2]
    info: dict = {"path": str(path), "size": _metadata(path).get("size", [w, h])}
    # Messages give the size as stored (a 1x10000 photo is read as 1x1000; the user never saw that).
    stored_w, stored_h = info["size"]
    if min(stored_w, stored_h) < 2:
        raise InputError(f"The photo '{path}' is {stored_w}x{stored_h}; it needs at least 2x2 pixels.")
    if min(h, w) < 2:
        raise InputError(f"The photo '{path}' is {stored_w}x{stored_h}, too thin for the light stage (it reduces "
                         f"photos to at most {max_side} px on the long side, which leaves {w}x{h}); crop it to a "
                         f"less extreme shape.")
    if info["size"] != [w, h]:
        info["working_size"] = {"size": [w, h], "why": f"reduced while read: the light stage needs at most "
                                                      f"{max_side} px on the long side"}
    if path.suffix.lower() in (".exr", ".hdr"):
        rgb = np.nan_to_num(np.maximum(rgb, 0.0), nan=0.0, posinf=0.0)
        exposure = camera_exposure(rgb)
        info["decoded"] = f"linear HDR exposed by x{exposure:.4g} (log-average luminance -> 0.18), clipped, sRGB-encoded"
        rgb = linear_to_srgb(np.clip(rgb * exposure, 0.0, 1.0))
    else:
        info["decoded"] = "sRGB as stored"
        rgb = np.clip(rgb, 0.0, 1.0)
    focal35 = _metadata(path).get("focal35")
    if focal35 is not None and plausible_focal_mm(focal35) is None:
        info["metadata_ignored"] = f"EXIF FocalLengthIn35mmFilm {str(focal35)[:40]!r} is not a focal length " \
                                   f"({FOCAL_RANGE_MM[0]:g} to {FOCAL_RANGE_MM[1]:g} mm)"
    elif focal35:
        # The 35 mm equivalent is defined on the diagonal (43.27 mm); the width's share of it gives the
        # horizontal view of any aspect ratio, upright portrait photos included.
        film_width = 43.27 * w / np.hypot(w, h)
        info["fov_from_metadata_deg"] = round(float(np.degrees(2 * np.arctan(film_width / (2 * float(focal35))))), 3)
    return rgb, info


def _metadata(path: Path) -> dict:
    """The photo's upright size (EXIF Orientation 5-8 swap width and height) and 35 mm focal length."""
    import OpenImageIO as oiio  # lazy: Blender may lack it (missing_modules)

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return {}
    try:
        spec = inp.spec()
        size = [spec.width, spec.height]
        if spec.get_int_attribute("Orientation", 1) >= 5:
            size.reverse()
        return {"size": size, "focal35": spec.getattribute("Exif:FocalLengthIn35mmFilm")}
    finally:
        inp.close()
