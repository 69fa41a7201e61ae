"""Synthetic photos from HDR environment maps, taken as a camera would take them.

Used for the bundled example and for measuring light estimation against ground truth: a
perspective view cut out of an equirectangular HDR map, exposed, clipped and stored in 8 bits.
"""
from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .imageio import linear_to_srgb
from .render import blender_direction_to_equirect_uv

STUDIOLIGHTS_DEVELOPMENT_SET = ("studio", "interior", "city", "forest")


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


@dataclass(frozen=True)
class PhotoCamera:
    """A pinhole looking along (yaw, pitch) in Blender's Z-up world; fov is horizontal, in degrees."""

    yaw_deg: float = 90.0
    pitch_deg: float = -10.0
    fov_deg: float = 60.0
    width: int = 640
    height: int = 480

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """forward, right, up unit vectors and the half extents of the image plane at distance 1."""
        yaw, pitch = np.radians(self.yaw_deg), np.radians(self.pitch_deg)
        forward = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        half_w = float(np.tan(np.radians(self.fov_deg) / 2))
        return forward, right, up, half_w, half_w * self.height / self.width

    def ray_directions(self) -> np.ndarray:
        forward, right, up, half_w, half_h = self.basis()
        xs = ((np.arange(self.width) + 0.5) / self.width * 2 - 1) * half_w
        ys = (1 - (np.arange(self.height) + 0.5) / self.height * 2) * half_h
        x, y = np.meshgrid(xs, ys)
        d = forward + x[..., None] * right + y[..., None] * up
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def project(self, points: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Pixel coordinates (x right, y down, pixel centres at +0.5) of world points seen from
        `origin`; the inverse of `ray_directions` (points must lie in front of the camera)."""
        forward, right, up, half_w, half_h = self.basis()
        rel = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
        depth = rel @ forward
        x = (rel @ right) / (depth * half_w)
        y = (rel @ up) / (depth * half_h)
        return np.stack([(x + 1) / 2 * self.width, (1 - y) / 2 * self.height], axis=-1)


def perspective_view(envmap: np.ndarray, camera: PhotoCamera) -> np.ndarray:
    """Linear radiance seen by `camera` in an equirectangular map (bilinear, wrapping in u)."""
    import cv2

    h, w = envmap.shape[:2]
    uv = blender_direction_to_equirect_uv(camera.ray_directions())
    map_x = (uv[..., 0] * w - 0.5).astype(np.float32)
    map_y = np.clip(uv[..., 1] * h - 0.5, 0, h - 1).astype(np.float32)
    padded = np.concatenate([envmap[:, -1:], envmap, envmap[:, :1]], axis=1).astype(np.float32)
    return cv2.remap(padded, map_x + 1.0, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def camera_exposure(radiance: np.ndarray, key: float = 0.18) -> float:
    """Auto-exposure as a camera meters: the scene's log-average luminance maps to middle grey."""
    lum = radiance[..., :3] @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    log_average = float(np.exp(np.mean(np.log(np.maximum(lum, 1e-6)))))
    return key / max(log_average, 1e-6)


def develop_photo(radiance: np.ndarray, exposure: float | None = None) -> np.ndarray:
    """Expose, clip highlights at sensor white, apply the sRGB curve, quantise to 8 bits."""
    exposure = camera_exposure(radiance) if exposure is None else exposure
    srgb = linear_to_srgb(np.clip(radiance * exposure, 0.0, 1.0))
    return np.round(srgb * 255.0).astype(np.uint8)
