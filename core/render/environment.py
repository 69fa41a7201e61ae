"""Environment maps for rendering: read one from a file, check it, or make a constant or a sun-and-sky one."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..data.imageio import read_color_image
from ..scene.frame import equirect_directions

# The fewest rows a map is rendered with: Mitsuba's importance-sampling table (Distribution2D) needs two
# in each direction, and a 2x1 map is a fair (if coarse) map.
MIN_HEIGHT = 8


def constant_environment(color, height: int = 32) -> np.ndarray:
    """A uniform environment of linear RGB `color` (the stand-in until light estimation runs)."""
    color = np.broadcast_to(np.asarray(color, np.float32), (3,))
    return np.broadcast_to(color, (height, 2 * height, 3)).copy()


def sun_environment(direction, sun_radiance: float = 2000.0, sky_radiance: float = 0.3, sun_radius_deg: float = 3.0,
                    height: int = 64) -> np.ndarray:
    """A grey sky with one small disc sun towards world `direction` (Blender's lat-long convention):
    hard-edged shadows with a known direction, for tests and benchmarks."""
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    env = np.full((height, 2 * height, 3), sky_radiance, np.float32)
    env[equirect_directions(height, 2 * height) @ d > np.cos(np.radians(sun_radius_deg))] = sun_radiance
    return env


def load_environment(path: str | Path, max_height: int = 256) -> np.ndarray:
    """An equirectangular HDR map (EXR/HDR linear, or an 8-bit image decoded from sRGB), downsized for rendering."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    env = read_color_image(path)
    h, w = env.shape[:2]
    if w != 2 * h:
        raise InputError(f"Environment map '{path}' is {w}x{h}; a latitude-longitude map is twice as wide as high.")
    check_environment(env, f"Environment map '{path}'")
    if h > max_height:
        env = cv2.resize(env, (2 * max_height, max_height), interpolation=cv2.INTER_AREA)
    elif h < MIN_HEIGHT:   # each texel repeated: the same light, at a size the renderers' sampling tables take
        env = cv2.resize(env, (2 * MIN_HEIGHT, MIN_HEIGHT), interpolation=cv2.INTER_NEAREST)
    return env.astype(np.float32)


def check_environment(env: np.ndarray, what: str = "The environment map") -> None:
    """Radiance is finite and never negative; anything else makes renders (and `mitsuba`) fail later."""
    if not np.isfinite(env).all():
        raise InputError(f"{what} holds NaN or infinite pixels; repair or re-export it.")
    if (env < 0).any():
        raise InputError(f"{what} holds negative pixels (light cannot be negative); clamp them to 0 and re-export.")
