"""What the camera estimate found, drawn so an artist can check it at a glance: the photo's line
segments coloured by the direction they vanish in, and the horizon. Match Camera in Blender lays it
over the photo behind the camera; `scenefit camera --overlay FILE` writes it beside the JSON.
"""
from __future__ import annotations

import numpy as np

from .camera import CameraEstimate

# RGB in [0, 1] per segment family (0 vertical, 1 and 2 the two horizontal directions) and the horizon.
FAMILY_COLOURS = ((0.2, 0.55, 1.0), (1.0, 0.3, 0.25), (0.25, 0.9, 0.35))
HORIZON_COLOUR = (1.0, 0.85, 0.1)


def camera_overlay(estimate: CameraEstimate) -> np.ndarray:
    """(H, W, 4) float RGBA at the photo's size, transparent except for the lines: each segment the
    estimate used, coloured by its vanishing direction, and the horizon across the whole photo (drawn
    also when it came from a default or the user, since that is where the stages put it)."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    width, height = estimate.width, estimate.height
    canvas = np.zeros((height, width, 4), np.float32)
    thickness = max(1, round(max(width, height) / 600))
    for x0, y0, x1, y1, family in estimate.segments:
        colour = (*FAMILY_COLOURS[int(family) % 3], 1.0)
        cv2.line(canvas, _point(x0, y0), _point(x1, y1), colour, thickness, cv2.LINE_AA)
    (hx0, hy0), (hx1, hy1) = estimate.horizon
    cv2.line(canvas, _point(hx0, hy0), _point(hx1, hy1), (*HORIZON_COLOUR, 1.0), 2 * thickness, cv2.LINE_AA)
    return canvas


def _point(x: float, y: float) -> tuple[int, int]:
    # cv2 wants integer pixels inside a sane range; a horizon far outside a steep photo is clipped by cv2.
    return int(round(np.clip(x, -1e6, 1e6))), int(round(np.clip(y, -1e6, 1e6)))
