"""Indoor or outdoor, from the photo alone (no model weights): two cues, each with a physical reason.

- clutter: the fraction of pixels that are corners (OpenCV's minimum-eigenvalue corner response above
  a threshold, on the photo resized to 320 pixels wide). Outdoors the view reaches far: foliage,
  façades, cars and skylines put many small structures in the frame; rooms are walls, furniture
  and curtains, large smooth planes and straight folds (edges, but few corners).
- sky ratio: the median linear brightness of the top eighth of the photo over that of the bottom
  eighth. Outdoors the sky above is the light source and outshines the ground; indoors the ceiling
  is lit from below and is rarely brighter than the floor by much.

score = max(clutter / CLUTTER_AT, log(sky ratio) / log(SKY_RATIO_AT)); outdoor when score >= 1.
Within [UNSURE_LOW, UNSURE_HIGH] the call is reported as unsure (the report shows both cues) and,
where both are cheap, the light stage averages the indoor and the outdoor estimates. On 24 views of
real captured maps (benchmarks/results/light_real.md) calls were wrong at scores 0.61-1.6 (a
workshop and a vestibule looking at their windows, a dim night square, a beach at dawn) and at
0.12 and 2.5-3.5 (a photo of clouds only; a room whose window fills the top of the frame): those
two stay wrong and sure, as no cue here tells them apart.
The thresholds were set on views of Blender's studio, interior, city and forest maps (all right)
and checked on courtyard, night, sunrise and sunset (benchmarks/results/light.md lists each view).
"""
from __future__ import annotations

import math

import numpy as np

from ...data.imageio import srgb_to_linear

WORK_WIDTH = 320
CORNER_RESPONSE = 0.002
CLUTTER_AT = 0.042
SKY_RATIO_AT = 3.2
UNSURE_LOW, UNSURE_HIGH = 0.6, 1.7   # widened on the corpus's 24 real views (issue 21)


def scene_type_cue(photo_srgb: np.ndarray) -> dict:
    """{"scene_type", "score", "unsure", "clutter", "sky_ratio", "rule"} for an sRGB [0, 1] photo."""
    import cv2  # lazy: Blender may lack OpenCV (missing_modules)

    photo = np.asarray(photo_srgb, np.float32)[..., :3]
    h, w = photo.shape[:2]
    if w != WORK_WIDTH:
        size = (WORK_WIDTH, max(8, round(h * WORK_WIDTH / w)))
        photo = cv2.resize(photo, size, interpolation=cv2.INTER_AREA if w > WORK_WIDTH else cv2.INTER_LINEAR)
    level = np.ascontiguousarray(photo.mean(axis=-1))
    clutter = float((cv2.cornerMinEigenVal(level, 5, 3) > CORNER_RESPONSE).mean())
    linear = srgb_to_linear(photo).mean(axis=-1)
    band = max(1, linear.shape[0] // 8)
    sky_ratio = float(np.median(linear[:band])) / max(float(np.median(linear[-band:])), 1e-4)
    score = max(clutter / CLUTTER_AT, math.log(max(sky_ratio, 1e-6)) / math.log(SKY_RATIO_AT))
    return {"scene_type": "outdoor" if score >= 1.0 else "indoor", "score": round(score, 4),
            "unsure": bool(UNSURE_LOW <= score <= UNSURE_HIGH), "clutter": round(clutter, 4),
            "sky_ratio": round(sky_ratio, 4),
            "rule": f"outdoor when max(clutter / {CLUTTER_AT}, log(sky ratio) / log({SKY_RATIO_AT})) >= 1; "
                    f"unsure within [{UNSURE_LOW}, {UNSURE_HIGH}]"}


def is_blended(decision: dict) -> bool:
    """True when an unsure call made the map the mean of the indoor and the outdoor estimates."""
    scales = decision.get("scales")
    return isinstance(scales, dict) and {"indoor", "outdoor"} <= set(scales)


def scene_type_words(decision: dict, decider: str = "") -> str:
    """What the light stage's `scene_type` decision says in words: "indoor", "outdoor", or, when an
    unsure call blended the two estimates, both (a reader must not take the blend for one of them),
    with `decider` (the setting that settles it) named when given."""
    if not is_blended(decision):
        return str(decision.get("chosen", ""))
    settle = f", {decider} decides" if decider else ""
    return f"indoor or outdoor (unsure, score {decision['auto']['score']:.2f}; the map is their mean{settle})"
