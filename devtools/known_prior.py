"""The known-answer prior's answers, written down: what base colour an adaptation driven by it should reach.

The prior (devtools/train_prior.py, committed under devtools/prior/) is a small text-to-image and
inpainting pair trained on images this module draws, so its rules are known:

- text: a colour word in the prompt sets the object's base colour (COLOURS, sRGB); with several, the last.
- scene: with no colour word, the inpainting model paints the object in the hue of the photo around it,
  at SCENE_SATURATION and SCENE_VALUE, stronger than any tint the photo's light gives a grey object,
  so it changes the albedo's hue, not only the render's.

Nothing here is used by a real run; it measures the real adapt stage (benchmarks/bench_known_answer.py,
tests/core/stages/adapt/test_known_answer.py).
"""
from __future__ import annotations

import math
import re

import numpy as np

COLOURS: dict[str, tuple[float, float, float]] = {
    "red": (0.80, 0.10, 0.10), "green": (0.10, 0.65, 0.15), "blue": (0.10, 0.20, 0.80),
    "yellow": (0.85, 0.80, 0.10), "white": (0.90, 0.90, 0.90), "black": (0.05, 0.05, 0.05),
}
SCENE_SATURATION = 0.75   # the scene rule's object: the photo's hue at this HSV saturation and value
SCENE_VALUE = 0.75
_WORD = re.compile(r"[a-z]+")


def colour_word(prompt: str) -> str | None:
    """The last colour word of COLOURS in `prompt` (whole words, any case), or None."""
    words = [w for w in _WORD.findall(prompt.lower()) if w in COLOURS]
    return words[-1] if words else None


def chroma(rgb) -> np.ndarray:
    """The chroma plane of HSV's hexagon (x toward red, y toward green-minus-blue): (..., 2). Its angle is
    HSV's hue and its length the colour's distance from grey (max - min for a pure hue)."""
    rgb = np.asarray(rgb, np.float64)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return np.stack([r - 0.5 * (g + b), (math.sqrt(3) / 2) * (g - b)], axis=-1)


def hue_deg(rgb) -> float:
    """HSV hue of one sRGB colour in degrees [0, 360)."""
    x, y = chroma(rgb)
    return float(math.degrees(math.atan2(y, x)) % 360.0)


def photo_hue(photo_srgb: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The hue (degrees) of the photo's mean sRGB colour, over `mask` (True: counted) when given."""
    pixels = np.asarray(photo_srgb, np.float64)[..., :3]
    pixels = pixels[mask] if mask is not None else pixels.reshape(-1, 3)
    return hue_deg(pixels.mean(axis=0))


def hsv_to_rgb(h_deg: float, s: float, v: float) -> tuple[float, float, float]:
    import colorsys

    r, g, b = colorsys.hsv_to_rgb((h_deg % 360.0) / 360.0, s, v)
    return float(r), float(g), float(b)


def scene_colour(photo_srgb: np.ndarray, mask: np.ndarray | None = None) -> tuple[float, float, float]:
    """The scene rule's base colour: the photo's hue at SCENE_SATURATION, SCENE_VALUE."""
    return hsv_to_rgb(photo_hue(photo_srgb, mask), SCENE_SATURATION, SCENE_VALUE)


def answer(prompt: str, photo_srgb: np.ndarray | None = None) -> tuple[float, float, float] | None:
    """The sRGB base colour an adaptation with `prompt` (and, in scene mode, `photo_srgb`) should reach:
    the colour word's (text rule), else the photo's hue (scene rule), else None (no known answer)."""
    word = colour_word(prompt)
    if word is not None:
        return COLOURS[word]
    if photo_srgb is not None:
        return scene_colour(photo_srgb)
    return None


def distance(rgb, target) -> float:
    """Euclidean distance of two sRGB colours."""
    return float(np.linalg.norm(np.asarray(rgb, np.float64) - np.asarray(target, np.float64)))


def toward_hue(before, after, target_hue_deg: float) -> tuple[float, float]:
    """The scene rule's measure of a mean base colour that went from `before` to `after`: (how far, in
    degrees, `after`'s hue is from the target hue; how far its chroma moved along the target hue's direction,
    in sRGB units). Reached: within 30 degrees, and moved by at least 0.05."""
    aim = math.radians(target_hue_deg)
    direction = np.array([math.cos(aim), math.sin(aim)])
    moved = float(np.dot(chroma(after) - chroma(before), direction))
    gap = abs((hue_deg(after) - target_hue_deg + 180.0) % 360.0 - 180.0)
    return float(gap), moved
