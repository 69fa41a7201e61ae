"""The world's frame and the environment map's convention.

World space is Blender's: Z up. A camera's frame is (forward, right, up) with right = forward x Z.
Light maps are latitude-longitude, twice as wide as high, rows from the zenith (+Z) down; the column
at u = 0.5 looks along +X and u = 0.25 along +Y: Blender's equirectangular Environment Texture
(checked against Cycles in tests/blender/test_lighting_blender.py). Mitsuba's envmap is Y up, so its emitter
gets ENVMAP_TO_WORLD.
"""
from __future__ import annotations

import math

import numpy as np

from ..base.errors import InputError


WORLD_UP = (0.0, 0.0, 1.0)


def look_frame(forward) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(forward, right, up) unit vectors of a camera looking along `forward` with the world's +Z up
    (Blender's convention: right = forward x Z, up = right x forward). The one camera frame every
    camera in SceneFit uses: orbit cameras, photo cameras, and ε_ψ's camera condition."""
    f = np.asarray(forward, np.float64)
    f = f / np.linalg.norm(f)
    right = np.cross(f, WORLD_UP)
    norm = np.linalg.norm(right)
    if norm < 1e-12:
        raise InputError("A camera looking straight up or down has no horizon to orient it; tilt it a little.")
    right /= norm
    return f, right, np.cross(right, f)


def rotation_z(deg: float) -> np.ndarray:
    """The 3x3 rotation by `deg` about the world's Z (up) axis."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Rotation taking Mitsuba's envmap frame (Y up) to Blender's world (Z up), chosen so that
# Mitsuba's direction->(u, v) lookup equals Blender's equirectangular Environment Texture:
# local (x, y, z) -> world (z, x, y).
ENVMAP_TO_WORLD = np.array(
    [[0.0, 0.0, 1.0, 0.0],
     [1.0, 0.0, 0.0, 0.0],
     [0.0, 1.0, 0.0, 0.0],
     [0.0, 0.0, 0.0, 1.0]]
)


def blender_direction_to_equirect_uv(direction: np.ndarray) -> np.ndarray:
    """(u, v) in [0, 1] of Blender's equirectangular mapping; v measured from the TOP row.

    Blender (intern/cycles/kernel/geom, direction_to_equirectangular with its default range):
    u = 0.5 - atan2(d.y, d.x) / 2pi, v_bottom = atan2(d.z, hypot(d.x, d.y)) / pi + 0.5.
    """
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    v_top = 0.5 - np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi
    return np.stack([u % 1.0, v_top], axis=-1)


def equirect_directions(height: int, width: int) -> np.ndarray:
    """World direction (Blender convention) through the centre of each texel of an (H, W) map."""
    u = (np.arange(width) + 0.5) / width
    v_top = (np.arange(height) + 0.5) / height
    phi = (0.5 - u) * 2.0 * np.pi                 # atan2(d.y, d.x)
    elevation = (0.5 - v_top) * np.pi
    el, ph = np.meshgrid(elevation, phi, indexing="ij")
    return np.stack([np.cos(ph) * np.cos(el), np.sin(ph) * np.cos(el), np.sin(el)], axis=-1)
