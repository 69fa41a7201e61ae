"""The sun's direction from a shadow the artist points at: three points in the photo, the foot of
something standing on the floor, its top (straight above the foot) and the tip of its shadow.

With the photo's camera and the floor known (the camera CAMERA_HEIGHT above it), the foot and the tip
are floor points; the top is the point of its pixel's ray straight above the foot; the sun lies along
tip -> top. The answer is in `--sun`'s terms: azimuth from the camera's view, positive to its right,
and elevation above the horizon (core/stages/light/estimate.py:sun_direction is the inverse). How far
it may be off (`sun_uncertainty_deg`) is how far a slipped click turns it: a long shadow near the
camera pins it within a degree or two, a short one far away may not pin it at all.
"""
from __future__ import annotations

import math

import numpy as np

from ...base.errors import InputError
from ...scene.camera import CAMERA_HEIGHT, PhotoCamera, pixel_ray
from ...scene.placement import Placement


def floor_point(camera: PhotoCamera, pixel: tuple[float, float], what: str) -> np.ndarray:
    """Where the pixel's ray meets the floor; one sentence when it does not (at or above the horizon)."""
    ray = pixel_ray(camera, *pixel)
    if ray[2] >= -1e-6:
        raise InputError(f"The {what} ({pixel[0]:.0f}, {pixel[1]:.0f}) is at or above the horizon of this camera, "
                         "so it is not on the floor; pick it on the ground, or check the camera's pitch.")
    origin = np.array([0.0, 0.0, CAMERA_HEIGHT])
    return origin + ray * (CAMERA_HEIGHT / -ray[2])


def sun_from_shadow(camera: PhotoCamera, foot: tuple[float, float], top: tuple[float, float],
                    tip: tuple[float, float]) -> tuple[float, float]:
    """(azimuth, elevation) in degrees of the sun casting the shadow; points are photo pixels (x right,
    y down) of the caster's foot, its top and the shadow's tip."""
    origin = np.array([0.0, 0.0, CAMERA_HEIGHT])
    base, end = floor_point(camera, foot, "foot"), floor_point(camera, tip, "shadow's tip")
    ray = pixel_ray(camera, *top)
    # The top is on its ray, straight above the foot: the ray's point nearest the foot's vertical.
    across = (base - origin)[:2]
    t = float(ray[:2] @ across / max(float(ray[:2] @ ray[:2]), 1e-12))
    above = origin + t * ray
    if t <= 0 or above[2] <= 1e-6:
        raise InputError("The top you picked is not above the foot (its ray meets the foot's vertical at or below "
                         "the floor); pick the caster's top, then its foot on the ground, then the shadow's tip.")
    if np.linalg.norm(above[:2] - base[:2]) > 0.25 * max(above[2], 1e-6):
        raise InputError("The top you picked is not straight above the foot in this camera's view; pick the top "
                         "and the foot of one upright thing (a post, a person, a table leg's corner).")
    return sun_deg_from_direction(above - end, camera.basis()[0])


# How far a click may slip, as a fraction of the photo's width (2 pixels of a 640-wide view, whatever the
# photo's own size): the sun's uncertainty is the largest turn of its direction when one point moves that far.
CLICK_SLIP = 2.0 / 640.0


def sun_uncertainty_deg(camera: PhotoCamera, foot: tuple[float, float], top: tuple[float, float],
                        tip: tuple[float, float]) -> float:
    """Degrees the sun from these points (pixels of `camera`'s image) turns, at most, when one point slips
    CLICK_SLIP of the width in any of four directions (a short shadow, or a tip near the horizon, turns it
    far), up to 90: where a slip makes the points no shadow (a point off the floor, the top no longer
    above the foot) or turns the sun that far, the clicks do not pin it."""
    slip_px = CLICK_SLIP * camera.width
    points = [tuple(map(float, foot)), tuple(map(float, top)), tuple(map(float, tip))]
    base = _unit(*sun_from_shadow(camera, *points))  # type: ignore[arg-type]
    worst = 0.0
    for index in range(3):
        for dx, dy in ((slip_px, 0.0), (-slip_px, 0.0), (0.0, slip_px), (0.0, -slip_px)):
            moved = list(points)
            moved[index] = (points[index][0] + dx, points[index][1] + dy)
            try:
                turned = _unit(*sun_from_shadow(camera, *moved))  # type: ignore[arg-type]
            except InputError:
                return 90.0
            worst = max(worst, math.degrees(math.acos(float(np.clip(base @ turned, -1.0, 1.0)))))
    return min(worst, 90.0)


def _unit(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


SHADOW_POINTS = ("foot", "top", "tip")


def check_point_count(points) -> None:
    if len(points) != len(SHADOW_POINTS):
        raise InputError(f"The sun from a shadow takes three points (foot, top, tip), got {len(points)}.")


def shadow_pixels(points, photo_wh: tuple[int, int], hw: tuple[int, int]) -> list[tuple[float, float]]:
    """FOOT, TOP, TIP given as `--at` takes a point (fractions, or pixels of the photo as stored,
    `photo_wh`) as pixels of the photo's working copy of size `hw`; one sentence for a bad point."""
    check_point_count(points)
    return [Placement.parse(point, photo_wh, what=f"The shadow's {name}").pixel(hw)
            for point, name in zip(points, SHADOW_POINTS)]


def sun_from_shadow_points(points, camera: PhotoCamera, photo_wh: tuple[int, int],
                           hw: tuple[int, int]) -> tuple[tuple[float, float], float]:
    """(`sun_from_shadow`, `sun_uncertainty_deg`) for the points as `shadow_pixels` takes them, through
    `camera`, the camera of the photo's working copy."""
    pixels = shadow_pixels(points, photo_wh, hw)
    return sun_from_shadow(camera, *pixels), sun_uncertainty_deg(camera, *pixels)


def sun_deg_from_direction(toward_sun, forward) -> tuple[float, float]:
    """--sun's (azimuth, elevation) in degrees of a world direction towards the sun, for a camera looking
    along `forward` (Z up; its pitch and roll do not matter): the inverse of estimate.sun_direction. A Sun
    light in Blender gives it (its local +Z), with the camera that shows the photo."""
    d = np.asarray(toward_sun, np.float64)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    f = np.array([forward[0], forward[1], 0.0], np.float64)
    if np.linalg.norm(f) < 1e-6:
        raise InputError("The camera looks straight up or down, so the sun's azimuth from its view is undefined; "
                         "tilt it towards the horizon.")
    f /= np.linalg.norm(f)
    right = np.array([f[1], -f[0], 0.0])
    azimuth = math.degrees(math.atan2(float(d @ right), float(d @ f)))
    return azimuth, math.degrees(math.asin(float(np.clip(d[2], -1.0, 1.0))))
