"""Synthetic photos from HDR environment maps, taken as a camera would take them.

Used for the bundled example and for measuring light estimation against ground truth: a
perspective view cut out of an equirectangular HDR map, exposed, clipped and stored in 8 bits.
"""
from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import look_frame
from .errors import InputError
from .imageio import linear_to_srgb
from .render import blender_direction_to_equirect_uv

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


# The photo camera's frame, defined once: it looks along +Y (yaw 90°, the composition's azimuth 0,
# which is the light map's frame), level unless told otherwise; pitch is where it looks above the
# horizon (negative: down).
PHOTO_YAW_DEG = 90.0
DEFAULT_PITCH_DEG = -10.0
DEFAULT_FOV_DEG = 60.0   # horizontal; a typical phone/kit-lens view (~28 mm full-frame equivalent)


@dataclass(frozen=True)
class PhotoCamera:
    """A pinhole looking along (yaw, pitch) in Blender's Z-up world; fov is horizontal, in degrees.

    roll_deg turns the camera counter-clockwise about its view axis as the photographer sees it, so
    the horizon appears turned clockwise in the image (last, so positional construction still works)."""

    yaw_deg: float = PHOTO_YAW_DEG
    pitch_deg: float = DEFAULT_PITCH_DEG
    fov_deg: float = DEFAULT_FOV_DEG
    width: int = 640
    height: int = 480
    roll_deg: float = 0.0

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """forward, right, up unit vectors and the half extents of the image plane at distance 1."""
        yaw, pitch = np.radians(self.yaw_deg), np.radians(self.pitch_deg)
        forward, right, up = look_frame([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
        if self.roll_deg:   # skipped at 0 so every level camera stays bit-identical
            c, s = np.cos(np.radians(self.roll_deg)), np.sin(np.radians(self.roll_deg))
            right, up = c * right + s * up, c * up - s * right
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


def photo_camera_for(photo_info: dict, width: int, height: int, fov_deg: float | None = None,
                     pitch_deg: float | None = None) -> tuple[PhotoCamera, dict]:
    """The camera a photo is taken to have: the given field of view, else the photo's metadata, else
    DEFAULT_FOV_DEG; the given pitch, else DEFAULT_PITCH_DEG. Returns it and where the fov came from."""
    metadata = photo_info.get("fov_from_metadata_deg")
    fov = fov_deg or metadata or DEFAULT_FOV_DEG
    why = {"deg": fov, "from": "config" if fov_deg else
           ("photo metadata" if metadata else f"default (horizontal {DEFAULT_FOV_DEG:g} deg)")}
    pitch = DEFAULT_PITCH_DEG if pitch_deg is None else pitch_deg
    return PhotoCamera(pitch_deg=pitch, fov_deg=fov, width=width, height=height), why


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
