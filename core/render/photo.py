"""Synthetic photos from HDR environment maps, taken as a camera would take them.

Used for the bundled example and for measuring light estimation against ground truth: a
perspective view cut out of an equirectangular HDR map, exposed, clipped and stored in 8 bits.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..data.imageio import linear_to_srgb
from ..data.photo import camera_exposure
from ..scene.camera import PhotoCamera
from ..scene.frame import blender_direction_to_equirect_uv


def studiolights_folder() -> Path:
    """The CC0 HDR maps inside the bpy wheel (found without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise InputError("The bpy module is not installed, so its bundled HDR maps cannot be found.")
    hits = sorted(Path(spec.origin).parent.glob("*/datafiles/studiolights/world"))
    if not hits:
        raise InputError(f"No datafiles/studiolights/world folder inside {Path(spec.origin).parent}.")
    return hits[-1]


def studiolight_path(name: str) -> Path:
    path = studiolights_folder() / f"{name}.exr"
    if not path.is_file():
        available = sorted(p.stem for p in studiolights_folder().glob("*.exr"))
        raise InputError(f"No studio light '{name}'; available: {', '.join(available)}.")
    return path


def perspective_view(envmap: np.ndarray, camera: PhotoCamera) -> np.ndarray:
    """Linear radiance seen by `camera` in an equirectangular map (bilinear, wrapping in u)."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    h, w = envmap.shape[:2]
    uv = blender_direction_to_equirect_uv(camera.ray_directions())
    map_x = (uv[..., 0] * w - 0.5).astype(np.float32)
    map_y = np.clip(uv[..., 1] * h - 0.5, 0, h - 1).astype(np.float32)
    padded = np.concatenate([envmap[:, -1:], envmap, envmap[:, :1]], axis=1).astype(np.float32)
    return cv2.remap(padded, map_x + 1.0, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def develop_photo(radiance: np.ndarray, exposure: float | None = None) -> np.ndarray:
    """Expose, clip highlights at sensor white, apply the sRGB curve, quantise to 8 bits."""
    exposure = camera_exposure(radiance) if exposure is None else exposure
    srgb = linear_to_srgb(np.clip(radiance * exposure, 0.0, 1.0))
    return np.round(srgb * 255.0).astype(np.uint8)
