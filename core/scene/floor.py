"""The floor the asset stands on, as the photo camera sees it.

The photo camera stands at (0, 0, CAMERA_HEIGHT) above the floor z = 0. The asset stands where the
ray through the placement pixel meets the floor; rays at or above the horizon are tilted just below
it. Where nothing better is known (no depth model), the light stage's room is the floor and a
cylindrical wall around the camera.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.errors import InputError
from .camera import CAMERA_HEIGHT, PhotoCamera, pixel_ray


MIN_PLACEMENT_DEPRESSION_DEG = 2.0  # a placement ray must point at least this far below the horizon


ORIGIN_LIFT = 0.05  # the map is seen from this high above the floor point (camera heights): the object's centre


@dataclass(frozen=True)
class FloorPoint:
    """Where the ray through the placement's pixel meets the floor: the object stands there."""

    pixel: tuple[float, float]     # (x, y) in photo pixels
    object_position: np.ndarray    # world, on the floor z = 0
    clamped: bool                  # the ray was lifted below the horizon to meet the floor


def place_on_floor(camera: PhotoCamera, pixel: tuple[float, float], height: float = CAMERA_HEIGHT) -> FloorPoint:
    """Where the placement pixel's ray meets the floor; rays at or above the horizon are tilted just below it."""
    x, y = pixel
    if not (0 <= x <= camera.width and 0 <= y <= camera.height):
        raise InputError(f"The placement ({x:.1f}, {y:.1f}) lies outside the {camera.width}x{camera.height} photo.")
    d = pixel_ray(camera, x, y)
    min_dz = -np.sin(np.radians(MIN_PLACEMENT_DEPRESSION_DEG))
    clamped = bool(d[2] > min_dz)
    if clamped:
        horizontal = d[:2] / max(np.linalg.norm(d[:2]), 1e-9)
        d = np.array([*(horizontal * np.cos(np.arcsin(-min_dz))), min_dz])
    t = height / -d[2]
    origin = np.array([0.0, 0.0, height])
    return FloorPoint((float(x), float(y)), origin + t * d, clamped)


def geometric_ray_distance(camera: PhotoCamera, placement: FloorPoint, height: float = CAMERA_HEIGHT) -> np.ndarray:
    """The fallback room: floor z = 0 and a cylindrical wall around the camera, (H, W) distances along rays.

    The wall stands at three times the floor distance to the object (at least 4 camera heights),
    so the object sits well inside the room; rays that do not meet the floor end on the wall.
    """
    dirs = camera.ray_directions()
    reach = float(np.linalg.norm(placement.object_position[:2]))
    radius = max(3.0 * reach, 4.0 * height)
    dz = dirs[..., 2]
    t_floor = np.where(dz < -1e-6, height / np.maximum(-dz, 1e-6), np.inf)
    horizontal = np.linalg.norm(dirs[..., :2], axis=-1)
    t_wall = radius / np.maximum(horizontal, 1e-6)
    return np.minimum(t_floor, t_wall).astype(np.float32)
