"""Where a click in the camera view lands in the photo, and where the asset goes for a placement.

Pure maths (no bpy), so the click handling of scenefit.pick_placement is tested without a window.
A placement is (x, y): fractions of the photo's width from the left and height from the TOP, as
the panel and the command line's --at take them. Region coordinates are Blender's: y from the bottom.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.compose import rotation_z
from ..core.errors import InputError
from ..core.photo import PhotoCamera
from ..core.photo_camera import pitch_roll_from_camera_to_world

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
                         fov_deg: float, pitch_deg: float, aspect: float, roll_deg: float = 0.0) -> np.ndarray:
    """Where SceneFit's photo camera stands so the asset's base point lands on `placement`, `size` tall.

    The camera is core's photo camera (core/photo.PhotoCamera: looking along +Y, the light map's azimuth
    0, at pitch_deg above the horizon, turned by roll_deg) with the horizontal field of view fov_deg and
    width/height `aspect`. base: the asset's bottom centre in world space; height: its height. The
    asset is not moved: the camera is placed around it.
    """
    if not 0.0 < size <= 1.0 or height <= 0.0:
        raise InputError("The asset's size in the photo must be in (0, 1] and the asset must have a height.")
    forward, right, up, tan_w, tan_h = PhotoCamera(pitch_deg=pitch_deg, fov_deg=fov_deg, width=1000,
                                                   height=max(1, round(1000 / aspect)), roll_deg=roll_deg).basis()
    # Depth along the view at which `height` fills `size` of the frame's height.
    depth = height / (size * 2.0 * tan_h)
    ray = forward + (2.0 * placement[0] - 1.0) * tan_w * right + (1.0 - 2.0 * placement[1]) * tan_h * up
    position = np.asarray(base, np.float64) - depth * ray
    if position[2] <= base[2]:
        raise InputError(f"The placement ({placement[0]:.2f}, {placement[1]:.2f}) is above the horizon of a camera "
                         f"at pitch {pitch_deg:.0f}°; pick a point on the ground or lower the Pitch.")
    return position


@dataclass(frozen=True)
class SceneView:
    """The artist's arrangement seen through their camera, in the terms the pipeline takes: the
    camera's field of view, pitch and roll, and the asset's placement, size and turn (see asset_in_view)."""

    fov_deg: float
    pitch_deg: float
    roll_deg: float
    yaw_deg: float                      # the camera's heading; the light map is turned by yaw - 90 to match
    placement: tuple[float, float]      # where the asset's base point is in the photo (fractions, y from the top)
    size: float                         # the asset's height in the photo as a fraction of its height
    turn_deg: float                     # the asset's turn about Z past facing the camera (core.compose.place_asset)


def camera_pose(camera_to_world: np.ndarray, shown: str = "the camera") -> tuple[float, float, float]:
    """(yaw, pitch, roll) in degrees of a Blender camera's world matrix (it looks down local -Z, +Y up):
    yaw is the heading of its view in the XY plane (90: along +Y, SceneFit's own camera)."""
    rotation = np.asarray(camera_to_world, np.float64)[:3, :3]
    pitch, roll = pitch_roll_from_camera_to_world(rotation, shown)
    forward = -rotation[:, 2]
    return math.degrees(math.atan2(forward[1], forward[0])), pitch, roll


def asset_in_view(camera_to_world: np.ndarray, fov_deg: float, width: int, height: int, points: np.ndarray,
                  object_yaw_deg: float, shown: str = "the camera") -> SceneView:
    """What the pipeline needs to compose the asset as the artist's camera sees it.

    points: the asset's vertices in world space; object_yaw_deg: the object's turn about Z (its mesh is
    handed to the pipeline in object space). core.compose.place_asset stands the asset's bottom centre,
    taken in axes turned with the camera, on the floor under the placement pixel, faces it to the camera
    and scales it to `size`: a similarity of this arrangement, so the composite shows the asset where and
    as large as the camera does."""
    matrix = np.asarray(camera_to_world, np.float64)
    yaw, pitch, roll = camera_pose(matrix, shown)
    origin = matrix[:3, 3]
    camera = PhotoCamera(yaw_deg=yaw, pitch_deg=pitch, fov_deg=fov_deg, width=width, height=height, roll_deg=roll)
    points = np.asarray(points, np.float64)
    # The bottom centre of the bounding box in axes where the camera looks along +Y, as core takes it.
    turn = rotation_z(90.0 - yaw)
    turned = points @ turn.T
    lo, hi = turned.min(axis=0), turned.max(axis=0)
    base = turn.T @ np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    forward = camera.basis()[0]
    if ((points - origin) @ forward).min() <= 0.0:
        raise InputError("Part of the asset is behind the scene camera; move the camera or the asset so the camera "
                         "sees all of it.")
    x, y = camera.project(base[None], origin)[0]
    ys = camera.project(points, origin)[:, 1]
    to_camera = origin[:2] - base[:2]
    facing = math.degrees(math.atan2(to_camera[1], to_camera[0]))
    return SceneView(fov_deg=float(fov_deg), pitch_deg=pitch, roll_deg=roll, yaw_deg=yaw,
                     placement=(float(x / width), float(y / height)),
                     size=float((ys.max() - ys.min()) / height),
                     turn_deg=float((object_yaw_deg - facing - 90.0 + 180.0) % 360.0 - 180.0))
