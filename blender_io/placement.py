"""Where a click in the camera view lands in the photo, and where the asset goes for a placement.

Pure maths (no bpy), so the click handling of scenefit.pick_placement is tested without a window.
A placement is (x, y): fractions of the photo's width from the left and height from the TOP, as
the panel and the command line's --at take them. Region coordinates are Blender's: y from the bottom.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.errors import InputError

CLICK, CANCEL, PASS = "click", "cancel", "pass"


def classify_event(event_type: str, value: str) -> str:
    """What pick_placement does with an event: a left press places, Esc or a right press cancels."""
    if value != "PRESS":
        return PASS
    if event_type == "LEFTMOUSE":
        return CLICK
    if event_type in ("ESC", "RIGHTMOUSE"):
        return CANCEL
    return PASS


def frame_rect(points: list[tuple[float, float]]) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) of the camera frame's corners projected into the region."""
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    return min(xs), min(ys), max(xs), max(ys)


def placement_from_click(mouse: tuple[float, float], rect: tuple[float, float, float, float]):
    """The placement of a click at region pixel `mouse`, or None when it is outside the photo's frame."""
    x0, y0, x1, y1 = rect
    if x1 <= x0 or y1 <= y0:
        return None
    u = (mouse[0] - x0) / (x1 - x0)
    v = (y1 - mouse[1]) / (y1 - y0)
    if not (0.0 <= u <= 1.0 and 0.0 <= v <= 1.0):
        return None
    return u, v


def region_from_placement(placement: tuple[float, float], rect: tuple[float, float, float, float]):
    """The region pixel where the marker for `placement` is drawn (inverse of placement_from_click)."""
    x0, y0, x1, y1 = rect
    return x0 + placement[0] * (x1 - x0), y1 - placement[1] * (y1 - y0)


def camera_for_placement(base: np.ndarray, height: float, placement: tuple[float, float], size: float,
                         fov_deg: float, elevation_deg: float, aspect: float) -> np.ndarray:
    """Where the photo camera stands so the asset's base point lands on `placement`, `size` tall.

    The camera looks along +Y (the light stage's azimuth 0) pitched down by elevation_deg, with the
    horizontal field of view fov_deg and width/height `aspect`. base: the asset's bottom centre in
    world space; height: its height. The asset is not moved: the camera is placed around it.
    """
    if not 0.0 < size <= 1.0 or height <= 0.0:
        raise InputError("The asset's size in the photo must be in (0, 1] and the asset must have a height.")
    pitch = math.radians(-elevation_deg)
    forward = np.array([0.0, math.cos(pitch), math.sin(pitch)])
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(right, forward)
    tan_w = math.tan(math.radians(fov_deg) / 2)
    tan_h = tan_w / aspect
    # Depth along the view at which `height` fills `size` of the frame's height.
    depth = height / (size * 2.0 * tan_h)
    ray = forward + (2.0 * placement[0] - 1.0) * tan_w * right + (1.0 - 2.0 * placement[1]) * tan_h * up
    position = np.asarray(base, np.float64) - depth * ray
    if position[2] <= base[2]:
        raise InputError(f"The placement ({placement[0]:.2f}, {placement[1]:.2f}) is above the horizon of a camera "
                         f"looking down by {elevation_deg:.0f}°; pick a point on the ground or raise the Elevation.")
    return position
