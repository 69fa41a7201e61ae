"""Where a click in the camera view lands in the photo, and where the asset goes for a placement.

Pure maths (no bpy), so the click handling of scenefit.pick_placement is tested without a window.
A placement is (x, y): fractions of the photo's width from the left and height from the TOP, as
the panel and the command line's --at take them. Region coordinates are Blender's: y from the bottom.
"""
from __future__ import annotations


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


