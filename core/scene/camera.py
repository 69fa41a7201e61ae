"""The photo camera: a pinhole CAMERA_HEIGHT above the floor z = 0, looking along (yaw, pitch), turned
by roll; its frame, defaults and the conventions of its angles, defined once.

pitch: where the camera looks above the horizon (negative: down). roll: how far the camera is turned
counter-clockwise about its view axis, so the horizon appears turned clockwise in the image. yaw: the
heading of its view in the XY plane; SceneFit's own photo camera has yaw 90 (along +Y), which is the
light map's azimuth 0. World units are camera heights (CAMERA_HEIGHT = 1): only ratios matter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from .frame import look_frame


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
    the horizon appears turned clockwise in the image (last, so positional construction still works).
    shift_x, shift_y: the lens shift as Blender measures it (fractions of the image's longer side; fSpy's
    off-centre principal point is one): the view moves right and up by that much, the direction it looks
    along stays, so the optical axis meets the image at `principal_px()` rather than the centre."""

    yaw_deg: float = PHOTO_YAW_DEG
    pitch_deg: float = DEFAULT_PITCH_DEG
    fov_deg: float = DEFAULT_FOV_DEG
    width: int = 640
    height: int = 480
    roll_deg: float = 0.0
    shift_x: float = 0.0
    shift_y: float = 0.0

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """forward, right, up unit vectors and the half extents of the image plane at distance 1."""
        yaw, pitch = np.radians(self.yaw_deg), np.radians(self.pitch_deg)
        forward, right, up = look_frame([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)])
        if self.roll_deg:   # skipped at 0 so every level camera stays bit-identical
            c, s = np.cos(np.radians(self.roll_deg)), np.sin(np.radians(self.roll_deg))
            right, up = c * right + s * up, c * up - s * right
        half_w = float(np.tan(np.radians(self.fov_deg) / 2))
        return forward, right, up, half_w, half_w * self.height / self.width

    def plane_offset(self) -> tuple[float, float]:
        """Where the image's centre lies on the image plane at distance 1 (right, up): the lens shift."""
        per_side = 2.0 * float(np.tan(np.radians(self.fov_deg) / 2)) * max(self.width, self.height) / self.width
        return self.shift_x * per_side, self.shift_y * per_side

    def principal_px(self) -> tuple[float, float]:
        """The pixel (x right, y down) the optical axis meets: the centre, moved against the lens shift."""
        side = max(self.width, self.height)
        return self.width / 2.0 - self.shift_x * side, self.height / 2.0 + self.shift_y * side

    def film_offset(self) -> tuple[float, float]:
        """The image centre's offset from the optical axis's pixel in fractions of the width and height (x right,
        y down): what Mitsuba's perspective sensor takes as its principal point offset."""
        side = max(self.width, self.height)
        return self.shift_x * side / self.width, -self.shift_y * side / self.height

    def plane_xy(self, x_px, y_px) -> tuple[np.ndarray, np.ndarray]:
        """Image-plane coordinates (right, up, at distance 1) of pixel positions (x right, y down)."""
        _, _, _, half_w, half_h = self.basis()
        off_x, off_y = self.plane_offset()
        return ((np.asarray(x_px) / self.width * 2 - 1) * half_w + off_x,
                (1 - np.asarray(y_px) / self.height * 2) * half_h + off_y)

    def image_xy(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sx, sy, depth) of world directions: sx, sy in [-1, 1] across the image (x right, y up), and
        each direction's component along the view (positive: in front)."""
        forward, right, up, half_w, half_h = self.basis()
        off_x, off_y = self.plane_offset()
        directions = np.asarray(directions, dtype=np.float64)
        depth = directions @ forward
        with np.errstate(divide="ignore", invalid="ignore"):
            return ((directions @ right) / depth - off_x) / half_w, ((directions @ up) / depth - off_y) / half_h, depth

    def ray_directions(self) -> np.ndarray:
        forward, right, up, _, _ = self.basis()
        x, y = np.meshgrid(*self.plane_xy(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5))
        d = forward + x[..., None] * right + y[..., None] * up
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def project(self, points: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Pixel coordinates (x right, y down, pixel centres at +0.5) of world points seen from
        `origin`; the inverse of `ray_directions` (points must lie in front of the camera)."""
        rel = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
        x, y, _ = self.image_xy(rel)
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


CAMERA_HEIGHT = 1.0


def pixel_ray(camera: PhotoCamera, x: float, y: float) -> np.ndarray:
    """World direction through photo pixel coordinates (x right, y down, pixel centres at +0.5)."""
    forward, right, up, _, _ = camera.basis()
    plane_x, plane_y = camera.plane_xy(x, y)
    d = forward + plane_x * right + plane_y * up
    return d / np.linalg.norm(d)


def camera_origin() -> np.ndarray:
    return np.array([0.0, 0.0, CAMERA_HEIGHT])


def horizon_row(camera: PhotoCamera) -> int:
    """The first image row with any pixel looking below the horizon (camera.height: none does)."""
    below = (camera.ray_directions()[..., 2] < 0).any(axis=1)
    rows = np.flatnonzero(below)
    return int(rows[0]) if len(rows) else camera.height


def pitch_roll_from_camera_to_world(rotation: np.ndarray, shown: str | Path = "the camera") -> tuple[float, float]:
    """Pitch and roll (degrees) of a camera-to-world rotation whose columns are the camera's right, up and
    backward (-view) axes in a Z-up world (fSpy's and Blender's camera convention)."""
    right, up, back = (rotation[:, i] / max(np.linalg.norm(rotation[:, i]), 1e-12) for i in range(3))
    forward = -back
    level_right = np.cross(forward, (0.0, 0.0, 1.0))
    if np.linalg.norm(level_right) < 1e-9:
        raise InputError(f"{shown} looks straight up or down, so it has no horizon to take pitch and roll from; "
                         "solve it again with the camera tilted less.")
    level_right /= np.linalg.norm(level_right)
    level_up = np.cross(level_right, forward)
    pitch = math.degrees(math.asin(float(np.clip(forward[2], -1.0, 1.0))))
    roll = math.degrees(math.atan2(float(right @ level_up), float(right @ level_right)))
    return pitch, roll


def camera_pose(camera_to_world: np.ndarray, shown: str = "the camera") -> tuple[float, float, float]:
    """(yaw, pitch, roll) in degrees of a Blender camera's world matrix (it looks down local -Z, +Y up):
    yaw is the heading of its view in the XY plane (90: along +Y, SceneFit's own camera)."""
    rotation = np.asarray(camera_to_world, np.float64)[:3, :3]
    pitch, roll = pitch_roll_from_camera_to_world(rotation, shown)
    forward = -rotation[:, 2]
    return math.degrees(math.atan2(forward[1], forward[0])), pitch, roll
